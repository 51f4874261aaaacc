"""The comparison's real-link cells: each control on the wall and the free-motion sine at
200 ms and 1 s round trip with 5 % independent loss over real Zenoh links, beside the
lockstep's cell of the same network, with the agreements counted (docs/architectures.md).
The quick set (CI) runs the wall cells only, with a shorter settling time.

A real-link cell runs one lane in real time at Ts: the lane laws (wave, four-channel with and
without its TDPA, mmt: compare_lanes.py's ``LANE_CONTROLS``) over
:class:`~haptic.common.wire.law_link.LawLink` objects carrying their own messages
(lockstep/compare_real_link_lanes.py), the paper's scheme and TDPA as the programs' ticks over
:class:`~haptic.common.wire.link.Link` objects (lockstep/compare_real_link_paper.py); the
delay and the loss are the links' own injection on their receive paths, not re-simulated.
Its lockstep counterpart is the comparison's lane simulator (or the lockstep simulator) on the
same task, network and duration; both are judged by the comparison's bounds
(lockstep/compare_records.py). The cell reports the round trip it measured: a loop that
stalls on a loaded machine skips ticks, so a wall-clock delay then spans fewer of them. A
cell is on target when at least :data:`ON_TARGET_SHARE` of its ticks held messages whose
round trip lies within :data:`ON_TARGET_BAND` of the network's; one that is not is run again
(at most :data:`ATTEMPTS` runs in all) and, if still off target, also set beside the lockstep
at the round trip it measured. The count that decides (``disagreements_on_target``) is over
the cells on target.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from haptic.common.control.law_pairs import LANE_CONTROLS, PERIOD_S
from haptic.common.model.teleop import TeleopModel
from haptic.lockstep.compare_grid import CompareGrid, Lane, TaskSettings
from haptic.lockstep.compare_paper import PAPER_CONTROLS
from haptic.lockstep.compare_real_link_lanes import RealLinkRun, run_lane_law_cell
from haptic.lockstep.compare_real_link_links import cell_link_configs
from haptic.lockstep.compare_real_link_paper import run_paper_cell
from haptic.lockstep.compare_records import LaneRecords, bounded_lanes, cell_figures
from haptic.lockstep.compare_simulate import simulate_control

#: The networks of the real-link cells: round trips (s), independent loss.
REAL_LINK_ROUND_TRIPS_S = (0.2, 1.0)
REAL_LINK_LOSS = 0.05
REAL_LINK_TASKS = ("wall", "free-sine")
#: The quick (CI) set's tasks: the wall contact only.
QUICK_REAL_LINK_TASKS = ("wall",)
#: Simulated time after the round trip, s: the full set's and the quick set's.
REAL_LINK_SETTLE_S = 3.0
QUICK_REAL_LINK_SETTLE_S = 2.0
#: A tick's round trip further than this share from the network's is off target ...
ON_TARGET_BAND = 0.1
#: ... and a cell is on target when at least this share of its ticks is not.
ON_TARGET_SHARE = 0.9
#: Runs of a cell at most, while it lands off target.
ATTEMPTS = 2


@dataclass(frozen=True)
class RealLinkSet:
    """Which real-link cells to run: controls x tasks x round trips (s), at ``loss``, each
    ``round trip + settle_s`` long; ``seed`` for the lockstep's draws and the links'."""

    controls: tuple[str, ...]
    tasks: tuple[str, ...] = REAL_LINK_TASKS
    round_trips_s: tuple[float, ...] = REAL_LINK_ROUND_TRIPS_S
    loss: float = REAL_LINK_LOSS
    settle_s: float = REAL_LINK_SETTLE_S
    seed: int = 0

    @classmethod
    def quick(cls, controls: tuple[str, ...], seed: int = 0) -> RealLinkSet:
        """The CI set: the wall cells only, :data:`QUICK_REAL_LINK_SETTLE_S` of settling."""
        return cls(controls, QUICK_REAL_LINK_TASKS, settle_s=QUICK_REAL_LINK_SETTLE_S,
                   seed=seed)

    def grid(self, control: str, round_trip_s: float) -> CompareGrid:
        """The comparison grid of one control's cells at one round trip (no Z-width
        ladder)."""
        return CompareGrid((control,), self.tasks, (round_trip_s,), (self.loss,),
                           ("independent",), (0.0,), (), TaskSettings(settle_s=self.settle_s),
                           seed=self.seed)


def _real_run(control: str, lane: Lane, grid: CompareGrid, model: TeleopModel | None,
              seed: int) -> RealLinkRun:
    configs = cell_link_configs(lane.network.round_trip_s, lane.network.loss, seed)
    if control in PAPER_CONTROLS:
        if model is None:
            raise ValueError(f"{control} needs the paper's model")
        return run_paper_cell(control, lane, grid, model, configs)
    if control not in LANE_CONTROLS:
        raise ValueError(f"unknown control {control!r}")
    return run_lane_law_cell(control, lane, grid, configs)


def _verdict(records: LaneRecords, index: int, lane: Lane, grid: CompareGrid,
             surface_m: float) -> dict[str, Any]:
    """``bounded`` and the cell's figures of lane ``index``."""
    bounded = bool(bounded_lanes(records, grid.bounds)[index])
    return {"bounded": bounded, **cell_figures(records, index, lane, surface_m)}


