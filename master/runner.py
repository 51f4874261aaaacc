"""The master alone: hardware lifecycle, read -> node -> write once per Ts.

This drives the handle without a slave (the received tool force is zero or comes from
``tool_force_source``); the networked program composes the same node with its supervisor
(master/tick.py). The pacing is the real-time runner's (common/runtime/runner.py: sleep, spin the
last ``spin_s``, re-anchor after a stall); unpaced, its ticks run back to back
(:class:`~haptic.common.runtime.runner.FreeRunningClock`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from haptic.common.runtime.runner import FreeRunningClock, LeadFunction, RealTimeRunner
from haptic.master.hardware.interface import HandleHardware, starts_cycles_early
from haptic.master.node import MasterNode, SafetyEvent

#: The runner's spin before each deadline when paced, s.
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
    period_error_max_s: float  # the runner's largest |t_k - t_(k-1) - Ts| (paced runs), s
    final_position_m: tuple[float, float]
    safe_state: bool
    events: list[SafetyEvent] = field(default_factory=list)
    hardware_faults: list[str] = field(default_factory=list)
    trace: MasterTrace | None = None


def early_sync(hardware: HandleHardware, first_tick: int = 1) -> LeadFunction | None:
    """The runner's ``lead`` (common/runtime/runner.py, ``[master.can] sync_lead_s``) for
    ``hardware`` that starts its cycles early (the CAN backends): ``hardware.sync()`` from
    tick ``first_tick`` on (the program's tick 0 uses the reading taken before the loop);
    ``None`` for hardware that samples in ``read()``. The sync does not wait for the answers:
    a loop blocked on the bus would wake on every frame and take the CPU from the devices
    that send them (measured: a longer CAN cycle on two cores)."""
    if not starts_cycles_early(hardware):
        return None

    def lead(tick: int) -> None:
        if tick >= first_tick:
            hardware.sync()

    return lead


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
    state = node.initial_state(reading.position_m[None, :])
    faults: list[str] = []
    forces, positions, commands, scales = [], [], [], []

    def step(cycle: int, _now_ns: int) -> None:
        nonlocal reading
        if cycle > 0:
            reading = hardware.read()
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
        if cycle + 1 >= cycles:
            runner.request_stop("cycles")

    free = None if pace else FreeRunningClock()
    runner = RealTimeRunner(period_s, step, spin_s=SPIN_MARGIN_S if pace else 0.0,
                            show_status=False,
                            **({} if free is None else {"clock_ns": free.clock_ns,
                                                        "sleep": free.sleep}))
    stats = runner.run() if cycles > 0 else runner.stats()
    reading = hardware.read()
    if reading.faults:
        faults.extend(f"cycle {reading.cycle}: {f}" for f in reading.faults)
    hardware.deactivate()
    trace = None
    if record:
        trace = MasterTrace(np.array(forces), np.array(positions), np.array(commands),
                            np.array(scales))
    final = reading.position_m
    lateness_s = stats.period_error_max_s if pace and not math.isnan(
        stats.period_error_max_s) else 0.0
    return RunSummary(stats.steps, stats.elapsed_s, stats.overruns if pace else 0, lateness_s,
                      (float(final[0]), float(final[1])), bool(state.faulted[0]),
                      list(state.events), faults, trace)
