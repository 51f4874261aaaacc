"""Any control's lanes in lockstep: ``paper`` and ``tdpa`` through the lockstep simulator
(lockstep/compare_paper.py), the lane laws through the lane simulator
(lockstep/compare_lanes.py). The comparison's grid and its real-link cells' counterparts both
run their lockstep cells here."""

from __future__ import annotations

from haptic.common.model.teleop import TeleopModel
from haptic.lockstep.compare_grid import CompareGrid, Lane
from haptic.lockstep.compare_lanes import simulate_lanes
from haptic.lockstep.compare_paper import PAPER_CONTROLS, simulate_paper_lanes
from haptic.lockstep.compare_records import LaneRecords


def simulate_control(control: str, lanes: list[Lane], grid: CompareGrid,
                     model: TeleopModel | None) -> LaneRecords:
    """The records of ``control`` on ``lanes``; ``model`` (the paper's) is required for
    ``paper`` and ``tdpa`` (ValueError without it)."""
    if control in PAPER_CONTROLS:
        if model is None:
            raise ValueError(f"{control} needs the paper's model")
        return simulate_paper_lanes(control, lanes, grid, model)
    return simulate_lanes(control, lanes, grid)


__all__ = ["simulate_control"]
