"""The master's supervisor as a pure block: forces only after the watchdog's resync with the
tool at Ah1 yh; a trip holds the handle where it was; faults latch."""

from __future__ import annotations

import math

import numpy as np
import pytest

from haptic.common.runtime.watchdog import WatchdogState
from haptic.common.wire.messages import Flags, ToolState
from haptic.master.supervisor import MasterSupervisor, Transition
from tests.helpers.steady import assert_steady_needs_each

PERIOD_S = 0.00054
MAX_AGE_S = 0.03
RESYNC = 5
RATIO = (2.0, 0.5)


def tool(x_m: float, y_m: float, enabled: bool = True, seq: int = 0) -> ToolState:
    flags = Flags.FORCES_ENABLED if enabled else Flags.SAFE_STATE
    return ToolState(1, seq, 0, flags, (0.0, 0.0), (x_m, y_m), (0.0, 0.0), 0.0, 0.0)


def make() -> MasterSupervisor:
    supervisor = MasterSupervisor(RATIO, 0.001, MAX_AGE_S, RESYNC)
    supervisor.start((0.01, 0.02))
    return supervisor


def run_in_sync(supervisor: MasterSupervisor, ticks: int, start: int = 0) -> list[Transition]:
    handle = (0.01, 0.02)
    return [supervisor.update((start + i) * PERIOD_S,
                              tool(RATIO[0] * handle[0], RATIO[1] * handle[1], seq=start + i),
                              handle) for i in range(ticks)]


def test_forces_come_on_after_the_resync_messages_in_sync() -> None:
    supervisor = make()
    transitions = run_in_sync(supervisor, RESYNC)
    assert transitions[:-1] == [Transition.NONE] * (RESYNC - 1)
    assert transitions.count(Transition.ACTIVATE) == 1 and supervisor.enabled
    assert supervisor.enabled and supervisor.ever_enabled


@pytest.mark.parametrize(("offset_m", "enabled_flag", "expected"), [
    ((0.0009, 0.0), True, True),   # just inside the tolerance on x
    ((0.0011, 0.0), True, False),  # just outside on x
    ((0.0, -0.0011), True, False),  # just outside on y
    ((0.0, 0.0), False, False),    # in place, but the slave's forces are off
])
def test_in_sync_needs_the_tool_at_ah1_yh_and_the_slaves_forces(offset_m, enabled_flag,
                                                                 expected) -> None:
    supervisor = make()
    handle = (0.01, 0.02)
    for i in range(2 * RESYNC):
        supervisor.update(i * PERIOD_S, tool(RATIO[0] * handle[0] + offset_m[0],
                                             RATIO[1] * handle[1] + offset_m[1],
                                             enabled_flag, seq=i), handle)
    assert supervisor.enabled is expected


def test_silence_holds_the_handle_where_it_was_and_forces_resume_after_resync() -> None:
    supervisor = make()
    run_in_sync(supervisor, RESYNC)
    now_s = RESYNC * PERIOD_S
    moved = (0.013, 0.021)
    # silence just under the limit: still enabled
    assert supervisor.update(now_s, None, moved, silence_s=MAX_AGE_S * 0.99) is Transition.NONE
    assert supervisor.enabled
    # just over: forces off, the handle held where it is now
    assert supervisor.update(now_s, None, moved, silence_s=MAX_AGE_S * 1.01) is Transition.HOLD
    assert not supervisor.enabled
    assert np.allclose(supervisor.hold_m, moved)
    assert supervisor.trips == 1
    # the slave is back: forces come on again only through a full resync, as RESUME
    handle = (0.01, 0.02)
    transitions = [supervisor.update(now_s + (i + 1) * PERIOD_S,
                                     tool(RATIO[0] * handle[0], RATIO[1] * handle[1], seq=i),
                                     handle) for i in range(RESYNC + 1)]
    assert Transition.RESUME in transitions and Transition.ACTIVATE not in transitions
    assert supervisor.enabled


def test_a_lost_liveliness_token_trips_at_once() -> None:
    supervisor = make()
    run_in_sync(supervisor, RESYNC)
    assert supervisor.update(1.0, None, (0.0, 0.0), peer_alive=False) is Transition.HOLD


