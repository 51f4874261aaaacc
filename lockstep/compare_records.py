"""What a comparison run keeps of its lanes and the cell figures computed from it.

Both lane simulators (lockstep/compare_lanes.py, lockstep/compare_paper.py) fill the same
:class:`LaneRecords`: the task axis (x) of the handle's and the tool's positions, the
operator's force on the handle and the force the tool applies to its environment, every
``stride`` samples, with the peaks over every sample. Positions are in the handle's
coordinates (the tool's map one to one), forces in the same sense (positive along +x).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from haptic.common.control.metrics import (
    final_position_gap_m,
    impact_overshoot_ratio,
    perceived_stiffness_ratio,
    rms_force_error_N,
    rms_position_error_m,
)
from haptic.lockstep.compare_grid import BoundSettings, Lane

#: Records keep one sample in RECORD_STRIDE (the peaks see every sample).
RECORD_STRIDE = 4
#: The final gap is the mean over this share of the run's end.
FINAL_SHARE = 0.1
#: The clay cut's force is the mean over the tool's positions in the first range, its speed
#: the mean over the second (m, the constant-rate block spans 2 to 12 cm), as the paper's
#: reproduction measures them (docs/lockstep.md).
CUT_FORCE_RANGE_M = (0.04, 0.10)
CUT_SPEED_RANGE_M = (0.02, 0.12)


@dataclass(eq=False)
class LaneRecords:
    """(records, lanes) arrays every ``stride`` samples of period ``period_s`` (s), and per
    lane the peak |force| over every sample (N) and whether a sample was non-finite."""

    period_s: float
    stride: int
    handle_position_m: np.ndarray
    tool_position_m: np.ndarray
    handle_force_N: np.ndarray
    environment_force_N: np.ndarray
    peak_force_N: np.ndarray
    non_finite: np.ndarray

    @classmethod
    def create(cls, period_s: float, steps: int, lanes: int,
               stride: int = RECORD_STRIDE) -> LaneRecords:
        """Empty records for ``steps`` samples of ``lanes`` lanes."""
        rows = (steps + stride - 1) // stride
        return cls(period_s, stride, *(np.full((rows, lanes), np.nan) for _ in range(4)),
                   np.zeros(lanes), np.zeros(lanes, bool))

    def add(self, tick: int, handle_m: np.ndarray, tool_m: np.ndarray, handle_force_N: np.ndarray,
            environment_force_N: np.ndarray) -> None:
        """Sample ``tick``'s task-axis values (lanes,): the peaks always, the rows every
        ``stride`` ticks."""
        with np.errstate(invalid="ignore"):
            np.fmax(self.peak_force_N, np.abs(handle_force_N), out=self.peak_force_N)
            np.fmax(self.peak_force_N, np.abs(environment_force_N), out=self.peak_force_N)
        self.non_finite |= ~(np.isfinite(handle_m) & np.isfinite(tool_m)
                             & np.isfinite(handle_force_N) & np.isfinite(environment_force_N))
        if tick % self.stride == 0:
            row = tick // self.stride
            self.handle_position_m[row] = handle_m
            self.tool_position_m[row] = tool_m
            self.handle_force_N[row] = handle_force_N
            self.environment_force_N[row] = environment_force_N

    @property
    def record_period_s(self) -> float:
        """Time between rows, s."""
        return self.period_s * self.stride


def kinetic_energy_tail_J(records: LaneRecords, bounds: BoundSettings) -> np.ndarray:
    """Per lane, the devices' mean kinetic energy over the last quarter of the run (J) in the
    speeds' deviation from their straight-line trend over that quarter, from the recorded
    positions' differences and the bound's device masses. The trend is taken out because the
    bound looks for a sustained oscillation: a device the operator still drives steadily
    (the clay cut's tool, through the block and on towards the hand's rest 0.6 m away, at
    0.2 m/s: 27 mJ) is moving, not unstable."""
    rows = records.handle_position_m.shape[0]
    tail = slice(max(0, rows - max(3, rows // 4)), rows)
    dt = records.record_period_s
    energy = np.zeros(records.handle_position_m.shape[1])
    with np.errstate(invalid="ignore", over="ignore"):
        for positions, mass in ((records.handle_position_m, bounds.master_mass_kg),
                                (records.tool_position_m, bounds.slave_mass_kg)):
            speed = np.diff(positions[tail], axis=0) / dt
            time = np.arange(speed.shape[0], dtype=float)[:, None]
            centred = time - time.mean()
            slope = np.sum(centred * speed, axis=0) / np.sum(centred * centred)
            deviation = speed - speed.mean(axis=0) - centred * slope
            energy = energy + 0.5 * mass * np.mean(deviation * deviation, axis=0)
    return np.where(np.isfinite(energy), energy, np.inf)


def bounded_lanes(records: LaneRecords, bounds: BoundSettings) -> np.ndarray:
    """Per lane: every sample finite, no force above the bound, the tail's energy under its
    bound (:class:`~haptic.lockstep.compare_grid.BoundSettings`)."""
    return (~records.non_finite & (records.peak_force_N <= bounds.force_bound_N)
            & (kinetic_energy_tail_J(records, bounds) <= bounds.energy_bound_J))


def _number(value: float) -> float | None:
    """A JSON-safe figure: None for NaN or infinity."""
    value = float(value)
    return value if math.isfinite(value) else None


def _in_range(position_m: np.ndarray, bounds_m: tuple[float, float]) -> np.ndarray:
    with np.errstate(invalid="ignore"):
        return (position_m >= bounds_m[0]) & (position_m <= bounds_m[1])


def _cut_figures(records: LaneRecords, tool_m: np.ndarray, force_N: np.ndarray
                 ) -> dict[str, float | None]:
    """The clay cut's mean force (N) and speed (m/s) over the tool's ranges (None: the tool
    never got there)."""
    figures: dict[str, float | None] = {"cut_force_N": None, "cut_speed_m_per_s": None}
    in_force = _in_range(tool_m, CUT_FORCE_RANGE_M)
    if in_force.any():
        figures["cut_force_N"] = _number(np.mean(force_N[in_force]))
    speed = np.diff(tool_m) / records.record_period_s
    in_speed = _in_range(tool_m[:-1], CUT_SPEED_RANGE_M)
    if in_speed.any():
        figures["cut_speed_m_per_s"] = _number(np.mean(speed[in_speed]))
    return figures


def cell_figures(records: LaneRecords, lane_index: int, lane: Lane, wall_surface_m: float
                 ) -> dict[str, float | None]:
    """The cell's figures from its lane's records (docs/architectures.md): the force and
    position errors and the final gap over the whole run; for the wall task the impact
    overshoot of the environment force from the first contact and the stiffness the operator
    feels over the contact samples; for the clay cut its force and speed. None where a figure
    does not exist (free motion has no contact; a diverged lane has no finite figure)."""
    handle = records.handle_position_m[:, lane_index]
    tool = records.tool_position_m[:, lane_index]
    fh = records.handle_force_N[:, lane_index]
    fe = records.environment_force_N[:, lane_index]
    final = max(1, int(round(handle.size * FINAL_SHARE)))
    figures: dict[str, float | None] = {
        "peak_force_N": _number(records.peak_force_N[lane_index]),
        "rms_position_error_m": _number(rms_position_error_m(handle, tool)),
        "rms_force_error_N": _number(rms_force_error_N(fh, fe)),
        "final_position_gap_m": _number(final_position_gap_m(handle, tool, final)),
        "impact_overshoot_ratio": None,
        "perceived_stiffness_ratio": None,
        "cut_force_N": None,
        "cut_speed_m_per_s": None,
    }
    if lane.task == "clay-cut":
        figures.update(_cut_figures(records, tool, fe))
    if lane.task != "wall":
        return figures
    contact = np.isfinite(tool) & (tool > wall_surface_m)
    if contact.any():
        impact = int(np.argmax(contact))
        figures["impact_overshoot_ratio"] = _number(impact_overshoot_ratio(fe[impact:]))
        figures["perceived_stiffness_ratio"] = _number(perceived_stiffness_ratio(
            handle, fh, lane.wall_stiffness_N_per_m, contact))
    return figures


__all__ = ["RECORD_STRIDE", "LaneRecords", "bounded_lanes", "cell_figures",
           "kinetic_energy_tail_J"]
