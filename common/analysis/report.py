"""The whole analysis of a configuration: per axis and overall, as named results.

Gains are searched by re-synthesizing the compensators for each trial k, so every verdict is
about the compensators the runtime would really run.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from haptic.common.analysis.eq30 import check_eq30
from haptic.common.analysis.loop import AxisLoop
from haptic.common.analysis.stability import (
    FrequencyGrid,
    delay_margin,
    is_stable,
    max_delayed_ratio,
)
from haptic.common.model.synthesis import SynthesisError, synthesize_axis
from haptic.common.model.teleop import AxisModel, TeleopModel

#: Bisection steps when searching a gain boundary (relative resolution about 2^-30).
GAIN_BISECTION_STEPS = 30
#: Trial gains per search before bisection, spread geometrically over (0, max_gain_k].
GAIN_SCAN_POINTS = 40


@dataclass(frozen=True)
class AnalysisSettings:
    """Search ranges of the analysis (units in the names)."""

    max_frequency_rad_s: float = 20000.0
    max_delay_s: float = 1.0
    max_gain_k: float = 200.0
    sample_period_s: float | None = None  # None: continuous model; else sampled at this Ts
    #: The paper mode's drift coupling (kp N/m, wc rad/s) in the loop (common/model/drift.py);
    #: None: the paper's loop exactly.
    drift: tuple[float, float] | None = None

    @property
    def grid(self) -> FrequencyGrid:
        return FrequencyGrid(self.max_frequency_rad_s)


@dataclass(frozen=True)
class AxisAnalysis:
    """Verdicts for one axis at gain ``k`` and round-trip delay ``delay_s``."""

    axis: str
    k: float
    delay_s: float
    stable: bool
    delay_margin_s: float | None
    crossing_frequency_rad_s: float | None
    k_max: float | None
    k_max_capped: bool
    k_max_delay_independent: float | None
    max_delayed_ratio: float
    eq30_satisfied: bool
    eq30_worst_ratio: float
    eq30_worst_frequency_rad_s: float
    eq30_k_bound: float | None
    eq30_unbounded_at_low_frequency: bool


@dataclass(frozen=True)
class Analysis:
    """The analysis of a configuration: overall verdicts (worst axis) and per axis."""

    k: float
    delay_s: float
    sampled: bool
    sample_period_s: float
    stable: bool
    delay_margin_s: float | None
    k_max: float | None
    k_max_delay_independent: float | None
    eq30_satisfied: bool
    eq30_worst_ratio: float
    axes: tuple[AxisAnalysis, ...]

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict (``axes`` keyed by axis name)."""
        data = asdict(self)
        data["axes"] = {axis.axis: asdict(axis) for axis in self.axes}
        return data


def axis_loop(
    model: TeleopModel, axis: AxisModel, k: float, settings: AnalysisSettings
) -> AxisLoop:
    """The loop of ``axis`` with the compensators synthesized for gain ``k``."""
    gained = model.with_gain(k)
    return AxisLoop(axis, synthesize_axis(axis, gained.ch1), settings.sample_period_s,
                    settings.drift)


def _stable_at(model: TeleopModel, axis: AxisModel, k: float, delay_s: float,
               settings: AnalysisSettings) -> bool:
    try:
        loop = axis_loop(model, axis, k, settings)
    except SynthesisError:
        return False
    return is_stable(loop, delay_s, settings.grid)


def _delay_independent_at(model: TeleopModel, axis: AxisModel, k: float,
                          settings: AnalysisSettings) -> bool:
    try:
        loop = axis_loop(model, axis, k, settings)
    except SynthesisError:
        return False
    return is_stable(loop, 0.0, settings.grid) and max_delayed_ratio(loop, settings.grid)[0] < 1.0


