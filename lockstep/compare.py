"""``haptic-sim compare``: every control on the same tasks, network grid and metrics
(docs/architectures.md).

Each control runs once over all its lanes: one lane per cell of the grid and one per rung of
the Z-width ladder (the wall task over a constant delay at each ladder stiffness). The laws of
common/control run in the lane simulator (lockstep/compare_lanes.py), the paper's scheme and
TDPA in the lockstep simulator (lockstep/compare_paper.py). The result holds per cell its
verdict and figures, per control and delay the Z-width, and the theories' predictions beside
the measurements with the count of disagreements (lockstep/compare_theory.py).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from haptic.common.control.law_pairs import PERIOD_S
from haptic.common.model.teleop import TeleopModel
from haptic.lockstep.compare_grid import (
    PAPER_CUT_FORCE_N,
    PAPER_CUT_SPEED_M_PER_S,
    CompareGrid,
    Lane,
)
from haptic.lockstep.compare_paper import PAPER_CONTROLS
from haptic.lockstep.compare_records import bounded_lanes, cell_figures
from haptic.lockstep.compare_simulate import simulate_control
from haptic.lockstep.compare_theory import Theory


@dataclass
class CompareResult:
    """The JSON of a comparison (see :meth:`to_json`)."""

    grid: CompareGrid
    cells: list[dict[str, Any]] = field(default_factory=list)
    z_width: list[dict[str, Any]] = field(default_factory=list)
    predictions: list[dict[str, Any]] = field(default_factory=list)
    simulated_seconds: float = 0.0
    wall_seconds: float = 0.0
    control_wall_seconds: dict[str, float] = field(default_factory=dict)

    def theory(self) -> dict[str, Any]:
        """The cells' predictions, how many were checked and how many the measurement
        contradicts, in all and per control; and the Z-widths a theory predicts whole, how
        many, and how many differ from the measured ones."""
        per_control: dict[str, dict[str, int]] = {}
        for item in self.predictions:
            counts = per_control.setdefault(item["control"], {"checked": 0, "disagreements": 0})
            counts["checked"] += 1
            counts["disagreements"] += int(not item["agree"])
        widths = [row for row in self.z_width if "predicted_z_width_N_per_m" in row]
        return {"checked": len(self.predictions),
                "disagreements": sum(not item["agree"] for item in self.predictions),
                "per_control": per_control, "predictions": self.predictions,
                "z_width_checked": len(widths),
                "z_width_disagreements": sum(row["predicted_z_width_N_per_m"]
                                             != row["z_width_N_per_m"] for row in widths)}

    def to_json(self) -> dict[str, Any]:
        """controls, grid, cells, z_width, theory, simulated_seconds, wall_seconds."""
        grid = self.grid
        return {
            "controls": list(grid.controls),
            "grid": {"tasks": list(grid.tasks), "round_trips_s": list(grid.round_trips_s),
                     "losses": list(grid.losses), "loss_models": list(grid.loss_models),
                     "jitters_s": list(grid.jitters_s),
                     "stiffness_ladder_N_per_m": list(grid.stiffness_ladder_N_per_m),
                     "duration_s": grid.duration_s, "task": asdict(grid.task),
                     "paper_cut": {"force_N": PAPER_CUT_FORCE_N,
                                   "speed_m_per_s": PAPER_CUT_SPEED_M_PER_S},
                     "bounds": asdict(grid.bounds), "seed": grid.seed},
            "cells": self.cells,
            "z_width": self.z_width,
            "theory": self.theory(),
            "simulated_seconds": round(self.simulated_seconds, 3),
            "wall_seconds": round(self.wall_seconds, 3),
            "control_wall_seconds": {k: round(v, 3) for k, v in
                                     self.control_wall_seconds.items()},
        }


def _width(rungs: list[tuple[float, bool | None]]) -> float | None:
    """The largest stiffness below which every rung is bounded (rungs sorted)."""
    width = None
    for stiffness, ok in rungs:
        if not ok:
            break
        width = stiffness
    return width


def z_width_rows(control: str, grid: CompareGrid, lanes: list[Lane], bounded: np.ndarray,
                 theory: Theory | None = None) -> list[dict[str, Any]]:
    """Per delay, the largest ladder stiffness below which every rung stayed bounded (None:
    not even the softest), with the ladder's verdicts; with ``theory``, the Z-width its
    predictions give (``predicted_z_width_N_per_m``, only where it predicts every rung)."""
    rows = []
    for round_trip in grid.round_trips_s:
        rungs = sorted((lane.wall_stiffness_N_per_m, bool(bounded[i]))
                       for i, lane in enumerate(lanes)
                       if lane.ladder and lane.network.round_trip_s == round_trip)
        row: dict[str, Any] = {"control": control, "round_trip_s": round_trip,
                               "z_width_N_per_m": _width(rungs),
                               "ladder_N_per_m": [stiffness for stiffness, _ in rungs],
                               "ladder_bounded": [ok for _, ok in rungs]}
        if theory is not None:
            predicted = [theory.predict(control, "wall", round_trip, True, stiffness)
                         for stiffness, _ in rungs]
            complete = bool(predicted) and all(p is not None and p.bounded is not None
                                               for p in predicted)
            if complete:
                row["predicted_z_width_N_per_m"] = _width(
                    [(stiffness, p.bounded) for (stiffness, _), p in zip(rungs, predicted,
                                                                         strict=True)])
        rows.append(row)
    return rows


def run_compare(grid: CompareGrid, model: TeleopModel | None = None) -> CompareResult:
    """Run every control of ``grid`` (``model``: the paper's, needed for paper and tdpa)."""
    result = CompareResult(grid)
    theory = Theory(model)
    started = time.perf_counter()
    for control in grid.controls:
        control_started = time.perf_counter()
        lanes = grid.cell_lanes(control) + grid.ladder_lanes()
        records = simulate_control(control, lanes, grid, model)
        bounded = bounded_lanes(records, grid.bounds)
        surface = 0.0 if control in PAPER_CONTROLS else grid.task.wall_surface_m
        period = model.sample_period_s if control in PAPER_CONTROLS and model else PERIOD_S
        for index, lane in enumerate(lanes):
            if lane.ladder:
                continue
            network = lane.network
            cell = {"control": control, "task": lane.task,
                    "round_trip_s": network.round_trip_s, "loss": network.loss,
                    "loss_model": network.loss_model, "jitter_s": network.jitter_s,
                    "bounded": bool(bounded[index]),
                    **cell_figures(records, index, lane, surface)}
            result.cells.append(cell)
            prediction = theory.predict(control, lane.task, network.round_trip_s,
                                        network.constant_delay, lane.wall_stiffness_N_per_m)
            if prediction is not None:
                cell["predicted_bounded"] = prediction.bounded
                if prediction.bounded is not None:
                    result.predictions.append({
                        "control": control, "task": lane.task,
                        "round_trip_s": network.round_trip_s, "theory": prediction.theory,
                        "predicted_bounded": prediction.bounded,
                        "measured_bounded": cell["bounded"],
                        "agree": prediction.bounded == cell["bounded"],
                        "margin_s": prediction.margin_s})
        result.z_width.extend(z_width_rows(control, grid, lanes, bounded, theory))
        steps = int(round(grid.duration_s / period))
        result.simulated_seconds += steps * period * len(lanes)
        result.control_wall_seconds[control] = time.perf_counter() - control_started
    result.wall_seconds = time.perf_counter() - started
    return result


def _stiffness(value: float | None) -> str:
    return "-" if value is None else format(value, "g")


def summary_text(result: CompareResult) -> str:
    """A few lines per control: bounded cells, Z-width per delay, disagreements."""
    data = result.to_json()
    lines = []
    theory = data["theory"]["per_control"]
    for control in data["controls"]:
        cells = [c for c in data["cells"] if c["control"] == control]
        bounded = sum(c["bounded"] for c in cells)
        counts = theory.get(control, {"checked": 0, "disagreements": 0})
        widths = ", ".join(
            f"{row['round_trip_s'] * 1e3:g} ms: {_stiffness(row['z_width_N_per_m'])}"
            + (f" ({_stiffness(row['predicted_z_width_N_per_m'])})"
               if "predicted_z_width_N_per_m" in row else "")
            for row in data["z_width"] if row["control"] == control)
        lines.append(f"{control:13s} bounded {bounded}/{len(cells)}  theory "
                     f"{counts['checked'] - counts['disagreements']}/{counts['checked']} agree"
                     f"  Z-width N/m (theory) [{widths}]")
    lines.append(f"simulated {data['simulated_seconds']:.0f} s in {data['wall_seconds']:.1f} s "
                 f"wall; disagreements with theory: {data['theory']['disagreements']} cells, "
                 f"{data['theory']['z_width_disagreements']} Z-widths")
    return "\n".join(lines)


__all__ = ["CompareResult", "run_compare", "summary_text", "z_width_rows"]
