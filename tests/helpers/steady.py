"""The check both sides' supervisor tests make of ``steady()``, the rule the lockstep's quiet
lanes rely on (master/quiet_kernel.py, slave_sim/quiet_kernel.py)."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

from haptic.common.runtime.watchdog import WatchdogState


def assert_steady_needs_each(steady_supervisor: Callable[[], Any],
                             conditions: Iterable[tuple[str, object]]) -> None:
    """``steady_supervisor()`` makes a new steady supervisor; each ``(attribute, value)`` set
    alone on one makes it not steady, and of the watchdog's states only ``ok`` is steady."""
    for name, value in conditions:
        supervisor = steady_supervisor()
        assert supervisor.steady(), name
        setattr(supervisor, name, value)
        assert not supervisor.steady(), name
    for state in WatchdogState:
        supervisor = steady_supervisor()
        supervisor.watchdog.state = state
        assert supervisor.steady() is (state is WatchdogState.OK), state