def test_a_hardware_fault_latches_the_safe_state_for_the_rest_of_the_run() -> None:
    supervisor = make()
    run_in_sync(supervisor, RESYNC)
    assert supervisor.update(0.1, None, (0.01, 0.02), faults=("x: following error",),
                             cycle=7) is Transition.HOLD
    assert supervisor.faulted
    assert supervisor.hardware_faults == ["cycle 7: x: following error"]
    assert [e["kind"] for e in supervisor.events] == ["node_trip"]
    assert not any(t is not Transition.NONE for t in run_in_sync(supervisor, 3 * RESYNC, 200))
    assert not supervisor.enabled


def test_a_node_trip_turns_forces_off_at_the_next_tick() -> None:
    supervisor = make()
    run_in_sync(supervisor, RESYNC)
    supervisor.note_node_fault()
    assert run_in_sync(supervisor, 1, RESYNC)[0] is Transition.HOLD
    assert not supervisor.enabled


def test_a_non_finite_handle_position_is_never_held() -> None:
    supervisor = make()
    run_in_sync(supervisor, RESYNC)
    supervisor.update(1.0, None, (float("nan"), 0.03), silence_s=1.0)
    np.testing.assert_array_equal(supervisor.hold_m, [0.0, 0.03])


@pytest.mark.parametrize("tolerance_m", [0.0, -0.001, float("nan")])
def test_a_tolerance_that_is_not_positive_is_refused(tolerance_m) -> None:
    with pytest.raises(ValueError, match="sync_tolerance_m"):
        MasterSupervisor(RATIO, tolerance_m, MAX_AGE_S, RESYNC)


def test_before_start_the_hold_is_the_origin_of_both_axes() -> None:
    supervisor = MasterSupervisor(RATIO, 0.001, MAX_AGE_S, RESYNC)
    np.testing.assert_array_equal(supervisor.hold_m, [0.0, 0.0])


@pytest.mark.parametrize("axis", [0, 1])
def test_an_offset_of_exactly_the_tolerance_is_not_in_sync(axis) -> None:
    """The band is open: |yt - Ah1 yh| < tolerance (0.25 m and 0.5 are exact binary)."""
    supervisor = MasterSupervisor((1.0, 1.0), 0.25, MAX_AGE_S, RESYNC)
    position = [0.0, 0.0]
    position[axis] = 0.25
    supervisor.tool = tool(*position)
    assert not supervisor.in_sync(0.0, 0.0)
    position[axis] = 0.2499
    supervisor.tool = tool(*position)
    assert supervisor.in_sync(0.0, 0.0)


def test_a_fault_without_a_cycle_is_logged_at_cycle_0() -> None:
    supervisor = make()
    supervisor.update(0.0, None, (0.01, 0.02), faults=("drive x: EMCY 0x8130",))
    supervisor.update(PERIOD_S, None, (0.01, 0.02), faults=("drive y: EMCY 0x8130",), cycle=7)
    assert supervisor.hardware_faults == ["cycle 0: drive x: EMCY 0x8130",
                                          "cycle 7: drive y: EMCY 0x8130"]


# --- with the tool-input guard (master/tool_guard.py) -------------------------------------

def guarded(clear_after: int = 3) -> MasterSupervisor:
    from haptic.master.tool_guard import ToolGuardSettings, ToolInputGuard

    settings = ToolGuardSettings(clear_after_messages=clear_after)
    supervisor = MasterSupervisor(RATIO, 0.001, MAX_AGE_S, RESYNC,
                                  ToolInputGuard(settings, PERIOD_S))
    supervisor.start((0.01, 0.02))
    return supervisor


def test_a_guarded_supervisor_runs_like_an_unguarded_one_on_plausible_messages() -> None:
    supervisor = guarded()
    assert not supervisor.input_faulted
    transitions = run_in_sync(supervisor, RESYNC)
    assert transitions[-1] is Transition.ACTIVATE and supervisor.enabled
    assert supervisor.stop_reason() == "watchdog ok"
    assert not supervisor.input_faulted


