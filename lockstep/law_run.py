"""``haptic-sim run`` in a lane-law mode (``[control] mode`` or ``--control`` = wave,
four-channel, four-channel-tdpa, mmt): one lane of the comparison's lane simulator
(lockstep/compare_lanes.py, the law kernels both programs step) on one of its tasks over one
network, with the law's settings from ``[control]``, and the cell's figures
(lockstep/compare_records.py) as the run's summary; the records are saved as ``traces.npz``.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from haptic.common.config import ConfigError
from haptic.common.control.law_settings import PERIOD_S, LawSettings
from haptic.lockstep.compare_grid import TASKS, CompareGrid, TaskSettings
from haptic.lockstep.compare_lanes import simulate_lanes
from haptic.lockstep.compare_records import bounded_lanes, cell_figures


def run_law(control: str, settings: LawSettings, task: str, round_trip_s: float,
            loss: float, jitter_s: float, duration_s: float, seed: int,
            out: Path) -> dict[str, Any]:
    """Run ``control`` on ``task`` (one of the comparison's tasks) for ``duration_s`` (s) over
    a round trip of ``round_trip_s`` (s) with independent ``loss`` (0..1) and ``jitter_s`` (s)
    per line; returns the summary and writes ``out/traces.npz``. Raises ConfigError for a
    period other than the lane simulator's or a run no longer than the round trip."""
    if abs(settings.period_s - PERIOD_S) > 1e-12:
        raise ConfigError("model.sample_period_s", f"the lane laws run at the paper's "
                          f"{PERIOD_S:g} s in the lockstep (got {settings.period_s:g})")
    if task not in TASKS:
        raise ConfigError("--task", f"must be one of {', '.join(TASKS)} (got {task!r})")
    if not duration_s > round_trip_s:
        raise ConfigError("--duration", f"must exceed the round trip {round_trip_s:g} s")
    grid = CompareGrid((control,), (task,), (round_trip_s,), (loss,), ("independent",),
                       (jitter_s,), (), replace(TaskSettings(), settle_s=duration_s
                                                - round_trip_s), seed=seed)
    lanes = grid.cell_lanes(control)
    if not lanes:
        raise ConfigError("--task", f"{control} does not run the {task} task")
    records = simulate_lanes(control, lanes, grid, settings)
    surface = grid.task.wall_surface_m
    figures = cell_figures(records, 0, lanes[0], surface)
    out.mkdir(parents=True, exist_ok=True)
    np.savez(out / "traces.npz", time_s=np.arange(records.handle_position_m.shape[0])
             * records.period_s * records.stride,
             handle_position_x_m=records.handle_position_m[:, 0],
             tool_position_x_m=records.tool_position_m[:, 0],
             handle_force_x_N=records.handle_force_N[:, 0],
             environment_force_x_N=records.environment_force_N[:, 0])
    return {"control": control, "task": task, "round_trip_delay_s": round_trip_s,
            "loss": loss, "jitter_s": jitter_s, "duration_s": grid.duration_s,
            "bounded": bool(bounded_lanes(records, grid.bounds)[0]), **figures,
            "wave_impedance_N_s_per_m": settings.wave_impedance_N_s_per_m,
            "out": str(out)}


__all__ = ["run_law"]