def real_link_cell(control: str, lane: Lane, grid: CompareGrid, model: TeleopModel | None,
                   lockstep: dict[str, Any], seed: int) -> dict[str, Any]:
    """One real-link cell beside its lockstep cell (``lockstep``: its verdict and figures),
    run again while it lands off target (at most :data:`ATTEMPTS` runs; the last is kept)."""
    surface = 0.0 if control in PAPER_CONTROLS else grid.task.wall_surface_m
    period = model.sample_period_s if control in PAPER_CONTROLS and model else PERIOD_S
    network = lane.network
    for attempt in range(1, ATTEMPTS + 1):
        started = time.perf_counter()
        run = _real_run(control, lane, grid, model, seed + 100 * (attempt - 1))
        wall = time.perf_counter() - started
        share = run.lags.share_within(network.round_trip_s, ON_TARGET_BAND, period)
        on_target = share >= ON_TARGET_SHARE
        if on_target:
            break
    measured = run.lags.round_trip_s(period)
    real = {**_verdict(run.records, 0, lane, grid, surface),
            "measured_round_trip_s": measured if np.isfinite(measured) else None,
            "on_target_share": round(share, 4), "attempts": attempt,
            "steps": run.runner.steps,
            "overruns": run.runner.overruns, "stalls": run.runner.stalls,
            "skipped_ticks": run.runner.skipped_ticks, "links": run.links,
            "wall_seconds": round(wall, 3)}
    return {"control": control, "task": lane.task, "round_trip_s": network.round_trip_s,
            "loss": network.loss, "loss_model": network.loss_model,
            "jitter_s": network.jitter_s, "duration_s": grid.duration_s,
            "real_link": real, "lockstep": lockstep,
            "agree": real["bounded"] == lockstep["bounded"], "on_target": on_target}


def lockstep_at_measured(cells: RealLinkSet, row: dict[str, Any],
                         model: TeleopModel | None) -> dict[str, Any] | None:
    """The lockstep's verdict of an off-target cell's task at the round trip the real link
    measured (same duration and loss; None when none was measured): what the loop that ran
    should be compared with."""
    measured = row["real_link"]["measured_round_trip_s"]
    if measured is None:
        return None
    control = row["control"]
    settle = cells.settle_s + row["round_trip_s"] - measured
    grid = CompareGrid((control,), (row["task"],), (measured,), (cells.loss,),
                       ("independent",), (0.0,), (), TaskSettings(settle_s=settle),
                       seed=cells.seed)
    lanes = grid.cell_lanes(control)
    records = simulate_control(control, lanes, grid, model)
    surface = 0.0 if control in PAPER_CONTROLS else grid.task.wall_surface_m
    bounded = _verdict(records, 0, lanes[0], grid, surface)["bounded"]
    return {"round_trip_s": measured, "bounded": bounded,
            "agree": bounded == row["real_link"]["bounded"]}


