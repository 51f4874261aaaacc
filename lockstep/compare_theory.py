"""What theory predicts of a comparison cell, where a theory does (docs/architectures.md).

- paper: the sampled Nyquist test of the paper's loop with the task's linear environment
  (lockstep/sweep.py's ``analytic_margin_s``): bounded below the round-trip delay margin,
  unbounded above it. Necessary and sufficient for the linear loop the lockstep runs.
- tdpa, wave and four-channel-tdpa: a passive channel with a passive operator and
  environment stays passive for any constant delay: bounded (sufficient).
- four-channel: Llewellyn's absolute stability of the two-port at the cell's one-way delay
  (common/control/two_port.py): bounded where it holds (sufficient); where it fails the
  theory guarantees nothing, so no verdict is predicted.
- mmt: no theory here; nor for the clay cut (its linearisation about steady cutting is the
  clay sweep's, judged by decay, not by these bounds).

Only constant-delay cells (no loss, no jitter) are predicted: none of these theories covers a
lossy or jittery link as the comparison injects it. A disagreement is a predicted verdict the
measurement contradicts.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from haptic.common.control.law_pairs import four_channel_gains
from haptic.common.control.two_port import absolute_stability
from haptic.common.model.teleop import TeleopModel
from haptic.lockstep.compare_paper import task_model
from haptic.lockstep.sweep import analytic_margin_s

#: Llewellyn's inequalities are checked over this grid, rad/s.
LLEWELLYN_FREQUENCIES_RAD_S = np.logspace(-1.0, 4.0, 2000)
THEORIES = {"paper": "nyquist delay margin", "tdpa": "passivity (constant delay)",
            "wave": "passivity (constant delay)", "four-channel": "llewellyn absolute stability",
            "four-channel-tdpa": "passivity (constant delay)"}


@dataclass(frozen=True)
class Prediction:
    """A theory's verdict on a cell: ``bounded`` (True, False, or None: nothing predicted),
    the theory's name and, for the paper's scheme, the delay margin (s)."""

    theory: str
    bounded: bool | None
    margin_s: float | None = None


@functools.cache
def _four_channel_stable(one_way_delay_s: float) -> bool:
    return absolute_stability(four_channel_gains(), LLEWELLYN_FREQUENCIES_RAD_S,
                              one_way_delay_s).absolutely_stable


class Theory:
    """The predictions of one comparison (the paper's margins computed once per task)."""

    def __init__(self, model: TeleopModel | None) -> None:
        self.model = model
        self._margins: dict[tuple[str, float], float] = {}

    def paper_margin_s(self, task: str, stiffness_N_per_m: float) -> float:
        """The paper's loop's round-trip delay margin with the task's environment, s
        (inf: none up to the analysis's largest delay, 0: unstable without delay)."""
        key = (task, stiffness_N_per_m if task == "wall" else 0.0)
        if key not in self._margins:
            if self.model is None:
                raise ValueError("the paper's margin needs the paper's model")
            model = task_model(self.model, task, stiffness_N_per_m)
            self._margins[key] = analytic_margin_s(model, model.ch1_gain_k,
                                                   model.sample_period_s)
        return self._margins[key]

    def predict(self, control: str, task: str, round_trip_s: float, constant_delay: bool,
                stiffness_N_per_m: float) -> Prediction | None:
        """The prediction for a cell, or None where no theory applies."""
        if control not in THEORIES or not constant_delay or task == "clay-cut":
            return None
        name = THEORIES[control]
        if control == "paper":
            margin = self.paper_margin_s(task, stiffness_N_per_m)
            return Prediction(name, bool(round_trip_s < margin),
                              margin if np.isfinite(margin) else None)
        if control == "four-channel":
            return Prediction(name, True if _four_channel_stable(round_trip_s / 2.0) else None)
        return Prediction(name, True)


__all__ = ["THEORIES", "Prediction", "Theory"]
