"""A real-link cell of the paper's scheme or of TDPA: the comparison's lockstep set-up for the
task (lockstep/compare_paper.py: the task's model, operator and environment, the rig) and the
programs' two ticks (master/tick.py, slave_sim/tick.py: supervisors, input guard and nodes as
they ship, one lane each), their messages (HandleState, ToolState) over two
:class:`~haptic.common.wire.link.Link` objects (in this process, over TCP on loopback) with
the cell's delay and loss injected on their receive paths, paced in real time at Ts, as
lockstep/real_link.py runs the latency sweep's cells.

The lockstep starts its lanes with the link already running (the lines hold the run-up's
messages: no force, the devices at their start, forces enabled). A real link has to run for
that: before tick 0 each side sends that run-up message once a tick, for the one-way delay
and :data:`RUNUP_MARGIN_S` more, so that at tick 0 each side holds the peer's messages as the
lockstep's would and its watchdog sees no silence. The run-up's messages count below tick 0
in the lags.
"""

from __future__ import annotations

import math
import time

import numpy as np

from haptic.common.config.scenario import load_scenario
from haptic.common.model.passivity import PassivitySettings
from haptic.common.model.teleop import TeleopModel
from haptic.common.runtime.runner import RealTimeRunner
from haptic.common.runtime.tick_driver import Stage, TickDriver
from haptic.common.wire.link import Link
from haptic.common.wire.link_config import LinkConfig
from haptic.common.wire.messages import Flags
from haptic.lockstep.compare_grid import CompareGrid, Lane
from haptic.lockstep.compare_paper import PAPER_CONTROLS, operator_spec, task_model
from haptic.lockstep.compare_real_link_lanes import RealLinkRun
from haptic.lockstep.compare_real_link_links import (
    SPIN_S,
    LagRecord,
    link_figures,
    wait_for_each_other,
)
from haptic.lockstep.compare_records import LaneRecords
from haptic.lockstep.simulator import LockstepSimulator
from haptic.master.simulated_rig.operator import parse_operator_spec
from haptic.master.simulated_rig.rig_block import RigModel, RigState
from haptic.master.tick import MasterLaneInputs, MasterTick
from haptic.slave_sim.tick import SlaveLaneInputs, SlaveTick

#: The run-up lasts the one-way delay and this much more, s.
RUNUP_MARGIN_S = 0.02


