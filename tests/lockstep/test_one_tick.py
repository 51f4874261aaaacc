"""The lockstep simulator runs the programs' tick (master/tick.py, slave_sim/tick.py): the
same supervisors, input guard and nodes, so what the simulator checks is what ships."""

from __future__ import annotations

import numpy as np

from haptic.common.analysis.margin_table import MarginEntry, MarginTable
from haptic.common.config.scenario import load_scenario
from haptic.common.model.passivity import PassivitySettings
from haptic.common.runtime.watchdog import WatchdogState
from haptic.common.wire.injection import InjectionConfig
from haptic.common.wire.messages import Flags, HandleState, ToolState
from haptic.lockstep.simulator import LockstepSimulator, LockstepSupervision
from haptic.master.margin_governor import GovernorSettings, MarginGovernor
from haptic.master.node import MasterNode
from haptic.master.settings import master_settings
from haptic.master.simulated_rig.operator import parse_operator_spec
from haptic.master.simulated_rig.rig_block import RigModel
from haptic.master.supervisor import MasterSupervisor
from haptic.master.tick import MasterLaneInputs, MasterTick
from haptic.slave_sim.input_guard import InputGuard, InputGuardSettings
from haptic.slave_sim.node import SlaveNode
from haptic.slave_sim.supervisor import SlaveSupervisor
from haptic.slave_sim.tick import SlaveLaneInputs, SlaveTick

OPERATOR = "regulate:fx=3.6,onset=0.05"


def _deployed(paper_config, paper_model, scenario) -> LockstepSimulator:
    """One lane with the shipped limits: the master's safety layer and the programs'
    supervision, watchdog, work area and input guard."""
    return LockstepSimulator(
        paper_model, scenario, parse_operator_spec(OPERATOR),
        np.array([paper_config["model"]["ch1"]["gain_k"]]),
        "linear", master_settings(paper_config).safety, device="cpu",
        supervision=LockstepSupervision.from_config(paper_config, scenario))



def _starts(config: dict, model, scenario) -> tuple:
    """The lockstep's supervision settings, Ah1 per axis, and the tool's and the handle's
    start positions (1, 2), m, for ``scenario``."""
    sup = LockstepSupervision.from_config(config, scenario)
    ratio = tuple(float(a.position_ratio_ah1) for a in model.axes)
    tool_start = np.asarray(scenario.tool.start_position_m, float)[None, :]
    return sup, ratio, tool_start, tool_start / np.asarray(ratio)

def _running_slave(config: dict, model, scenario) -> tuple[SlaveTick, InputGuardSettings]:
    """A one-lane slave tick as the program builds it (the shipped work area and input
    guard), in sync and running with the handle at its start; and the guard's settings."""
    sup, ratio, tool_start, handle_start = _starts(config, model, scenario)
    slave_node = SlaveNode(model, scenario, "linear", device="cpu")
    guard_settings = InputGuardSettings.from_config(config)
    slave = SlaveTick(slave_node, slave_node.initial_state(1, tool_start),
                      [SlaveSupervisor(ratio, sup.sync_tolerance_m, sup.work_area_m,
                                       sup.max_message_age_s, sup.resync_messages)],
                      [InputGuard(guard_settings, model.sample_period_s)])
    slave.handle_position_m[...] = handle_start
    slave.start(synced=True)
    return slave, guard_settings