def test_an_implausible_tool_message_turns_forces_off_until_cleared_and_in_sync() -> None:
    supervisor = guarded(clear_after=3)
    run_in_sync(supervisor, RESYNC)
    handle = (0.01, 0.02)
    bad = tool(RATIO[0] * handle[0], RATIO[1] * handle[1], seq=RESYNC)
    bad = ToolState(1, RESYNC, RESYNC * 540_000, bad.flags, (1e6, 0.0), bad.tool_position_m,
                    (0.0, 0.0), 0.0, 0.0)
    assert supervisor.update(RESYNC * PERIOD_S, bad, handle) is Transition.HOLD
    assert not supervisor.enabled and supervisor.input_faulted
    assert supervisor.tool.tool_force_N != (1e6, 0.0)  # not an input
    assert supervisor.stop_reason() == "tool input fault"
    # plausible messages again: the guard clears after 3, forces wait for the resync check
    transitions = [supervisor.update((RESYNC + i) * PERIOD_S,
                                     _timed_tool(RATIO[0] * handle[0], RATIO[1] * handle[1],
                                                 RESYNC + i), handle)
                   for i in range(1, 3)]
    assert transitions == [Transition.NONE] * 2 and supervisor.input_faulted
    assert supervisor.stop_reason() == "tool input fault"
    resumed = supervisor.update((RESYNC + 3) * PERIOD_S,
                                _timed_tool(RATIO[0] * handle[0], RATIO[1] * handle[1],
                                            RESYNC + 3), handle)
    assert resumed is Transition.RESUME and supervisor.enabled
    assert not supervisor.input_faulted


def test_after_an_input_fault_forces_wait_for_the_tool_at_the_handle() -> None:
    supervisor = guarded(clear_after=1)
    run_in_sync(supervisor, RESYNC)
    handle = (0.01, 0.02)
    bad = ToolState(1, RESYNC, RESYNC * 540_000, Flags.FORCES_ENABLED, (math.nan, 0.0),
                    (RATIO[0] * handle[0], RATIO[1] * handle[1]), (0.0, 0.0), 0.0, 0.0)
    assert supervisor.update(RESYNC * PERIOD_S, bad, handle) is Transition.HOLD
    # plausible but 2 mm away from Ah1 yh: the guard clears, the resync check does not pass
    # (each move below stays inside the guard's 2 m/s x 0.54 ms + 2 mm allowance)
    far = _timed_tool(RATIO[0] * handle[0] + 0.002, RATIO[1] * handle[1], RESYNC + 1)
    assert supervisor.update((RESYNC + 1) * PERIOD_S, far, handle) is Transition.NONE
    assert supervisor.input_faulted and not supervisor.enabled
    assert supervisor.stop_reason() == "tool input fault: waiting for the tool at the handle"
    back = _timed_tool(RATIO[0] * handle[0] + 0.0015, RATIO[1] * handle[1], RESYNC + 2)
    assert supervisor.update((RESYNC + 2) * PERIOD_S, back, handle) is Transition.NONE
    assert supervisor.input_faulted  # still 1.5 mm off
    home = _timed_tool(RATIO[0] * handle[0], RATIO[1] * handle[1], RESYNC + 3)
    assert supervisor.update((RESYNC + 3) * PERIOD_S, home, handle) is Transition.RESUME


def test_no_message_is_not_a_fault() -> None:
    supervisor = guarded()
    run_in_sync(supervisor, RESYNC)
    assert supervisor.update(RESYNC * PERIOD_S, None, (0.01, 0.02)) is Transition.NONE
    assert supervisor.enabled and not supervisor.input_faulted
    assert supervisor.tool_guard.counters.faults == 0


def test_stop_reasons_name_the_latest_hardware_fault() -> None:
    supervisor = make()
    supervisor.update(0.0, None, (0.01, 0.02), faults=("drive x: EMCY 0x8130",))
    supervisor.update(PERIOD_S, None, (0.01, 0.02), faults=("drive y: EMCY 0x8611",))
    supervisor.update(2 * PERIOD_S, None, (0.01, 0.02), faults=("sensor: frame lost",), cycle=2)
    assert supervisor.stop_reason() == "node or hardware fault: cycle 2: sensor: frame lost"
    node_only = make()
    node_only.note_node_fault()
    assert node_only.stop_reason() == "node or hardware fault: safety layer trip"