class PaperMasterSide:
    """The master's stages: poll (the newest tool message), read (the rig at SYNC k shown
    that tool force and the last command), the whole tick, write (the rig's next command),
    send (the handle message). Before tick 0 (the run-up) it polls and sends the run-up
    message only."""

    stage_names = ("poll", "read", "supervise", "node", "write", "send")
    schedule_shift_ns = 0

    def __init__(self, link: Link, tick: MasterTick, rig: RigModel, rig_state: RigState,
                 gain_k: float, period_s: float, runup: int, lags: LagRecord,
                 runup_flags: Flags) -> None:
        self.link, self.tick, self.rig, self.rig_state = link, tick, rig, rig_state
        self.period_s, self.runup, self.lags = period_s, runup, lags
        self.inputs = MasterLaneInputs()
        self.outputs = tick.configure_lane(gain_k)
        self.command_m = tick.state.last_command_m.copy()
        #: the handle's start (m), what the run-up's messages say; set by the cell
        self.start_m = (0.0, 0.0)
        self.force_scale = float(np.asarray(tick.state.force_scale).reshape(-1)[0])
        self.runup_flags = runup_flags
        self.tool_force_N = np.zeros((1, 2))  # the newest received, held (as lockstep)
        self.unsendable = 0

    def stages(self) -> tuple[Stage, ...]:
        return (self.poll, self.read, self.step_tick, self.write, self.send)

    def poll(self, tick: int, _now_ns: int) -> None:
        """The newest tool message and, from tick 0, its lag."""
        link, inputs = self.link, self.inputs
        k = tick - self.runup
        inputs.now_s = k * self.period_s
        inputs.message = link.poll()
        latest = inputs.latest = link.latest
        inputs.silence_s = link.silence_s()
        inputs.peer_alive = link.peer_alive
        if latest is not None:
            self.tool_force_N = np.array([latest.tool_force_N])
        if k >= 0:
            self.lags.to_master[k] = LagRecord.lag(
                k, None if latest is None else latest.seq - self.runup)

    def read(self, tick: int, _now_ns: int) -> None:
        if tick < self.runup:
            return
        sample = self.rig.step(self.rig_state, self.command_m, self.tool_force_N)
        self.inputs.handle_force_N = sample.handle_force_measured_N
        self.inputs.handle_position_m = sample.handle_position_m

    def step_tick(self, tick: int, _now_ns: int) -> int:
        """The whole tick (not in the run-up); returns the clock at its supervise | node
        boundary."""
        if tick < self.runup:
            return time.perf_counter_ns()
        return self.tick.step_lane(self.inputs, time.perf_counter_ns).supervised_ns

    def write(self, tick: int, _now_ns: int) -> None:
        if tick >= self.runup:
            self.command_m = self.outputs.used.command_m.copy()

    def send(self, tick: int, _now_ns: int) -> None:
        """The handle message (the run-up's before tick 0); one with a non-finite value (a
        diverged loop) is not sent, its sequence number skipped."""
        link = self.link
        if tick < self.runup:
            link.send_handle((0.0, 0.0), self.start_m, self.runup_flags, 0.0, 0.0,
                             self.force_scale)
            return
        outputs = self.outputs
        used = outputs.used
        try:
            link.send_handle(tuple(used.handle_force_used_N[0].tolist()),
                             tuple(self.inputs.handle_position_m[0].tolist()), outputs.flags,
                             outputs.gain_k, outputs.energy_J, float(used.force_scale[0]))
        except ValueError:
            self.unsendable += 1


class PaperSlaveSide:
    """The slave's stages: poll (the newest handle message), the whole tick, send (the tool
    message), record (the tick's task-axis values). Before tick 0 it polls and sends the
    run-up message only."""

    stage_names = ("poll", "supervise", "node", "send", "record")
    schedule_shift_ns = 0

    def __init__(self, link: Link, tick: SlaveTick, master: PaperMasterSide,
                 records: LaneRecords, runup_flags: Flags) -> None:
        self.link, self.tick, self.master = link, tick, master
        self.period_s, self.runup, self.lags = master.period_s, master.runup, master.lags
        self.records = records
        self.inputs = SlaveLaneInputs()
        self.outputs = tick.configure_lane(None)
        #: the tool's start (m), what the run-up's messages say; set by the cell
        self.start_m = (0.0, 0.0)
        self.runup_flags = runup_flags
        self.unsendable = 0

    def stages(self) -> tuple[Stage, ...]:
        return (self.poll, self.step_tick, self.send, self.record)

    def poll(self, tick: int, _now_ns: int) -> None:
        link, inputs = self.link, self.inputs
        k = tick - self.runup
        inputs.now_s = k * self.period_s
        inputs.message = link.poll()
        inputs.silence_s = link.silence_s()
        inputs.peer_alive = link.peer_alive
        if k >= 0:
            latest = link.latest
            self.lags.to_slave[k] = LagRecord.lag(
                k, None if latest is None else latest.seq - self.runup)

    def step_tick(self, tick: int, _now_ns: int) -> int:
        if tick < self.runup:
            return time.perf_counter_ns()
        return self.tick.step_lane(self.inputs, time.perf_counter_ns).supervised_ns

    def send(self, tick: int, _now_ns: int) -> None:
        """The tool message (the run-up's before tick 0); a non-finite one is not sent."""
        link = self.link
        if tick < self.runup:
            link.send_tool((0.0, 0.0), self.start_m, (0.0, 0.0), 0.0, 0.0, self.runup_flags)
            return
        outputs = self.outputs
        out = outputs.ticked.out
        try:
            link.send_tool(tuple(out.tool_force_N[0].tolist()),
                           tuple(out.tool_position_m[0].tolist()),
                           tuple(out.tool_velocity_m_s[0].tolist()), 0.0, 0.0, outputs.flags,
                           outputs.echo_send_time_ns, outputs.energy_J)
        except ValueError:
            self.unsendable += 1

    def record(self, tick: int, _now_ns: int) -> None:
        """The operator's force on the handle and the handle's position (the master's
        reading), the tool's position and its force on the environment, x."""
        if tick < self.runup:
            return
        master, out = self.master.inputs, self.outputs.ticked.out
        self.records.add(tick - self.runup, master.handle_position_m[:, 0],
                         out.tool_position_m[:, 0], master.handle_force_N[:, 0],
                         out.tool_force_N[:, 0])