def test_lockstep_outputs_equal_program_ticks_fed_the_same_inputs(paper_config,
                                                                  paper_model) -> None:
    """Drive a master tick and a slave tick built as the programs build them (one lane each,
    messages as the link delivers them) with the rig and one-sample lines by hand: the
    handle forces, commands and tool forces equal the lockstep's, bit for bit."""
    scenario = load_scenario("constant-rate")
    simulator = _deployed(paper_config, paper_model, scenario)
    duration_s = 0.3
    result = simulator.run(duration_s, 2, record_lanes=[0])  # d1 = 1 to the slave, d2 = 1 back
    ts = paper_model.sample_period_s
    sup, ratio, tool_start, handle_start = _starts(paper_config, paper_model, scenario)
    node = MasterNode.from_model(paper_model, master_settings(paper_config).safety)
    master = MasterTick(node, [MasterSupervisor(ratio, sup.sync_tolerance_m,
                                                sup.max_message_age_s, sup.resync_messages)])
    master.start(handle_start, synced=True)
    slave_node = SlaveNode(paper_model, scenario, "linear", device="cpu")
    slave = SlaveTick(slave_node, slave_node.initial_state(1, tool_start),
                      [SlaveSupervisor(ratio, sup.sync_tolerance_m, sup.work_area_m,
                                       sup.max_message_age_s, sup.resync_messages,
                                       grid_m=sup.grid_m)],
                      [InputGuard(InputGuardSettings.from_config(paper_config), ts)])
    slave.handle_position_m[...] = handle_start
    slave.start(synced=True)
    rig = RigModel.from_model(paper_model, parse_operator_spec(OPERATOR), 0.0)
    rng = np.random.default_rng(0).spawn(3)[2]
    rig_state = rig.initial_state(handle_start, rng)
    enabled = Flags.FORCES_ENABLED
    to_slave = HandleState(0, -1, -int(ts * 1e9), enabled, (0.0, 0.0),
                           tuple(handle_start[0]),
                           force_scale=float(master.state.force_scale[0]))
    to_master_next = ToolState(0, -2, 0, enabled, (0.0, 0.0), tuple(tool_start[0]),
                               (0.0, 0.0), 0.0, 0.0)
    to_master = to_master_next
    command = master.state.last_command_m.copy()
    fh_trace, command_trace, ft_trace = [], [], []
    for k in range(result.steps):
        sample = rig.step(rig_state, command, np.array([to_master.tool_force_N]))
        fh, yh = sample.handle_force_measured_N, sample.handle_position_m
        master.supervise(k * ts, [to_master], yh)
        used = master.control(fh, yh)
        command = used.command_m.copy()
        sent = HandleState(0, k, int(k * ts * 1e9), used.flags[0],
                           tuple(used.handle_force_used_N[0].tolist()), tuple(yh[0].tolist()),
                           force_scale=float(used.force_scale[0]))  # as the program sends
        slave.supervise(k * ts, [to_slave])
        out = slave.control()
        to_slave = sent  # one sample to the slave
        to_master = to_master_next  # the tool force of tick k - 1 describes t_k
        to_master_next = ToolState(
            0, k, int(k * ts * 1e9), out.flags[0], tuple(out.out.tool_force_N[0].tolist()),
            tuple(out.out.tool_position_m[0].tolist()),
            tuple(out.out.tool_velocity_m_s[0].tolist()), 0.0, 0.0)
        fh_trace.append(fh[0].copy())
        command_trace.append(command[0].copy())
        ft_trace.append(out.out.tool_force_N[0].copy())
    np.testing.assert_array_equal(result.traces["handle_force_N"][:, 0], np.array(fh_trace))
    np.testing.assert_array_equal(result.traces["handle_command_m"][:, 0],
                                  np.array(command_trace))
    np.testing.assert_array_equal(result.traces["tool_force_N"][:, 0], np.array(ft_trace))
    # the operator pushed: the node's start-up gate opened and forces went through
    assert np.abs(result.traces["tool_force_recv_N"]).max() > 0.0


def test_the_lockstep_watchdog_trips_on_a_silent_link_and_resyncs(paper_config,
                                                                  paper_model) -> None:
    """With the shipped watchdog, a lossy line to the master (bursts of total loss) trips the
    master's watchdog in the lockstep as in the program: the forces go off (the command
    holds), the tool stops, and after the resync both sides run again."""
    scenario = load_scenario("constant-rate")
    simulator = _deployed(paper_config, paper_model, scenario)
    bursts = InjectionConfig(burst_enter_probability=0.002, burst_exit_probability=0.005,
                             burst_loss_probability=1.0)
    result = simulator.run(2.0, 4, to_master=bursts, seed=3, record_lanes=[0])
    master, slave = simulator.last_ticks
    watchdog = master.supervisors[0].watchdog
    assert watchdog.trips >= 1
    kinds = [event.kind for event in watchdog.events]
    assert "trip" in kinds and "forces_enabled" in kinds  # tripped, then resynced
    # while tripped the master holds the handle: the command does not move
    trip_s = next(event.time_s for event in watchdog.events if event.kind == "trip")
    trip_k = int(round(trip_s / paper_model.sample_period_s))
    held = result.traces["handle_command_m"][trip_k:trip_k + 20, 0]
    np.testing.assert_array_equal(held, np.broadcast_to(held[0], held.shape))
    assert watchdog.state is WatchdogState.OK  # back in sync at the end
    assert not result.diverged[0]


