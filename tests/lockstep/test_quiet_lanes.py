"""The lockstep's quiet lanes (lockstep/quiet_lanes.py, in front of each tick's ``supervise``):
a lane whose supervisor and guard have nothing to change only stores its message, every other
lane goes through them as the program's one lane does. A run is the same, bit for bit, as
one that feeds every lane's message object to its supervisor and guard each tick
(``every_lane_supervised``): results, node states, the supervisors' and guards' states,
counters and events. The runs below reach every path: watchdog trips and resyncs from bursts
of loss, input faults, saturation and rate limits, the work-area stop and its resync,
diverging lanes, and the governor switching a standby passivity layer."""

from __future__ import annotations

from dataclasses import fields, replace

import numpy as np
import pytest

from haptic.common.analysis.margin_table import build_margin_table
from haptic.common.config.scenario import load_scenario
from haptic.common.model.delay_profile import parse_delay_profile
from haptic.common.model.passivity import PassivitySettings
from haptic.common.wire.injection import InjectionConfig
from haptic.lockstep.quiet_lanes import MasterQuietLanes, SlaveQuietLanes
from haptic.lockstep.simulator import (
    TRANSPARENT_SUPERVISION,
    LockstepResult,
    LockstepSimulator,
    LockstepSupervision,
)
from haptic.master.margin_governor import GovernorSettings, MarginGovernor
from haptic.master.settings import master_settings
from haptic.master.simulated_rig.operator import parse_operator_spec
from haptic.master.tick import MasterTick
from haptic.slave_sim.input_guard import InputGuardSettings
from haptic.slave_sim.tick import SlaveTick

#: Bursts of loss of mean length 50 messages (27 ms): longer than the watchdog's silence.
BURSTS = InjectionConfig(delay_s=0.002, jitter_s=0.001, loss_probability=0.02,
                         burst_enter_probability=0.002, burst_exit_probability=0.02)


def _assert_same(a: object, b: object, where: str) -> None:
    """Equal arrays (NaN equal to NaN) or equal reprs (dataclasses, events, tuples)."""
    if isinstance(a, np.ndarray):
        np.testing.assert_array_equal(a, b, err_msg=where)
    else:
        assert repr(a) == repr(b), where


def _assert_same_runs(pair: list[tuple[LockstepSimulator, LockstepResult]]) -> None:
    (quick_sim, quick), (every_sim, every) = pair
    for item in fields(LockstepResult):
        a, b = getattr(quick, item.name), getattr(every, item.name)
        if item.name == "stats":
            for stat in fields(a):
                _assert_same(getattr(a, stat.name), getattr(b, stat.name), stat.name)
        elif isinstance(a, dict):
            assert a.keys() == b.keys()
            for key in a:
                _assert_same(a[key], b[key], key)
        elif item.name != "governed":
            _assert_same(a, b, item.name)
    for state_a, state_b in zip(quick_sim.final_states, every_sim.final_states, strict=True):
        for item in fields(state_a):
            value = getattr(state_a, item.name)
            if isinstance(value, np.ndarray):
                _assert_same(value, getattr(state_b, item.name), item.name)
    (master_a, slave_a), (master_b, slave_b) = quick_sim.last_ticks, every_sim.last_ticks
    assert isinstance(master_a, MasterTick) and isinstance(slave_a, SlaveTick)
    # the quiet path read the delay lines' columns in place (the same arrays every tick)
    assert quick_sim.last_quiet_lanes is not None and every_sim.last_quiet_lanes is None
    for quiet in quick_sim.last_quiet_lanes:
        assert quiet.kernel.inputs.in_place
    assert repr(master_a.passivity_events) == repr(master_b.passivity_events)
    for sup_a, sup_b in zip(master_a.supervisors, master_b.supervisors, strict=True):
        for name in ("tool", "enabled", "faulted", "hold_m", "events", "peer_stops",
                     "input_faulted", "peer_held"):
            _assert_same(getattr(sup_a, name), getattr(sup_b, name), f"master {name}")
        assert sup_a.watchdog.state == sup_b.watchdog.state
        assert sup_a.watchdog.trips == sup_b.watchdog.trips
        assert repr(sup_a.watchdog.events) == repr(sup_b.watchdog.events)
    for sup_a, sup_b in zip(slave_a.supervisors, slave_b.supervisors, strict=True):
        for name in ("handle_position_m", "master_enabled", "running", "ready", "outside",
                     "rejoining", "input_fault", "events"):
            _assert_same(getattr(sup_a, name), getattr(sup_b, name), f"slave {name}")
        assert sup_a.watchdog.trips == sup_b.watchdog.trips
        assert repr(sup_a.watchdog.events) == repr(sup_b.watchdog.events)
    for guard_a, guard_b in zip(slave_a.guards, slave_b.guards, strict=True):
        assert repr(guard_a) == repr(guard_b)  # counters, events, state, bounded values
    for name in ("handle_force_N", "handle_position_m", "force_scale", "echo_send_time_ns",
                 "running"):
        _assert_same(getattr(slave_a, name), getattr(slave_b, name), name)


