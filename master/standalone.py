"""The master alone (``haptic-master --no-link``): hardware lifecycle, read -> node -> write
once per Ts.

This drives the handle without a slave (the received tool force is zero or comes from
``tool_force_source``); the networked program composes the same node with its supervisor
(master/tick.py). Its stages (:class:`StandaloneStages`) run on the one tick driver
(common/runtime/tick_driver.py) and the real-time runner (common/runtime/runner.py: sleep,
spin the last ``spin_s``, re-anchor after a stall); unpaced, its ticks run back to back
(:class:`~haptic.common.runtime.runner.FreeRunningClock`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from haptic.common.runtime.runner import FreeRunningClock, LeadFunction, RealTimeRunner
from haptic.common.runtime.tick_driver import Stage, TickDriver
from haptic.master.hardware.interface import HandleHardware, HandleReading, starts_cycles_early
from haptic.master.node import MasterNode, MasterNodeState, SafetyEvent

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


class StandaloneStages:
    """The master alone as a side of the tick driver: ``read`` (the hardware; a fault trips
    the node), ``node`` (vh = Ch1 fh - Ct1 ft behind the safety layer, ft from
    ``tool_force_source(cycle)``, N, zero when None), ``write`` (the command and the tool
    force shown) and ``telemetry`` (the trace with ``record``, ``on_cycle(cycle)``, the stop
    after ``cycles``)."""

    stage_names = ("read", "node", "write", "telemetry")
    schedule_shift_ns = 0  # no peer to follow

    def __init__(self, hardware: HandleHardware, node: MasterNode, state: MasterNodeState,
                 reading: HandleReading, cycles: int,
                 tool_force_source: Callable[[int], np.ndarray] | None, record: bool,
                 on_cycle: Callable[[int], None] | None) -> None:
        self.hardware = hardware
        self.node = node
        self.state = state
        self.reading = reading
        self.cycles = cycles
        self.tool_force_source = tool_force_source
        self.record = record
        self.on_cycle = on_cycle
        self.faults: list[str] = []
        self.trace: tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray], list[float]] = (
            [], [], [], [])
        self.tool_force_N = np.zeros(2)
        self.command_m = np.zeros(2)
        #: called when the last cycle has run (the runner's ``request_stop``)
        self.stop: Callable[[str], None] = lambda _reason: None

    def stages(self) -> tuple[Stage, ...]:
        """read, node, write, telemetry."""
        return (self.read, self.step_node, self.write, self.telemetry)

    def read(self, cycle: int, _now_ns: int) -> None:
        """This cycle's reading (cycle 0: the one taken at the start); a fault trips the
        node."""
        if cycle > 0:
            self.reading = self.hardware.read()
        reading = self.reading
        if reading.faults:
            self.faults.extend(f"cycle {reading.cycle}: {f}" for f in reading.faults)
            self.node.trip(self.state, np.array([True]), "hardware: " + "; ".join(reading.faults))

    def step_node(self, cycle: int, _now_ns: int) -> None:
        """The node's step with the received tool force."""
        source = self.tool_force_source
        self.tool_force_N = (np.zeros(2) if source is None
                             else np.asarray(source(cycle), float))
        reading = self.reading
        self.command_m = self.node.step(self.state, reading.force_N[None, :],
                                        reading.position_m[None, :],
                                        self.tool_force_N[None, :])[0]

    def write(self, _cycle: int, _now_ns: int) -> None:
        """The command, and the tool force shown to a simulated operator."""
        self.hardware.present_tool_force(self.tool_force_N)
        self.hardware.write(self.command_m)

    def telemetry(self, cycle: int, _now_ns: int) -> None:
        """The trace (``record``), ``on_cycle``, and the stop after the last cycle."""
        if self.record:
            forces, positions, commands, scales = self.trace
            forces.append(self.reading.force_N)
            positions.append(self.reading.position_m)
            commands.append(self.command_m)
            scales.append(float(self.state.force_scale[0]))
        if self.on_cycle is not None:
            self.on_cycle(cycle)
        if cycle + 1 >= self.cycles:
            self.stop("cycles")


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
    hardware.configure()
    hardware.activate()
    hardware.present_forces_enabled(True)  # alone, the master's forces are on from the start
    reading = hardware.read()
    state = node.initial_state(reading.position_m[None, :])
    stages = StandaloneStages(hardware, node, state, reading, cycles, tool_force_source,
                              record, on_cycle)
    driver = TickDriver([stages])
    free = None if pace else FreeRunningClock()
    runner = RealTimeRunner(node.period_s, driver.step, spin_s=SPIN_MARGIN_S if pace else 0.0,
                            show_status=False,
                            **({} if free is None else {"clock_ns": free.clock_ns,
                                                        "sleep": free.sleep}))
    stages.stop = runner.request_stop
    stats = runner.run() if cycles > 0 else runner.stats()
    reading = hardware.read()
    faults = stages.faults
    if reading.faults:
        faults.extend(f"cycle {reading.cycle}: {f}" for f in reading.faults)
    hardware.deactivate()
    trace = None
    if record:
        trace = MasterTrace(*(np.array(column) for column in stages.trace))
    final = reading.position_m
    lateness_s = stats.period_error_max_s if pace and not math.isnan(
        stats.period_error_max_s) else 0.0
    return RunSummary(stats.steps, stats.elapsed_s, stats.overruns if pace else 0, lateness_s,
                      (float(final[0]), float(final[1])), bool(state.faulted[0]),
                      list(state.events), faults, trace)