def test_the_slaves_work_area_stop_reaches_the_master_tick_and_holds_the_handle(
        paper_config, paper_model) -> None:
    """Issue 16, on the shared ticks: the slave's tick flags its work-area stop
    (WORK_AREA_STOP) and the master's tick, fed that message, holds the handle (its forces
    off, SAFE_STATE on the wire) instead of running on alone."""
    scenario = load_scenario("constant-rate")
    ts = paper_model.sample_period_s
    sup, ratio, tool_start, handle_start = _starts(paper_config, paper_model, scenario)
    x, y = float(tool_start[0, 0]), float(tool_start[0, 1])
    # a work area that ends 1 mm short of the tool, on x: the guard stops it at once
    area = (x - 0.05, x - 0.001, y - 0.05, y + 0.05)
    grid = (x - 0.04, x - 0.002, y - 0.04, y + 0.04)
    slave_node = SlaveNode(paper_model, scenario, "linear", device="cpu")
    slave = SlaveTick(slave_node, slave_node.initial_state(1, tool_start),
                      [SlaveSupervisor(ratio, sup.sync_tolerance_m, area,
                                       sup.max_message_age_s, sup.resync_messages,
                                       grid_m=grid)],
                      [InputGuard(InputGuardSettings.from_config(paper_config), ts)])
    slave.handle_position_m[...] = handle_start
    slave.start(synced=True)
    node = MasterNode.from_model(paper_model, master_settings(paper_config).safety)
    master = MasterTick(node, [MasterSupervisor(ratio, sup.sync_tolerance_m,
                                                sup.max_message_age_s, sup.resync_messages)])
    master.start(handle_start, synced=True)
    handle = HandleState(0, 0, 0, Flags.FORCES_ENABLED, (0.0, 0.0), tuple(handle_start[0]))
    slave.supervise(0.0, [handle])
    out = slave.control()
    assert Flags.WORK_AREA_STOP in out.flags[0] and not out.running[0]
    message = ToolState(0, 0, 0, out.flags[0], tuple(out.out.tool_force_N[0].tolist()),
                        tuple(out.out.tool_position_m[0].tolist()),
                        tuple(out.out.tool_velocity_m_s[0].tolist()), 0.0, 0.0)
    master.supervise(ts, [message], handle_start)
    used = master.control(np.zeros((1, 2)), handle_start)
    assert not used.enabled[0] and Flags.SAFE_STATE in used.flags[0]
    np.testing.assert_array_equal(used.handle_force_used_N[0], 0.0)
    assert master.supervisors[0].peer_stops == 1
    # the master holding does not end the slave's stop: the handle is still beyond the grid
    held = HandleState(0, 1, int(ts * 1e9), used.flags[0], (0.0, 0.0), tuple(handle_start[0]))
    slave.supervise(2 * ts, [held])
    assert Flags.WORK_AREA_STOP in slave.control().flags[0]


def test_a_slave_input_fault_holds_the_handle_until_both_are_back_in_sync(
        paper_config, paper_model) -> None:
    """On the shared ticks: a forged 1e9 N handle message is an input fault at the slave
    (its tool stops, FORCES_ENABLED leaves its messages); the master's tick, fed that
    message, holds the handle instead of running on alone; once plausible messages clear the
    fault the tool is re-placed at the handle and both run again."""
    scenario = load_scenario("constant-rate")
    ts = paper_model.sample_period_s
    sup, ratio, tool_start, handle_start = _starts(paper_config, paper_model, scenario)
    slave, guard_settings = _running_slave(paper_config, paper_model, scenario)
    node = MasterNode.from_model(paper_model, master_settings(paper_config).safety)
    master = MasterTick(node, [MasterSupervisor(ratio, sup.sync_tolerance_m,
                                                sup.max_message_age_s, sup.resync_messages)])
    master.start(handle_start, synced=True)
    handle_xy = tuple(handle_start[0])

    def exchange(tick: int, force_N: tuple[float, float], master_flags: Flags):
        handle = HandleState(0, tick, int(tick * ts * 1e9), master_flags, force_N, handle_xy)
        slave.supervise(tick * ts, [handle])
        out = slave.control()
        tool = ToolState(0, tick, int(tick * ts * 1e9), out.flags[0],
                         tuple(out.out.tool_force_N[0].tolist()),
                         tuple(out.out.tool_position_m[0].tolist()),
                         tuple(out.out.tool_velocity_m_s[0].tolist()), 0.0, 0.0)
        master.supervise((tick + 1) * ts, [tool], handle_start)
        return out, master.control(np.zeros((1, 2)), handle_start)

    out, used = exchange(0, (1e9, 0.0), Flags.FORCES_ENABLED)  # the forged message
    assert not out.running[0] and Flags.FORCES_ENABLED not in out.flags[0]
    assert not used.enabled[0] and Flags.SAFE_STATE in used.flags[0]
    np.testing.assert_array_equal(used.handle_force_used_N[0], 0.0)
    supervisor = master.supervisors[0]
    assert supervisor.peer_stops == 1 and supervisor.work_area_stops == 0
    flags = used.flags[0]
    for tick in range(1, guard_settings.clear_after_messages + 40):
        out, used = exchange(tick, (0.0, 0.0), flags)
        flags = used.flags[0]
        if used.enabled[0]:
            break
    assert used.enabled[0] and Flags.FORCES_ENABLED in out.flags[0]
    assert supervisor.peer_stops == 1 and not supervisor.peer_held
    assert np.all(np.abs(out.out.tool_position_m[0] - np.asarray(ratio) * handle_start[0])
                  < sup.sync_tolerance_m)


