"""The supervision core both supervisors share, and the peer-input guard both sides put on
what they receive: one definition, used by both sides."""

from __future__ import annotations

import pytest

from haptic.common.runtime import peer_guard, supervision
from haptic.common.runtime.supervision import SupervisionCore, Transition


def test_the_resync_check_is_strict_on_both_axes() -> None:
    core = SupervisionCore((2.0, 0.5), 0.001, 0.03, 3)
    assert core.positions_in_sync(0.0205, 0.0, 0.01, 0.0)  # 0.5 mm off x
    assert not core.positions_in_sync(0.021, 0.0, 0.01, 0.0)  # exactly the tolerance
    assert not core.positions_in_sync(0.02, 0.0061, 0.01, 0.01)  # 1.1 mm off y


@pytest.mark.parametrize("tolerance_m", [0.0, -1e-3, float("nan")])
def test_a_tolerance_that_is_not_positive_is_refused(tolerance_m: float) -> None:
    with pytest.raises(ValueError, match="sync_tolerance_m"):
        SupervisionCore((1.0, 1.0), tolerance_m, 0.03, 3)


def test_both_sides_use_the_one_core_guard_and_transition() -> None:
    from haptic.master import supervisor as master_supervisor
    from haptic.master.tool_guard import ToolInputGuard
    from haptic.slave_sim import supervisor as slave_supervisor
    from haptic.slave_sim.input_guard import InputGuard

    assert master_supervisor.Transition is slave_supervisor.Transition is Transition
    assert issubclass(master_supervisor.MasterSupervisor, SupervisionCore)
    assert issubclass(slave_supervisor.SlaveSupervisor, SupervisionCore)
    assert issubclass(ToolInputGuard, peer_guard.PeerGuard)
    assert issubclass(InputGuard, peer_guard.PeerGuard)
    assert {t.value for t in Transition} == {"none", "activate", "resume", "hold", "stop"}
    assert supervision.FORCES_ENABLED & supervision.STOPPING == 0