def paper_simulator(control: str, lane: Lane, grid: CompareGrid,
                    model: TeleopModel) -> LockstepSimulator:
    """The one-lane lockstep simulator of the comparison's cell (compare_paper.py's)."""
    if control not in PAPER_CONTROLS:
        raise ValueError(f"control must be one of {', '.join(PAPER_CONTROLS)}")
    environment = "clay" if lane.task == "clay-cut" else "linear"
    return LockstepSimulator(task_model(model, lane.task, lane.wall_stiffness_N_per_m),
                             load_scenario("constant-rate"),
                             parse_operator_spec(operator_spec(grid, lane.task)),
                             np.array([model.ch1_gain_k]), environment, device="cpu",
                             passivity=PassivitySettings() if control == "tdpa" else None)


def run_paper_cell(control: str, lane: Lane, grid: CompareGrid, model: TeleopModel,
                   configs: tuple[LinkConfig, LinkConfig]) -> RealLinkRun:
    """Run ``control`` ("paper" or "tdpa") on ``lane``'s task for the grid's duration over
    the two links of ``configs`` (master's, slave's), in real time."""
    simulator = paper_simulator(control, lane, grid, model)
    ts = model.sample_period_s
    steps = int(round(grid.duration_s / ts))
    start = np.asarray(simulator.scenario.tool.start_position_m, float).reshape(1, 2)
    ratio = np.array([a.position_ratio_ah1 for a in model.axes])
    handle_start = start / ratio
    master_tick, slave_tick = simulator.ticks(handle_start, start)
    rig_state = simulator.rig.initial_state(
        handle_start, np.random.default_rng(grid.seed).spawn(3)[2])
    injected_s = configs[0].injection.delay_s
    runup = math.ceil((injected_s + RUNUP_MARGIN_S) / ts)
    flags = Flags.FORCES_ENABLED | (Flags.TDPA if control == "tdpa" else Flags(0))
    lags = LagRecord(steps)
    records = LaneRecords.create(ts, steps, 1)
    with Link(configs[0]) as master_link, Link(configs[1]) as slave_link:
        wait_for_each_other(master_link, slave_link)
        master = PaperMasterSide(master_link, master_tick, simulator.rig, rig_state,
                                 model.ch1_gain_k, ts, runup, lags, flags)
        slave = PaperSlaveSide(slave_link, slave_tick, master, records, flags)
        master.start_m = (float(handle_start[0, 0]), float(handle_start[0, 1]))
        slave.start_m = (float(start[0, 0]), float(start[0, 1]))
        driver = TickDriver([master, slave])
        with np.errstate(over="ignore", invalid="ignore"):
            stats = RealTimeRunner(ts, driver.step, max_steps=runup + steps, spin_s=SPIN_S,
                                   show_status=False, handle_signals=False).run()
        links = {"master": link_figures(master_link), "slave": link_figures(slave_link)}
        links["master"]["unsendable"] = master.unsendable
        links["slave"]["unsendable"] = slave.unsendable
    return RealLinkRun(records, lags, links, stats)


__all__ = ["RUNUP_MARGIN_S", "PaperMasterSide", "PaperSlaveSide", "paper_simulator",
           "run_paper_cell"]
