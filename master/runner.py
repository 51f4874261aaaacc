"""The master's own loop: hardware lifecycle, read -> node -> write once per Ts.

This runner drives the handle alone (no slave link: the received tool force is zero or
comes from ``tool_force_source``); the networked real-time runner composes the same node.
Pacing (when asked) sleeps until about 0.3 ms before each deadline, then spins, and
re-anchors the schedule after a stall instead of firing missed cycles back to back.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from haptic.master.hardware import HandleHardware
from haptic.master.node import MasterNode, SafetyEvent

SPIN_MARGIN_S = 0.0003


@dataclass(frozen=True)
class MasterTrace:
    """Per-cycle record (cycles, 2): what the node saw and what it commanded."""

    handle_force_N: np.ndarray
    handle_position_m: np.ndarray
    handle_command_m: np.ndarray
    force_scale: np.ndarray  # (cycles,) force ramp factor 0..1 applied in the cycle


@dataclass(frozen=True)
class RunSummary:
    """What a run did: cycles, overruns (paced runs), the final position, the events."""

    cycles: int
    wall_time_s: float
    overruns: int
    max_lateness_s: float
    final_position_m: tuple[float, float]
    safe_state: bool
    events: list[SafetyEvent] = field(default_factory=list)
    hardware_faults: list[str] = field(default_factory=list)
    trace: MasterTrace | None = None


def run_master(
    hardware: HandleHardware,
    node: MasterNode,
    cycles: int,
    pace: bool = True,
    tool_force_source: Callable[[int], np.ndarray] | None = None,
    record: bool = False,
    on_cycle: Callable[[int], None] | None = None,
) -> RunSummary:
    """Configure and activate ``hardware``, run ``cycles`` control cycles, deactivate.

    ``tool_force_source(cycle)`` gives the received tool force (N, x and y); zero when
    ``None``. ``on_cycle(cycle)`` is called after each write (tests use it to inject
    faults). The hardware is left configured-inactive; the caller cleans it up.
    """
    period_s = node.period_s
    hardware.configure()
    hardware.activate()
    hardware.present_forces_enabled(True)  # alone, the master's forces are on from the start
    reading = hardware.read()
    state = node.activate(reading.position_m[None, :])
    faults: list[str] = []
    forces, positions, commands, scales = [], [], [], []
    overruns = 0
    max_lateness = 0.0
    start = time.perf_counter()
    deadline = start
    for cycle in range(cycles):
        if reading.faults:
            faults.extend(f"cycle {reading.cycle}: {f}" for f in reading.faults)
            node.trip(state, np.array([True]), "hardware: " + "; ".join(reading.faults))
        tool_force = (np.zeros(2) if tool_force_source is None
                      else np.asarray(tool_force_source(cycle), float))
        command = node.step(state, reading.force_N[None, :], reading.position_m[None, :],
                            tool_force[None, :])
        hardware.present_tool_force(tool_force)
        hardware.write(command[0])
        if record:
            forces.append(reading.force_N)
            positions.append(reading.position_m)
            commands.append(command[0])
            scales.append(float(state.force_scale[0]))
        if on_cycle is not None:
            on_cycle(cycle)
        if pace:
            deadline += period_s
            now = time.perf_counter()
            if now > deadline:
                overruns += 1
                max_lateness = max(max_lateness, now - deadline)
                deadline = now  # re-anchor after a stall
            else:
                if deadline - now > SPIN_MARGIN_S:
                    time.sleep(deadline - now - SPIN_MARGIN_S)
                while time.perf_counter() < deadline:
                    pass
        reading = hardware.read()
    wall = time.perf_counter() - start
    if reading.faults:
        faults.extend(f"cycle {reading.cycle}: {f}" for f in reading.faults)
    hardware.deactivate()
    trace = None
    if record:
        trace = MasterTrace(np.array(forces), np.array(positions), np.array(commands),
                            np.array(scales))
    final = reading.position_m
    return RunSummary(cycles, wall, overruns, max_lateness, (float(final[0]), float(final[1])),
                      bool(state.faulted[0]), list(state.events), faults, trace)