def largest_gain(predicate, max_gain_k: float) -> tuple[float | None, bool]:
    """The largest k in (0, max_gain_k] below which ``predicate(k)`` holds throughout the
    scan; ``(None, False)`` if it fails at the smallest trial gain, ``(max, True)`` if it
    never fails (capped)."""
    trials = np.geomspace(max_gain_k * 1e-4, max_gain_k, GAIN_SCAN_POINTS)
    last_good = None
    for trial in trials:
        if predicate(float(trial)):
            last_good = float(trial)
            continue
        if last_good is None:
            return None, False
        low, high = last_good, float(trial)
        for _ in range(GAIN_BISECTION_STEPS):
            middle = np.sqrt(low * high)
            if predicate(middle):
                low = middle
            else:
                high = middle
        return low, False
    return float(max_gain_k), True


def analyse_axis(model: TeleopModel, axis: AxisModel, k: float, delay_s: float,
                 settings: AnalysisSettings) -> AxisAnalysis:
    """All verdicts for one axis."""
    loop = axis_loop(model, axis, k, settings)
    grid = settings.grid
    margin = delay_margin(loop, settings.max_delay_s, grid)
    ratio, _ = max_delayed_ratio(loop, grid)
    k_max, capped = largest_gain(lambda g: _stable_at(model, axis, g, delay_s, settings),
                                 settings.max_gain_k)
    k_independent, _ = largest_gain(lambda g: _delay_independent_at(model, axis, g, settings),
                                    settings.max_gain_k)
    omega = grid.log_points(1e-3)
    eq30 = check_eq30(axis, model.with_gain(k).ch1, omega)
    unit_gain_eq30 = check_eq30(axis, model.with_gain(1.0).ch1, omega)
    linear_in_k = bool(np.all(axis.handle_compliance_sh.num[0][0] == 0))
    return AxisAnalysis(
        axis=axis.name,
        k=k,
        delay_s=delay_s,
        stable=is_stable(loop, delay_s, grid),
        delay_margin_s=margin.delay_margin_s,
        crossing_frequency_rad_s=margin.crossing_frequency_rad_s,
        k_max=k_max,
        k_max_capped=capped,
        k_max_delay_independent=k_independent,
        max_delayed_ratio=ratio,
        eq30_satisfied=eq30.satisfied,
        eq30_worst_ratio=eq30.worst_ratio,
        eq30_worst_frequency_rad_s=eq30.worst_frequency_rad_s,
        eq30_k_bound=(1.0 / unit_gain_eq30.worst_ratio
                      if linear_in_k and not eq30.unbounded_at_low_frequency else None),
        eq30_unbounded_at_low_frequency=eq30.unbounded_at_low_frequency,
    )


def _minimum(values: list[float | None]) -> float | None:
    """The smallest bound over the axes; None (no stable gain) if any axis has none."""
    return None if any(v is None for v in values) else min(values)


def analyse(model: TeleopModel, k: float | None = None, delay_s: float = 0.0,
            settings: AnalysisSettings | None = None) -> Analysis:
    """Analyse every axis of ``model`` at gain ``k`` (the model's own by default) and
    round-trip delay ``delay_s``."""
    settings = settings or AnalysisSettings()
    gain = model.ch1_gain_k if k is None else float(k)
    model.with_gain(gain)  # validates the gain
    axes = tuple(analyse_axis(model, axis, gain, delay_s, settings) for axis in model.axes)
    margins = [a.delay_margin_s for a in axes]
    finite_margins = [m for m in margins if m is not None]
    return Analysis(
        k=gain,
        delay_s=delay_s,
        sampled=settings.sample_period_s is not None,
        sample_period_s=model.sample_period_s,
        stable=all(a.stable for a in axes),
        delay_margin_s=min(finite_margins) if finite_margins else None,
        k_max=_minimum([a.k_max for a in axes]),
        k_max_delay_independent=_minimum([a.k_max_delay_independent for a in axes]),
        eq30_satisfied=all(a.eq30_satisfied for a in axes),
        eq30_worst_ratio=max(a.eq30_worst_ratio for a in axes),
        axes=axes,
    )
