"""The slave supervisor's parts of issue 17: an input fault stops the tool (and says why), and
after the work-area guard stopped it, the tool rejoins the handle once the handle is back over
the grid (the resync policy), without waiting for a watchdog cycle."""

from __future__ import annotations

from haptic.common.wire.messages import Flags, HandleState
from haptic.slave_sim.supervisor import SlaveSupervisor, Transition

PERIOD_S = 0.00054
RESYNC = 4
AREA = (-0.01, 0.2, -0.01, 0.05)   # with its margin
GRID = (0.0, 0.19, 0.0, 0.04)      # the grid itself


def handle(x_m: float, seq: int) -> HandleState:
    return HandleState(1, seq, 0, Flags.FORCES_ENABLED, (0.0, 0.0), (x_m, 0.01))


def running_supervisor() -> SlaveSupervisor:
    supervisor = SlaveSupervisor((1.0, 1.0), 0.001, AREA, 0.03, RESYNC, grid_m=GRID)
    for i in range(RESYNC):
        supervisor.receive(handle(0.05, i))
        supervisor.update(i * PERIOD_S, True, (0.05, 0.01))
    assert supervisor.running
    return supervisor


def test_an_input_fault_stops_the_tool_and_clears() -> None:
    supervisor = running_supervisor()
    t = RESYNC * PERIOD_S
    assert supervisor.update(t, True, (0.05, 0.01), input_fault=True) is Transition.STOP
    assert not supervisor.ready and supervisor.stop_reason() == "input fault"
    assert supervisor.events[-1]["reason"] == "input fault: the tool stops"
    supervisor.receive(handle(0.05, 10))
    assert supervisor.update(t + PERIOD_S, True, (0.05, 0.01)) is Transition.RESUME


def test_the_tool_rejoins_the_handle_back_over_the_grid() -> None:
    supervisor = running_supervisor()
    t = RESYNC * PERIOD_S
    # the tool left the work area: stopped
    supervisor.receive(handle(0.25, 10))
    assert supervisor.update(t, True, (0.25, 0.01)) is Transition.STOP
    assert supervisor.outside
    assert supervisor.stop_reason() == "the tool is stopped by the work-area guard"
    # the handle is still outside the grid: the stop holds, the tool is not re-placed
    assert not supervisor.receive(handle(0.195, 11))
    supervisor.update(t + PERIOD_S, True, (0.25, 0.01))
    assert supervisor.outside and not supervisor.running
    # back over the grid: the stop ends; the next message re-places the tool at the handle
    assert not supervisor.receive(handle(0.10, 12))
    # the tool is still out there: it does not run (no flapping) until it is at the handle
    assert supervisor.update(t + 2 * PERIOD_S, True, (0.25, 0.01)) is Transition.NONE
    assert not supervisor.outside and not supervisor.running
    assert supervisor.events[-1]["kind"] == "tool_resync"
    assert "rejoins" in supervisor.stop_reason()
    # on its way back (still outside the area) the guard does not stop it again
    assert supervisor.receive(handle(0.10, 13))
    supervisor.update(t + 2.5 * PERIOD_S, True, (0.22, 0.01))
    assert not supervisor.outside and supervisor.rejoining
    assert [e["kind"] for e in supervisor.events].count("tool_stopped") == 1
    assert supervisor.receive(handle(0.10, 14))  # re-place the tool (resync)
    assert supervisor.update(t + 3 * PERIOD_S, True, (0.10, 0.01)) is Transition.RESUME


def test_without_a_grid_only_a_resync_cycle_ends_the_stop() -> None:
    supervisor = SlaveSupervisor((1.0, 1.0), 0.001, AREA, 0.03, RESYNC)
    for i in range(RESYNC):
        supervisor.receive(handle(0.05, i))
        supervisor.update(i * PERIOD_S, True, (0.05, 0.01))
    supervisor.update(RESYNC * PERIOD_S, True, (0.25, 0.01))
    supervisor.receive(handle(0.10, 20))
    supervisor.update((RESYNC + 1) * PERIOD_S, True, (0.25, 0.01))
    assert supervisor.outside