def run_real_link_cells(cells: RealLinkSet, model: TeleopModel | None = None
                        ) -> dict[str, Any]:
    """Every cell of ``cells``, each beside its lockstep cell (an off-target one also beside
    the lockstep at its measured round trip, ``lockstep_at_measured``); the JSON's
    ``real_link``: ``cells``, ``agreements``, ``disagreements`` (those on target and in
    all), ``off_target`` and ``wall_seconds``."""
    started = time.perf_counter()
    rows = []
    for control in cells.controls:
        for round_trip in cells.round_trips_s:
            grid = cells.grid(control, round_trip)
            lanes = grid.cell_lanes(control)
            records = simulate_control(control, lanes, grid, model)
            surface = 0.0 if control in PAPER_CONTROLS else grid.task.wall_surface_m
            for index, lane in enumerate(lanes):
                lockstep = _verdict(records, index, lane, grid, surface)
                seed = cells.seed * 1000 + len(rows)
                row = real_link_cell(control, lane, grid, model, lockstep, seed)
                if not row["on_target"]:
                    row["lockstep_at_measured"] = lockstep_at_measured(cells, row, model)
                rows.append(row)
    return {"settings": {"controls": list(cells.controls), "tasks": list(cells.tasks),
                         "round_trips_s": list(cells.round_trips_s), "loss": cells.loss,
                         "loss_model": "independent", "settle_s": cells.settle_s,
                         "on_target_band": ON_TARGET_BAND,
                         "on_target_share": ON_TARGET_SHARE, "attempts": ATTEMPTS},
            "cells": rows,
            "agreements": sum(row["agree"] for row in rows),
            "disagreements": sum(not row["agree"] for row in rows),
            "disagreements_on_target": sum(not row["agree"] and row["on_target"]
                                           for row in rows),
            "off_target": sum(not row["on_target"] for row in rows),
            "wall_seconds": round(time.perf_counter() - started, 3)}


def _figure(value: float | None, scale: float = 1.0, digits: int = 3) -> str:
    return "-" if value is None else f"{value * scale:.{digits}g}"


def _at_measured(row: dict[str, Any]) -> str:
    """An off-target cell's lockstep verdict at its measured round trip, as text."""
    at = row.get("lockstep_at_measured")
    if at is None:
        return ""
    return (f" (lockstep at the measured round trip: "
            f"{'bounded' if at['bounded'] else 'unbounded'}, "
            f"{'agree' if at['agree'] else 'DISAGREE'})")


def real_link_text(result: dict[str, Any]) -> str:
    """One line per real-link cell and a closing count."""
    lines = []
    for row in result["cells"]:
        real, lock = row["real_link"], row["lockstep"]
        verdict = {True: "bounded", False: "unbounded"}
        lines.append(
            f"real link {row['control']:13s} {row['task']:9s} "
            f"{row['round_trip_s'] * 1e3:5.0f} ms (measured "
            f"{_figure(real['measured_round_trip_s'], 1e3, 4)} ms"
            f"{'' if row['on_target'] else ', off target'}): {verdict[real['bounded']]}, "
            f"lockstep {verdict[lock['bounded']]}  {'agree' if row['agree'] else 'DISAGREE'}"
            f"  peak {_figure(real['peak_force_N'])} N ({_figure(lock['peak_force_N'])})"
            f"{_at_measured(row)}"
            f"  rms pos {_figure(real['rms_position_error_m'], 1e3)} mm "
            f"({_figure(lock['rms_position_error_m'], 1e3)})  overruns {real['overruns']}"
            + (f", {real['attempts']} runs" if real["attempts"] > 1 else ""))
    lines.append(f"real link: {result['agreements']}/{len(result['cells'])} agree with the "
                 f"lockstep ({result['disagreements_on_target']} disagreements on target, "
                 f"{result['off_target']} off target) in {result['wall_seconds']:.0f} s wall")
    return "\n".join(lines)


__all__ = ["ON_TARGET_BAND", "QUICK_REAL_LINK_TASKS", "REAL_LINK_LOSS",
           "REAL_LINK_ROUND_TRIPS_S", "REAL_LINK_TASKS", "RealLinkSet", "lockstep_at_measured",
           "real_link_cell", "real_link_text", "run_real_link_cells"]