def _both(make, **run) -> list[tuple[LockstepSimulator, LockstepResult]]:
    pair = []
    for every in (False, True):
        simulator = make()
        pair.append((simulator, simulator.run(**run, every_lane_supervised=every)))
    return pair


def test_sweep_lanes_with_loss_and_diverging_lanes(paper_model) -> None:
    """The sweep's transparent limits, with a watchdog: jitter and bursts of loss over 12
    lanes, some of them past their margin (their forces grow without bound)."""
    gains = np.repeat([3.0, 13.0, 19.0, 30.0], 3)
    delays = np.tile([0, 12, 40], 4)
    steps = int(round(1.5 / paper_model.sample_period_s))
    pulse = np.zeros((steps, 2))
    pulse[:20] = 1.0
    # the sweep's supervision with a watchdog that trips on the bursts
    watchdog = replace(TRANSPARENT_SUPERVISION, max_message_age_s=0.01, resync_messages=5)
    pair = _both(lambda: LockstepSimulator(paper_model, load_scenario("constant-rate"),
                                           parse_operator_spec("constant:fx=0,fy=0"), gains,
                                           "linear", device="cpu", supervision=watchdog),
                 duration_s=1.5, round_trip_delay_samples=delays, to_slave=BURSTS,
                 to_master=BURSTS, seed=3, excitation_N=pulse, record_lanes=[0, 5, 11])
    _assert_same_runs(pair)
    grown = pair[0][1].peak_handle_force_N.max(axis=1) > 1e3  # N, against a 1 N pulse
    assert grown.any() and not grown.all()
    master_tick, slave_tick = pair[0][0].last_ticks
    trips = [s.watchdog.trips for s in master_tick.supervisors]
    assert min(trips) > 0  # every lane lost its slave for a while and resynced
    for quiet in pair[0][0].last_quiet_lanes:
        assert 0 < quiet.lane_ticks_fed < 0.2 * quiet.lane_ticks


def _clay_lanes(paper_config, paper_model, guard: InputGuardSettings | None = None):
    """Four lanes cutting clay with the shipped limits and supervision (``guard``: other
    input bounds on the slave)."""
    scenario = load_scenario("constant-rate")
    supervision = LockstepSupervision.from_config(paper_config, scenario)
    if guard is not None:
        supervision = replace(supervision, input_guard=guard)
    return lambda: LockstepSimulator(
        paper_model, scenario, parse_operator_spec("regulate:fx=3.6,onset=0.05"),
        np.full(4, 3.0), "clay", master_settings(paper_config).safety, device="cpu",
        supervision=supervision)


def test_shipped_supervision_cutting_clay_to_the_wall_through_bursts(paper_config,
                                                                      paper_model) -> None:
    """The shipped limits and supervision, cutting clay to the work area's wall through
    bursts of loss: the watchdogs trip, the tools stop, resync and resume, lane by lane."""
    pair = _both(_clay_lanes(paper_config, paper_model), duration_s=4.6,
                 round_trip_delay_samples=np.array([2, 2, 8, 16]), to_slave=BURSTS,
                 to_master=InjectionConfig(delay_s=0.001), seed=7, record_lanes=[0, 3])
    _assert_same_runs(pair)
    master_tick, slave_tick = pair[0][0].last_ticks
    kinds = [event["kind"] for s in slave_tick.supervisors for event in s.events]
    assert kinds.count("tool_resumed") >= 5 and kinds.count("tool_stopped") >= 5
    assert sum(s.watchdog.trips for s in slave_tick.supervisors) >= 5
    assert np.any(slave_tick.state.tool[:, 0] == 0.15)  # on the wall
    # the master's line loses nothing, but each stop of a tool holds its handle until the
    # tool is back in sync (handle_held), and those lane-ticks go through its supervisor
    held = [event for s in master_tick.supervisors for event in s.events
            if event["kind"] == "handle_held"]
    assert len(held) >= 5 and len(held) == sum(s.peer_stops for s in master_tick.supervisors)
    master_quiet, slave_quiet = pair[0][0].last_quiet_lanes
    assert 0 < master_quiet.lane_ticks_fed < 0.5 * master_quiet.lane_ticks
    # many lane-ticks were quiet; the guards counted their messages all the same
    assert 0 < slave_quiet.lane_ticks_fed < 0.5 * slave_quiet.lane_ticks
    every_tick = pair[1][0].last_ticks[1]
    assert ([g.counters.checked for g in slave_tick.guards]
            == [g.counters.checked for g in every_tick.guards])


