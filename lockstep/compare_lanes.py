"""The comparison's lane simulator for the laws of common/control: wave variables,
four-channel (plain, and with the TDPA on its ports) and model-mediated teleoperation, every
cell of a control one lane.

One tick (period ``Ts``), every lane at once:

1. the operator's hand and the environment give the measured forces from the devices' state:
   ``fh`` on the handle (free-sine: a spring and damper towards the sine; wall: the intent
   force through the paper's operator impedance; clay-cut: the clay sweep's steady push
   through the same impedance), ``fe`` the tool applies to the wall (``max(0, k p + b v)``
   inside, common/control/tasks.py's law with each lane's stiffness) or to the clay (the
   constant-rate scenario's Warp clay, which the paper's and TDPA's clay cells also cut);
2. the master reads the tool line and steps its law (a Warp kernel over the lanes), then
   sends on the handle line;
3. the slave reads the handle line and steps its law, then sends on the tool line;
4. each device, a mass and damper under a servo (implicit Euler in the servo and the damping:
   stable at any gain), follows its law's command under the external force (``+fh`` on the
   handle, ``-fe`` on the tool): a position and velocity servo, its position command the
   law's (four-channel, the model-mediated master) or the integral of the law's velocity
   command (wave variables, the model-mediated slave), kept within the servo's force limit
   of the device's position (anti-windup: blocked by a wall, an integral would grow and push
   with the servo's whole stiffness).

The hand's mass rides on the handle (the master device's mass includes it; the force sensor
does not see it). Positions start at 0; the tool's coordinates are the handle's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from haptic.common.config.scenario import load_scenario
from haptic.common.control.law_pairs import (
    HANDLE_DEVICE_DAMPING_N_S_PER_M,
    HANDLE_DEVICE_MASS_KG,
    LANE_CONTROLS,
    PAIRS,
    PERIOD_S,
    TOOL_DEVICE_DAMPING_N_S_PER_M,
    TOOL_DEVICE_MASS_KG,
    ControlPair,
    Device,
    four_channel_gains,
)
from haptic.common.control.law_settings import LawSettings
from haptic.common.control.tasks import free_motion_sine
from haptic.common.runtime.gc_pauses import frozen_heap
from haptic.lockstep.compare_grid import CompareGrid, Lane
from haptic.lockstep.compare_links import lane_lines
from haptic.lockstep.compare_records import LaneRecords
from haptic.slave_sim.environment import ClayEnvironment


@dataclass(frozen=True)
class LaneTasks:
    """The task of each lane as arrays: which lanes push into a wall and its stiffness, which
    cut the clay."""

    wall: np.ndarray  # (lanes,) bool
    stiffness_N_per_m: np.ndarray  # (lanes,)
    clay: np.ndarray  # (lanes,) bool

    @classmethod
    def of(cls, lanes: list[Lane]) -> LaneTasks:
        return cls(np.array([lane.task == "wall" for lane in lanes]),
                   np.array([lane.wall_stiffness_N_per_m for lane in lanes]),
                   np.array([lane.task == "clay-cut" for lane in lanes]))


class LaneClay:
    """The constant-rate scenario's Warp clay (a 10 cm block at 100 N s/m from x = 2 cm, the
    tool starting at 0, as in the lockstep's clay cells) on the clay-cut lanes only: each
    lane its own workpiece, cut along the tool's move of each period."""

    def __init__(self, tasks: LaneTasks) -> None:
        self.lanes = np.flatnonzero(tasks.clay)
        self.clay = None
        if self.lanes.size:
            self.clay = ClayEnvironment(load_scenario("constant-rate"), PERIOD_S, "warp", "cpu")
            self.state = self.clay.initial_state(self.lanes.size)
            self.previous_m = np.zeros((self.lanes.size, 2))

    def force_N(self, position_m: np.ndarray, velocity_m_per_s: np.ndarray) -> np.ndarray:
        """The force the tool applies to the clay (lanes, 2), N, 0 on the other lanes; the
        tool moved to ``position_m`` since the last call."""
        force = np.zeros_like(position_m)
        if self.clay is None:
            return force
        position, velocity = position_m[self.lanes], velocity_m_per_s[self.lanes]
        # a diverged lane's tool stays where it was for the clay and gets no force (as the
        # wall gives none to a non-finite position); its records show the divergence
        finite = (np.isfinite(position).all(axis=1) & np.isfinite(velocity).all(axis=1))[:, None]
        position = np.where(finite, position, self.previous_m)
        cut = self.clay.step(self.state, self.previous_m, position,
                             np.where(finite, velocity, 0.0), np.zeros_like(position))
        self.previous_m = position
        force[self.lanes] = np.where(finite & np.isfinite(cut.force_N), cut.force_N, 0.0)
        return force


