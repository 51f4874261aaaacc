"""The slave's supervisor as a pure block: the tool follows the handle while halted, runs
only with the watchdog ok and the master's forces on, and the work-area guard stops it."""

from __future__ import annotations

from haptic.common.runtime.watchdog import WatchdogState
from haptic.common.wire.messages import Flags, HandleState
from haptic.slave_sim.supervisor import SlaveSupervisor, Transition
from tests.helpers.steady import assert_steady_needs_each

PERIOD_S = 0.00054
MAX_AGE_S = 0.03
RESYNC = 4
RATIO = (1.0, 1.0)
AREA = (-0.01, 0.2, -0.01, 0.05)


def handle(x_m: float, y_m: float = 0.0, enabled: bool = True, seq: int = 0) -> HandleState:
    flags = Flags.FORCES_ENABLED if enabled else Flags.SAFE_STATE
    return HandleState(1, seq, 0, flags, (0.0, 0.0), (x_m, y_m))


def make() -> SlaveSupervisor:
    return SlaveSupervisor(RATIO, 0.001, AREA, MAX_AGE_S, RESYNC)


def start(supervisor: SlaveSupervisor, x_m: float = 0.05) -> list[Transition]:
    transitions = []
    for i in range(RESYNC):
        follow = supervisor.receive(handle(x_m, seq=i))
        assert follow  # halted: every fresh message re-places the tool at the handle
        transitions.append(supervisor.update(i * PERIOD_S, True, (x_m, 0.0)))
    return transitions


def test_the_tool_runs_after_the_resync_with_the_masters_forces_on() -> None:
    supervisor = make()
    transitions = start(supervisor)
    assert transitions[-1] is Transition.RESUME and supervisor.running and supervisor.ready
    # running: fresh messages no longer re-place the tool
    assert not supervisor.receive(handle(0.06, seq=9))


def test_the_master_in_its_safe_state_stops_the_tool_but_this_side_stays_ready() -> None:
    supervisor = make()
    start(supervisor)
    supervisor.receive(handle(0.05, enabled=False, seq=10))
    assert supervisor.update(0.1, True, (0.05, 0.0)) is Transition.STOP
    assert not supervisor.running and supervisor.ready
    assert supervisor.events[-1]["reason"].startswith("the master is in its safe state")


def test_silence_over_the_limit_stops_the_tool_and_under_it_does_not() -> None:
    supervisor = make()
    start(supervisor)
    assert supervisor.update(0.1, False, (0.05, 0.0), silence_s=MAX_AGE_S * 0.99) \
        is Transition.NONE
    assert supervisor.update(0.1, False, (0.05, 0.0), silence_s=MAX_AGE_S * 1.01) \
        is Transition.STOP
    assert not supervisor.ready and supervisor.trips == 1


def test_the_work_area_guard_stops_the_tool_until_a_resync_cycle() -> None:
    supervisor = make()
    start(supervisor)
    assert supervisor.update(0.1, True, (0.2 + 1e-4, 0.0)) is Transition.STOP
    assert supervisor.outside and not supervisor.ready
    assert supervisor.events[-1]["kind"] == "tool_stopped"
    # stopped by the guard: the tool does not follow the handle ...
    assert not supervisor.receive(handle(0.05, seq=20))
    assert supervisor.update(0.11, True, (0.2 + 1e-4, 0.0)) is Transition.NONE
    # ... until the master goes to its safe state, which ends the guard's stop
    supervisor.receive(handle(0.05, enabled=False, seq=21))
    supervisor.update(0.12, True, (0.2 + 1e-4, 0.0))
    assert not supervisor.outside
    assert supervisor.receive(handle(0.05, seq=22))


def test_out_of_sync_never_runs() -> None:
    supervisor = make()
    for i in range(3 * RESYNC):
        supervisor.receive(handle(0.05, seq=i))
        supervisor.update(i * PERIOD_S, True, (0.05 + 0.0011, 0.0))
    assert not supervisor.running and not supervisor.ready


def test_after_a_work_area_stop_the_tool_runs_again_only_once_back_at_the_handle() -> None:
    """The handle back over the grid ends the guard's stop, but the tool (still outside,
    moving back through the clay at a bounded speed) runs only once in sync: no
    stop/resume cycle at the edge."""
    grid = (0.0, 0.19, 0.0, 0.04)
    supervisor = SlaveSupervisor(RATIO, 0.001, AREA, MAX_AGE_S, RESYNC, grid_m=grid)
    start(supervisor)
    assert supervisor.update(0.1, True, (0.2 + 1e-4, 0.0)) is Transition.STOP
    transitions = []
    tool_x_m = 0.2 + 1e-4
    for i in range(40):  # the handle is back at 0.15 m; the tool closes in 2 mm a tick
        follow = supervisor.receive(handle(0.15, seq=30 + i))
        if follow:
            tool_x_m = max(0.15, tool_x_m - 0.002)
        transitions.append(supervisor.update(0.1 + (i + 1) * PERIOD_S, True, (tool_x_m, 0.0)))
    assert transitions.count(Transition.STOP) == 0
    assert transitions.count(Transition.RESUME) == 1
    resumed = transitions.index(Transition.RESUME)
    assert resumed >= 24  # 50 mm back at 2 mm a tick, then in sync
    assert supervisor.running and abs(tool_x_m - 0.15) < 0.001