def test_a_warm_start_is_enabled_and_counts_as_ever_enabled() -> None:
    supervisor = make()
    assert not supervisor.peer_held  # nothing has stopped the tool yet
    assert supervisor.stop_reason().startswith("watchdog")
    supervisor.start_synced()
    assert supervisor.enabled and supervisor.ever_enabled
    assert supervisor.state_name() == "ok"
    # the lockstep's first ticks, before the delayed first message: still enabled
    assert supervisor.update(0.0, None, (0.01, 0.02)) is Transition.NONE
    # the next tick in sync changes nothing; a silence then holds
    assert run_in_sync(supervisor, 1)[0] is Transition.NONE
    assert supervisor.update(1.0, None, (0.01, 0.02), silence_s=1.0) is Transition.HOLD


def _timed_tool(x_m: float, y_m: float, seq: int) -> ToolState:
    return ToolState(1, seq, seq * 540_000, Flags.FORCES_ENABLED, (0.0, 0.0), (x_m, y_m),
                     (0.0, 0.0), 0.0, 0.0)


def test_a_missing_handle_reading_never_goes_on_the_wire() -> None:
    """A missed PDO reads NaN on an axis: the master sends the last measured position (the
    node trips on the NaN itself); a finite reading goes out as it is."""
    from haptic.common.wire.messages import HandleState, encode
    from haptic.master.program import position_for_the_wire

    last = (0.01, 0.02)
    assert position_for_the_wire((0.011, 0.021), last) == (0.011, 0.021)
    for missing in ((math.nan, 0.021), (0.011, math.nan), (math.inf, -math.inf)):
        sent = position_for_the_wire(missing, last)
        assert sent == last
        encode(HandleState(1, 1, 1, Flags.SAFE_STATE, (0.0, 0.0), sent))  # never raises


def test_the_slaves_work_area_stop_holds_the_handle_until_the_tool_is_back_in_sync() -> None:
    """Issue 16: the slave's work-area guard (Flags.WORK_AREA_STOP) holds the handle too,
    with an event and a count; forces return only once the flag clears and the tool is at
    Ah1 yh again, not merely when the flag clears."""
    supervisor = make()
    run_in_sync(supervisor, RESYNC)
    assert supervisor.enabled
    handle = (0.01, 0.02)
    stopped = ToolState(1, 100, 0, Flags.SAFE_STATE | Flags.WORK_AREA_STOP, (0.0, 0.0),
                        (0.05, 0.01), (0.0, 0.0), 0.0, 0.0)
    assert supervisor.update(100 * PERIOD_S, stopped, handle) is Transition.HOLD
    assert supervisor.peer_stops == 1
    assert [e["kind"] for e in supervisor.events].count("handle_held") == 1
    np.testing.assert_allclose(supervisor.hold_m, handle)
    for i in range(1, 10):  # still stopped: held, counted once
        supervisor.update((100 + i) * PERIOD_S, ToolState(
            1, 100 + i, 0, stopped.flags, (0.0, 0.0), (0.05, 0.01), (0.0, 0.0), 0.0, 0.0),
            handle)
    assert not supervisor.enabled and supervisor.peer_stops == 1
    # the flag clears but the tool is not yet at the handle: still held
    supervisor.update(110 * PERIOD_S, tool(0.05, 0.01, seq=110), handle)
    assert not supervisor.enabled
    transitions = run_in_sync(supervisor, 2, start=111)
    assert Transition.RESUME in transitions and supervisor.enabled