@pytest.mark.parametrize("force_limit_N, velocity_trip_m_per_s, kinds", [
    (5.0, 0.3, {"input_saturated", "input_rate_limited"}),
    (3.0, 0.1, {"input_fault", "input_saturated", "input_rate_limited",
                "input_fault_cleared"}),
])
def test_input_faults_saturation_and_rate_limits(paper_config, paper_model, force_limit_N,
                                                 velocity_trip_m_per_s, kinds) -> None:
    """Input bounds on the slave tight enough to saturate and rate-limit the handle force
    (up and down) on lanes that are otherwise quiet, and (with the lower speed bound) to
    fault on the cut: the faults stop the tools, they clear, the tools rejoin the handle."""
    tight = InputGuardSettings(force_limit_N=force_limit_N, force_trip_N=60.0,
                               force_rate_limit_N_per_s=300.0,
                               velocity_trip_m_per_s=velocity_trip_m_per_s,
                               jump_margin_m=0.0002, clear_after_messages=20)
    steps = int(round(2.0 / paper_model.sample_period_s))
    # from 0.3 s (the master's start-up gate open), the handle force jumps up and down by
    # 2 N every 0.1 s
    time_s = np.arange(steps) * paper_model.sample_period_s
    square = np.zeros((steps, 2))
    square[:, 1] = np.where((time_s > 0.3) & (time_s % 0.2 < 0.1), 2.0, 0.0)
    pair = _both(_clay_lanes(paper_config, paper_model, tight), duration_s=2.0,
                 round_trip_delay_samples=np.array([2, 2, 8, 16]), to_slave=BURSTS,
                 to_master=InjectionConfig(delay_s=0.001), seed=7, excitation_N=square)
    _assert_same_runs(pair)
    slave_tick = pair[0][0].last_ticks[1]
    assert kinds == {event["kind"] for guard in slave_tick.guards for event in guard.events}
    assert "tool_resumed" in {event["kind"] for s in slave_tick.supervisors for event in s.events}


@pytest.fixture(scope="module")
def table(paper_model, paper_config):
    return build_margin_table(paper_model.with_gain(13.0), paper_config["analysis"],
                              min_gain_k=1.0, step_ratio=0.8)


def test_governed_lanes_switching_a_standby_passivity_layer(paper_model, table) -> None:
    """The governor's tdpa action switches the standby layer on and off at run time in two
    lanes and the slave follows the flag, the other two lanes are ungoverned by the step."""
    model = paper_model.with_gain(13.0)
    steps = int(round(3.0 / model.sample_period_s))
    pulse = np.zeros((steps, 2))
    pulse[:20] = 1.0

    def make() -> LockstepSimulator:
        return LockstepSimulator(model, load_scenario("constant-rate"),
                                 parse_operator_spec("constant:fx=0,fy=0"), np.full(3, 13.0),
                                 "linear", device="cpu", passivity=PassivitySettings(),
                                 passivity_standby=True)

    def governors() -> list[MarginGovernor]:
        return [MarginGovernor(GovernorSettings(enabled=True, action="tdpa",
                                                recover_after_s=0.3, hold_s=0.2), table,
                               tdpa_available=True) for _ in range(3)]

    pair = []
    for every in (False, True):
        simulator = make()
        pair.append((simulator, simulator.run(
            3.0, 0, to_slave=InjectionConfig(delay_s=0.002),
            to_master=InjectionConfig(delay_profile=parse_delay_profile(
                "step 0:0.002 0.5:0.040 1.5:0.002")),
            excitation_N=pulse, governors=governors(), every_lane_supervised=every)))
    _assert_same_runs(pair)
    slave_tick = pair[0][0].last_ticks[1]
    kinds = [event["kind"] for event in slave_tick.supervisors[0].events
             if event["kind"].startswith("tdpa")]
    assert kinds == ["tdpa_on", "tdpa_off"]


def test_quiet_lanes_refuse_what_they_cannot_mirror(paper_config, paper_model) -> None:
    """The filters mirror one guard setting for every lane, no tool guard and no followed
    gain: anything else is refused, not silently mis-stepped."""
    from haptic.master.tool_guard import ToolGuardSettings, ToolInputGuard
    from haptic.slave_sim.input_guard import InputGuard

    simulator = _clay_lanes(paper_config, paper_model)()
    start = np.zeros((4, 2))
    master, slave = simulator.ticks(start, start)
    ts = paper_model.sample_period_s
    line = simulator  # never read: the refusal comes first
    slave.guards[1] = InputGuard(InputGuardSettings(force_limit_N=1.0), ts)
    with pytest.raises(ValueError, match="share"):
        SlaveQuietLanes(slave, line)  # type: ignore[arg-type]
    master.supervisors[2].tool_guard = ToolInputGuard(
        ToolGuardSettings.from_config(paper_config), ts)
    with pytest.raises(ValueError, match="tool guard"):
        MasterQuietLanes(master, line)  # type: ignore[arg-type]
    _, slave = simulator.ticks(start, start)
    slave.follow_gain(3.0, True)
    with pytest.raises(ValueError, match="gain"):
        SlaveQuietLanes(slave, line)  # type: ignore[arg-type]