def test_a_tolerance_that_is_not_positive_is_refused() -> None:
    for tolerance_m in (0.0, -0.001, float("nan")):
        try:
            SlaveSupervisor(RATIO, tolerance_m, AREA, MAX_AGE_S, RESYNC)
        except ValueError as error:
            assert "sync_tolerance_m" in str(error)
        else:
            raise AssertionError(f"tolerance {tolerance_m} accepted")


def test_before_any_message_nothing_is_enabled_and_the_handle_is_at_the_origin() -> None:
    supervisor = make()
    assert supervisor.handle_position_m == (0.0, 0.0)
    assert not (supervisor.master_enabled or supervisor.ready or supervisor.running
                or supervisor.rejoining or supervisor.input_fault or supervisor.outside)
    # the origin is what in_sync compares against before the first message
    assert supervisor.in_sync(0.0, 0.0) and not supervisor.in_sync(0.0011, 0.0)
    assert not supervisor.in_sync(0.0, 0.0011)


def test_an_offset_of_exactly_the_tolerance_is_not_in_sync() -> None:
    """The band is open on both axes (0.25 m is an exact binary fraction)."""
    supervisor = SlaveSupervisor(RATIO, 0.25, AREA, MAX_AGE_S, RESYNC)
    supervisor.receive(handle(0.0, 0.0))
    assert not supervisor.in_sync(0.25, 0.0) and not supervisor.in_sync(0.0, -0.25)
    assert supervisor.in_sync(0.2499, 0.0) and supervisor.in_sync(0.0, -0.2499)


def test_the_work_area_edges_belong_to_the_work_area() -> None:
    """A tool exactly on an edge of the work area keeps running; just beyond it stops."""
    x_low, x_high, y_low, y_high = AREA
    for edge in ((x_low, 0.0), (x_high, 0.0), (0.05, y_low), (0.05, y_high)):
        supervisor = make()
        start(supervisor)
        supervisor.receive(handle(*edge, seq=20))
        assert supervisor.update(0.1, True, edge) is Transition.NONE, edge
        assert supervisor.running and not supervisor.outside, edge
    supervisor = make()
    start(supervisor)
    assert supervisor.update(0.1, False, (x_high + 1e-9, 0.0)) is Transition.STOP
    assert supervisor.outside


def test_the_handle_exactly_on_the_grids_edge_is_back_over_it() -> None:
    grid = (0.0, 0.125, -0.0625, 0.0625)  # exact binary fractions
    for back in ((0.0, 0.0), (0.125, 0.0), (0.05, -0.0625), (0.05, 0.0625)):
        supervisor = SlaveSupervisor(RATIO, 0.001, AREA, MAX_AGE_S, RESYNC, grid_m=grid)
        start(supervisor)
        supervisor.receive(handle(0.3, seq=20))
        assert supervisor.update(0.1, True, (0.3, 0.0)) is Transition.STOP
        supervisor.receive(handle(*back, seq=21))
        supervisor.update(0.1 + PERIOD_S, True, (0.3, 0.0))
        assert not supervisor.outside and supervisor.rejoining, back
        assert supervisor.events[-1]["kind"] == "tool_resync"


def test_stop_reasons_name_the_watchdog_or_the_master() -> None:
    supervisor = make()
    start(supervisor)
    supervisor.receive(handle(0.05, enabled=False, seq=10))
    supervisor.update(0.1, True, (0.05, 0.0))
    assert supervisor.stop_reason() == "the master's forces are off"
    supervisor.update(0.2, False, (0.05, 0.0), silence_s=1.0)
    assert supervisor.stop_reason() == "watchdog tripped"
    supervisor.update(0.3, False, (0.05, 0.0), silence_s=1.0, input_fault=True)
    assert supervisor.stop_reason() == "input fault"


def test_a_warm_start_runs_at_once_with_the_handle_where_it_is() -> None:
    supervisor = make()
    supervisor.start_synced((0.03, 0.02))
    assert supervisor.handle_position_m == (0.03, 0.02)
    assert supervisor.master_enabled and supervisor.running and supervisor.ready
    assert supervisor.update(0.0, False, (0.03, 0.02)) is Transition.NONE
    assert supervisor.running


