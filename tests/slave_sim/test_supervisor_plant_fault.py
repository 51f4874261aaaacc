"""The slave supervisor's robot-plant fault events (slave_sim/supervisor.py): a trip is said
once, when it starts, even while the tool is already stopped for another cause (it now stays
stopped for good); a trip that stops a running tool is said once, by its stop event; a trip on
the tick another cause stopped the tool is said after that cause's event."""

from __future__ import annotations

from haptic.common.wire.messages import Flags, HandleState
from haptic.slave_sim.supervisor import SlaveSupervisor, Transition

PERIOD_S = 0.00054
RESYNC = 4
AREA = (-0.01, 0.2, -0.01, 0.05)
STAYS_STOPPED = "the robot plant's watchdog tripped: the tool stays stopped"
STOPS = "the robot plant's watchdog tripped: the tool stops"


def handle(x_m: float, seq: int, enabled: bool = True) -> HandleState:
    flags = Flags.FORCES_ENABLED if enabled else Flags.SAFE_STATE
    return HandleState(1, seq, 0, flags, (0.0, 0.0), (x_m, 0.0))


def running_supervisor() -> SlaveSupervisor:
    supervisor = SlaveSupervisor((1.0, 1.0), 0.001, AREA, 0.03, RESYNC)
    for i in range(RESYNC):
        supervisor.receive(handle(0.05, i))
        supervisor.update(i * PERIOD_S, True, (0.05, 0.0))
    assert supervisor.running
    return supervisor


def reasons(supervisor: SlaveSupervisor) -> list[str]:
    return [event["reason"] for event in supervisor.events]


def test_a_new_supervisor_has_no_plant_fault() -> None:
    supervisor = SlaveSupervisor((1.0, 1.0), 0.001, AREA, 0.03, RESYNC)
    assert not supervisor.plant_fault
    supervisor.start_synced((0.05, 0.0))
    assert supervisor.steady()


def test_a_trip_of_a_halted_tool_is_said_once_when_it_starts() -> None:
    supervisor = SlaveSupervisor((1.0, 1.0), 0.001, AREA, 0.03, RESYNC)
    supervisor.receive(handle(0.05, 0))
    assert supervisor.update(0.0, True, (0.05, 0.0), plant_fault=True) is Transition.NONE
    assert reasons(supervisor) == [STAYS_STOPPED]
    for i in range(1, 6):
        supervisor.receive(handle(0.05, i))
        supervisor.update(i * PERIOD_S, True, (0.05, 0.0), plant_fault=True)
    assert reasons(supervisor) == [STAYS_STOPPED]
    assert not supervisor.running


def test_a_trip_while_stopped_for_another_cause_is_said_after_it() -> None:
    supervisor = running_supervisor()
    supervisor.receive(handle(0.05, 10, enabled=False))
    assert supervisor.update(0.1, True, (0.05, 0.0)) is Transition.STOP
    before = reasons(supervisor)
    supervisor.receive(handle(0.05, 11, enabled=False))
    assert supervisor.update(0.2, True, (0.05, 0.0), plant_fault=True) is Transition.NONE
    assert reasons(supervisor) == [*before, STAYS_STOPPED]
    supervisor.receive(handle(0.05, 12, enabled=False))
    supervisor.update(0.3, True, (0.05, 0.0), plant_fault=True)
    assert reasons(supervisor) == [*before, STAYS_STOPPED]


def test_a_trip_that_stops_the_running_tool_is_said_by_its_stop_event_only() -> None:
    supervisor = running_supervisor()
    # an input fault and its end first: the trip's event is not the first nor the second
    supervisor.receive(handle(0.05, 10))
    assert supervisor.update(0.1, True, (0.05, 0.0), input_fault=True) is Transition.STOP
    supervisor.receive(handle(0.05, 11))
    assert supervisor.update(0.2, True, (0.05, 0.0)) is Transition.RESUME
    before = reasons(supervisor)
    assert len(before) >= 3
    supervisor.receive(handle(0.05, 12))
    assert supervisor.update(0.3, True, (0.05, 0.0), plant_fault=True) is Transition.STOP
    assert reasons(supervisor) == [*before, STOPS]


def test_a_trip_on_the_tick_the_work_area_guard_stops_the_tool_is_said_after_it() -> None:
    supervisor = running_supervisor()
    supervisor.receive(handle(0.25, 10))
    assert supervisor.update(0.1, True, (0.25, 0.0), plant_fault=True) is Transition.STOP
    assert supervisor.events[-2]["reason"].startswith("tool left the work area")
    assert supervisor.events[-1] == {"time_s": 0.1, "kind": "tool_stopped",
                                     "reason": STAYS_STOPPED}