def hand_force_N(grid: CompareGrid, tasks: LaneTasks, time_s: float, duration_s: float,
                 position_m: np.ndarray, velocity_m_per_s: np.ndarray) -> np.ndarray:
    """The operator's force on the handle (lanes, 2), N (see the module's docstring)."""
    task = grid.task
    target, target_rate = free_motion_sine(np.array([time_s]), task.sine_amplitude_m,
                                           task.sine_frequency_hz)
    track = (task.track_stiffness_N_per_m * (target - position_m)
             + task.track_damping_N_s_per_m * (target_rate - velocity_m_per_s))
    intent = np.zeros((2, 2))
    intent[0, 0] = task.push_force_N * min(1.0, time_s / (0.5 * duration_s))
    intent[1, 0] = task.cut_push_force_N * min(1.0, time_s / task.cut_rise_s)
    push = (np.where(tasks.clay[:, None], intent[1], intent[0])
            - task.hand_damping_N_s_per_m * velocity_m_per_s
            - task.hand_stiffness_N_per_m * position_m)
    return np.where((tasks.wall | tasks.clay)[:, None], push, track)


def wall_force_N(grid: CompareGrid, tasks: LaneTasks, position_m: np.ndarray,
                 velocity_m_per_s: np.ndarray) -> np.ndarray:
    """The force the tool applies to the wall (lanes, 2), N: ``max(0, k p + b v)`` along +x
    inside it, 0 outside and on the free-motion lanes."""
    depth = position_m[:, 0] - grid.task.wall_surface_m
    push = np.where(depth > 0.0, np.maximum(
        tasks.stiffness_N_per_m * depth + grid.task.wall_damping_N_s_per_m
        * velocity_m_per_s[:, 0], 0.0), 0.0)
    force = np.zeros_like(position_m)
    force[:, 0] = np.where(tasks.wall, push, 0.0)
    return force


def lane_devices(grid: CompareGrid, lanes: int) -> tuple[Device, Device]:
    """The handle (the hand's mass riding on it) and the tool devices at rest at 0, over
    ``lanes`` lanes: the lane simulator's and the real-link cells'."""
    return (Device.at_rest(HANDLE_DEVICE_MASS_KG + grid.task.hand_mass_kg,
                           HANDLE_DEVICE_DAMPING_N_S_PER_M, lanes),
            Device.at_rest(TOOL_DEVICE_MASS_KG, TOOL_DEVICE_DAMPING_N_S_PER_M, lanes))


def simulate_lanes(control: str, lanes: list[Lane], grid: CompareGrid,
                   settings: LawSettings | None = None) -> LaneRecords:
    """Run ``control`` (one of :data:`LANE_CONTROLS`) on every lane for the grid's
    duration, built with ``settings`` (default: the comparison's, at :data:`PERIOD_S`); the
    records of the task axis."""
    if control not in PAIRS:
        raise ValueError(f"the lane simulator runs {', '.join(LANE_CONTROLS)} (got {control!r})")
    count = len(lanes)
    duration = grid.duration_s
    steps = int(round(duration / PERIOD_S))
    pair: ControlPair = PAIRS[control](count, settings)
    handle_initial, tool_initial = pair.initial_messages(count)
    handle_line, tool_line = lane_lines(lanes, steps, PERIOD_S, grid.seed, handle_initial,
                                        tool_initial)
    tasks = LaneTasks.of(lanes)
    clay = LaneClay(tasks)
    handle, tool = lane_devices(grid, count)
    records = LaneRecords.create(PERIOD_S, steps, count)
    # the heap from before the run frozen, as in LockstepSimulator.run: no full collection
    # of the program's objects in mid-run
    with np.errstate(over="ignore", invalid="ignore"), frozen_heap(collect=False):
        for k in range(steps):
            fh = hand_force_N(grid, tasks, k * PERIOD_S, duration, handle.position_m,
                              handle.velocity_m_per_s)
            fe = (wall_force_N(grid, tasks, tool.position_m, tool.velocity_m_per_s)
                  + clay.force_N(tool.position_m, tool.velocity_m_per_s))
            records.add(k, handle.position_m[:, 0], tool.position_m[:, 0], fh[:, 0], fe[:, 0])
            tool_message = tool_line.receive(k)
            master_command = pair.master(fh, tool_message, tool_line.fresh, handle_line.slot(k))
            handle_message = handle_line.receive(k)
            slave_command = pair.slave(fe, tool.position_m, tool.velocity_m_per_s,
                                       handle_message, handle_line.fresh, tool_line.slot(k))
            handle.step(*master_command, fh)
            tool.step(*slave_command, -fe)
    return records


def lane_steps(grid: CompareGrid) -> int:
    """Ticks of a run of ``grid``."""
    return int(math.floor(grid.duration_s / PERIOD_S + 0.5))


__all__ = ["LANE_CONTROLS", "PERIOD_S", "four_channel_gains", "lane_devices", "lane_steps",
           "simulate_lanes"]