def test_a_work_area_stop_lasts_while_the_master_holds_until_the_handle_is_back() -> None:
    """Issue 16: the master holds its handle on the slave's work-area stop; with a grid, that
    hold does not end the stop (no stop/hold/resume cycle at the edge): the handle back over
    the grid does."""
    grid = (0.0, 0.19, 0.0, 0.04)
    supervisor = SlaveSupervisor(RATIO, 0.001, AREA, MAX_AGE_S, RESYNC, grid_m=grid)
    start(supervisor)
    assert supervisor.update(0.1, True, (0.2 + 1e-4, 0.0)) is Transition.STOP
    for i in range(10):  # the master holds (safe state), the handle still beyond the grid
        supervisor.receive(handle(0.21, enabled=False, seq=30 + i))
        supervisor.update(0.1 + (i + 1) * PERIOD_S, True, (0.2 + 1e-4, 0.0))
        assert supervisor.outside and not supervisor.ready
    supervisor.receive(handle(0.15, enabled=False, seq=40))  # the handle back over the grid
    supervisor.update(0.2, True, (0.2 + 1e-4, 0.0))
    assert not supervisor.outside and supervisor.ready


def test_steady_is_running_with_nothing_stopped_rejoining_or_faulted() -> None:
    """The lockstep's quiet lanes rely on it (slave_sim/quiet_kernel.py): each condition alone
    makes a supervisor not steady."""
    assert not make().steady()

    def steady_supervisor() -> SlaveSupervisor:
        supervisor = make()
        assert start(supervisor)[-1] is Transition.RESUME
        return supervisor

    assert_steady_needs_each(steady_supervisor, (
        ("running", False), ("master_enabled", False), ("outside", True), ("rejoining", True),
        ("input_fault", True)))


def test_the_masters_last_message_stops_the_tool_without_a_trip() -> None:
    """An orderly end of the master's run (SAFE_STATE | STOPPING): the tool stops at once
    with the watchdog's safe state, no trip is counted when the master's liveliness token
    goes next, and a new run of the master resyncs as after a trip."""
    supervisor = make()
    start(supervisor)
    goodbye = HandleState(1, 10, 0, Flags.SAFE_STATE | Flags.STOPPING, (0.0, 0.0), (0.05, 0.0))
    supervisor.receive(goodbye)
    assert supervisor.peer_stopping
    assert supervisor.update(0.1, True, (0.05, 0.0)) is Transition.STOP
    assert not supervisor.peer_stopping  # taken once
    assert not supervisor.running and not supervisor.ready
    assert supervisor.watchdog.state is WatchdogState.TRIPPED
    assert supervisor.events[-1]["reason"] == "the peer ended its run: the tool stops"
    assert supervisor.stop_reason() == "the peer ended its run"
    supervisor.receive(None)
    supervisor.update(0.101, False, (0.05, 0.0), silence_s=0.001, peer_alive=False)
    assert supervisor.trips == 0 and supervisor.watchdog.peer_ends == 1
    assert [e.kind for e in supervisor.watchdog.events][-1] == "peer_ended"
    for i in range(RESYNC):
        supervisor.receive(handle(0.05, seq=i))
        transition = supervisor.update(0.2 + i * PERIOD_S, True, (0.05, 0.0))
    assert transition is Transition.RESUME and supervisor.trips == 0


def test_a_tick_without_a_message_is_no_goodbye() -> None:
    """receive(None) clears what the last message said: the tool runs on and nothing ends."""
    supervisor = make()
    start(supervisor)
    supervisor.receive(None)
    assert not supervisor.peer_stopping
    assert supervisor.update(0.01, False, (0.05, 0.0), silence_s=0.001) is Transition.NONE
    assert supervisor.running and supervisor.watchdog.peer_ends == 0


def test_a_plant_fault_stops_the_tool_and_withdraws_its_forces() -> None:
    """A robot plant whose own watchdog tripped: the tool stops, this side is not ready (its
    messages lose FORCES_ENABLED, so the master holds its handle), and the reason says so."""
    supervisor = make()
    start(supervisor)
    supervisor.receive(handle(0.05, seq=10))
    assert supervisor.update(0.1, True, (0.05, 0.0), plant_fault=True) is Transition.STOP
    assert not supervisor.running and not supervisor.ready and not supervisor.steady()
    assert supervisor.events[-1]["reason"] == (
        "the robot plant's watchdog tripped: the tool stops")
    assert supervisor.stop_reason() == "the robot plant's watchdog tripped"