def test_every_message_delivered_in_a_tick_passes_the_guard_and_is_a_sample(
        paper_config, paper_model) -> None:
    """The slave's tick checks each older message delivered with the newest (a forged one
    among them is a fault, not a sample) and keeps the admitted ones' bounded force and
    position for the pacing (slave_sim/pacing.py)."""
    scenario = load_scenario("constant-rate")
    ts = paper_model.sample_period_s
    sup, ratio, tool_start, handle_start = _starts(paper_config, paper_model, scenario)
    slave, guard_settings = _running_slave(paper_config, paper_model, scenario)
    x, y = (float(v) for v in handle_start[0])
    period_ns = int(ts * 1e9)

    def handle(seq: int, force_N: float) -> HandleState:
        return HandleState(0, seq, seq * period_ns, Flags.FORCES_ENABLED, (force_N, 0.0),
                           (x, y))

    limit = guard_settings.force_limit_N
    fresh = slave.supervise(0.0, [handle(3, 0.3)], earlier=[[handle(1, 0.1), handle(2, 0.2)]])
    assert fresh[0]
    assert [(seq, force) for _, seq, force, _, _ in slave.samples[0]] == [
        (1, (0.1, 0.0)), (2, (0.2, 0.0)), (3, (0.3, 0.0))]
    assert slave.handle_force_N[0].tolist() == [0.3, 0.0]  # the newest is the tick's input
    # a forged force among the older ones: a fault, not a sample
    slave.supervise(ts, [handle(6, 0.3)], earlier=[[handle(4, 1e9), handle(5, limit + 5)]])
    assert [seq for _, seq, _, _, _ in slave.samples[0]] == [5, 6]
    assert slave.samples[0][0][2][0] <= limit  # bounded like the newest
    assert slave.guards[0].faulted and slave.guards[0].counters.faults == 1
    assert not slave.running[0]  # the latched fault stops the tool
    # without ``earlier`` (the lockstep) no samples are kept
    slave.samples[0].clear()
    slave.supervise(2 * ts, [handle(7, 0.3)])
    assert slave.samples[0] == []