def test_a_slave_that_stops_its_tool_holds_the_handle_until_it_is_ready_and_in_sync() -> None:
    """The slave stops its tool on its own (its watchdog, an input fault: FORCES_ENABLED gone
    from its messages) while the master's forces are on: the handle is held too, with an
    event saying why, and forces return only once the slave reports its forces enabled and
    its tool at Ah1 yh again."""
    supervisor = make()
    run_in_sync(supervisor, RESYNC)
    assert supervisor.enabled
    handle = (0.01, 0.02)
    assert supervisor.update(100 * PERIOD_S, tool(0.02, 0.01, enabled=False, seq=100),
                             handle) is Transition.HOLD
    assert supervisor.peer_held and supervisor.peer_stops == 1
    held = [e for e in supervisor.events if e["kind"] == "handle_held"]
    assert len(held) == 1 and "the slave stopped its tool" in held[0]["reason"]
    assert "the slave stopped its tool" in supervisor.stop_reason()
    for i in range(1, 10):  # the slave still stopped: held, counted once
        assert supervisor.update((100 + i) * PERIOD_S,
                                 tool(0.02, 0.01, enabled=False, seq=100 + i),
                                 handle) is Transition.NONE
    assert not supervisor.enabled and supervisor.peer_stops == 1
    # ready again but its tool elsewhere: still held
    supervisor.update(110 * PERIOD_S, tool(0.05, 0.01, seq=110), handle)
    assert not supervisor.enabled
    transitions = run_in_sync(supervisor, 2, start=111)
    assert Transition.RESUME in transitions and supervisor.enabled
    assert not supervisor.peer_held and supervisor.watchdog.trips == 0


def test_a_slave_not_ready_before_forces_came_on_holds_nothing_new() -> None:
    """Before the master's forces first come on (and during its own resync) a slave without
    FORCES_ENABLED is the watchdog's business: no handle_held event, no count."""
    supervisor = make()
    handle = (0.01, 0.02)
    for i in range(20):
        supervisor.update(i * PERIOD_S, tool(0.02, 0.01, enabled=False, seq=i), handle)
    assert not supervisor.enabled and supervisor.peer_stops == 0
    assert not [e for e in supervisor.events if e["kind"] == "handle_held"]
    transitions = run_in_sync(supervisor, RESYNC, start=20)
    assert transitions.count(Transition.ACTIVATE) == 1 and supervisor.enabled


def test_steady_is_forces_on_with_nothing_latched_awaited_or_guarded() -> None:
    """The lockstep's quiet lanes rely on it (master/quiet_kernel.py): each condition alone
    makes a supervisor not steady."""
    fresh = make()
    assert (fresh.peer_stops, fresh.work_area_stops) == (0, 0) and not fresh.steady()

    def steady_supervisor() -> MasterSupervisor:
        supervisor = make()
        assert run_in_sync(supervisor, RESYNC)[-1] is Transition.ACTIVATE
        return supervisor

    assert_steady_needs_each(steady_supervisor, (
        ("enabled", False), ("faulted", True), ("_await_sync", True), ("_await_peer", True),
        ("tool_guard", object())))


def test_the_slaves_last_message_holds_the_handle_without_a_trip() -> None:
    """An orderly end of the slave's run (SAFE_STATE | STOPPING): the handle is held at once
    and no trip is counted, not even when its liveliness token goes next; a new run of the
    slave resyncs as after a trip."""
    supervisor = make()
    run_in_sync(supervisor, RESYNC)
    handle = (0.01, 0.02)
    goodbye = ToolState(1, RESYNC, 0, Flags.SAFE_STATE | Flags.STOPPING, (0.0, 0.0),
                        (RATIO[0] * handle[0], RATIO[1] * handle[1]), (0.0, 0.0), 0.0, 0.0)
    assert supervisor.update(RESYNC * PERIOD_S, goodbye, handle) is Transition.HOLD
    assert supervisor.update((RESYNC + 1) * PERIOD_S, None, handle, peer_alive=False) \
        is Transition.NONE
    assert supervisor.trips == 0 and supervisor.watchdog.peer_ends == 1
    assert supervisor.watchdog.state is WatchdogState.TRIPPED
    assert supervisor.watchdog.events[-1].kind == "peer_ended"
    assert supervisor.peer_stops == 0 and not supervisor.peer_held  # no stop to wait out
    assert supervisor.stop_reason() == "the peer ended its run"
    assert not supervisor.steady()
    transitions = run_in_sync(supervisor, RESYNC, start=RESYNC + 2)
    assert transitions[-1] is Transition.RESUME and supervisor.trips == 0