def test_the_lockstep_lane_is_the_programs_step_lane_with_a_governor_and_tdpa(
        paper_config, paper_model) -> None:
    """The glue around supervise and the node (the governed k on both sides, the passivity
    layer's energies, the drift correction's target) is the ticks' own: the simulator's lane
    and the programs' ticks built by ``LockstepSimulator.ticks``, stepped one lane at a time
    through ``step_lane`` with the messages as the link delivers them, give the same forces,
    commands, gains and energies, bit for bit, while the governor lowers k and the passivity
    layer runs (a one-sample round trip: d1 = 0 to the slave, d2 = 1 back)."""
    scenario = load_scenario("constant-rate")
    ts = paper_model.sample_period_s
    k0 = float(paper_config["model"]["ch1"]["gain_k"])
    # the round trip the echo shows (2 samples) is beyond this k's margin, inside the lower's
    table = MarginTable((MarginEntry(k0, 2.5 * ts), MarginEntry(0.6 * k0, None)), 0.1, ts)

    def governor() -> MarginGovernor:
        return MarginGovernor(GovernorSettings(enabled=True, recover_after_s=0.0), table)

    simulator = LockstepSimulator(paper_model, scenario, parse_operator_spec(OPERATOR),
                                  np.array([k0]), "linear", device="cpu",
                                  passivity=PassivitySettings())
    result = simulator.run(0.3, 1, record_lanes=[0], governors=[governor()])
    tool_start = np.asarray(scenario.tool.start_position_m, float)[None, :]
    handle_start = tool_start / np.array([a.position_ratio_ah1 for a in paper_model.axes])
    master, slave = simulator.ticks(handle_start, tool_start)  # the programs' ticks
    master_out = master.configure_lane(k0, governor(), allow_unstable=True)
    slave.follow_gain(k0, True)
    slave_out = slave.configure_lane()
    rig = simulator.rig
    rig_state = rig.initial_state(handle_start, np.random.default_rng(0).spawn(3)[2])
    period_ns = round(ts * 1e9)
    start_ns = 1000 * period_ns  # every send time > 0: an echo of tick 0 is a round trip

    def sent_ns(tick: int) -> int:
        return start_ns + tick * period_ns

    mode = Flags.FORCES_ENABLED | Flags.TDPA  # the run-up's messages, as the link's
    to_master = ToolState(0, -2, sent_ns(-2), mode, (0.0, 0.0), tuple(tool_start[0]),
                          (0.0, 0.0), 0.0, 0.0)
    to_master_next = to_master
    command = master.state.last_command_m.copy()
    master_in, slave_in = MasterLaneInputs(), SlaveLaneInputs()
    traces: dict[str, list] = {"fh": [], "command": [], "ft": [], "gain": [], "energy": []}
    for k in range(result.steps):
        now_s = k * ts
        sample = rig.step(rig_state, command, np.array([to_master.tool_force_N]))
        master_in.now_s, master_in.message = now_s, to_master
        master_in.handle_force_N = sample.handle_force_measured_N
        master_in.handle_position_m = yh = sample.handle_position_m
        master_in.latest, master_in.silence_s = to_master, 0.0
        master_in.first_sent_ns, master_in.last_sent_ns = sent_ns(0), sent_ns(k - 1)
        master_in.poll_ns = sent_ns(k)
        master.step_lane(master_in)
        used = master_out.used
        command = used.command_m.copy()
        to_slave = HandleState(0, k, sent_ns(k), master_out.flags,
                               tuple(used.handle_force_used_N[0].tolist()),
                               tuple(yh[0].tolist()), gain_k=master_out.gain_k,
                               energy_J=master_out.energy_J,
                               force_scale=float(used.force_scale[0]))
        slave_in.now_s, slave_in.message, slave_in.silence_s = now_s, to_slave, 0.0
        slave.step_lane(slave_in)  # d1 = 0: the message of this tick
        out = slave_out.ticked.out
        to_master = to_master_next  # d2 = 1, and the tool force of tick k - 1 describes t_k
        to_master_next = ToolState(
            0, k, sent_ns(k), slave_out.flags, tuple(out.tool_force_N[0].tolist()),
            tuple(out.tool_position_m[0].tolist()), tuple(out.tool_velocity_m_s[0].tolist()),
            0.0, 0.0, echo_send_time_ns=slave_out.echo_send_time_ns,
            energy_J=slave_out.energy_J)
        for name, value in (("fh", sample.handle_force_measured_N[0]), ("command", command[0]),
                            ("ft", out.tool_force_N[0]), ("gain", master_out.gain_k),
                            ("energy", (master_out.energy_J, slave_out.energy_J))):
            traces[name].append(np.copy(value))
    np.testing.assert_array_equal(result.traces["handle_force_N"][:, 0], np.array(traces["fh"]))
    np.testing.assert_array_equal(result.traces["handle_command_m"][:, 0],
                                  np.array(traces["command"]))
    np.testing.assert_array_equal(result.traces["tool_force_N"][:, 0], np.array(traces["ft"]))
    gains = result.governed.gains_k[:, 0]
    np.testing.assert_array_equal(gains, np.array(traces["gain"]))
    ended = simulator.final_states  # the lockstep's, and the step_lane ticks' below
    for lockstep, programs in zip(ended, (master.state, slave.state), strict=True):
        for name in ("sent_J", "peer_sent_J", "tank_J"):  # the passivity layer's account
            np.testing.assert_array_equal(getattr(programs.passivity, name),
                                          getattr(lockstep.passivity, name))
    np.testing.assert_array_equal(master.state.peer_target_m, ended[0].peer_target_m)
    # not a comparison of idle sides: the governor lowered k, the master handed energy over
    # and the slave took it, and the drift correction had the tool as its target
    assert gains[0] == k0 and gains[-1] < k0
    assert traces["energy"][-1][0] > 0.0 and slave.state.passivity.peer_sent_J[0] > 0.0
    assert np.all(np.isfinite(master.state.peer_target_m))
