"""The peer watchdog's state machine and the resync protocol."""

from __future__ import annotations

import pytest

from haptic.common.watchdog import PeerWatchdog, WatchdogState

AGE = 0.03


def feed(watchdog: PeerWatchdog, n: int, t0: float, in_sync: bool = True, dt: float = 0.001):
    for i in range(n):
        watchdog.update(t0 + i * dt, True, dt, in_sync)
    return t0 + n * dt


def test_starts_safe_and_enables_forces_after_resync():
    wd = PeerWatchdog(AGE, resync_messages=5)
    assert wd.state is WatchdogState.WAITING and not wd.forces_enabled
    feed(wd, 4, 0.0)
    assert not wd.forces_enabled
    feed(wd, 1, 0.004)
    assert wd.forces_enabled and wd.state is WatchdogState.OK
    assert wd.trips == 0
    assert wd.events[-1].kind == "forces_enabled"


def test_silence_trips_and_the_return_needs_resync_and_position_match():
    wd = PeerWatchdog(AGE, resync_messages=3)
    t = feed(wd, 3, 0.0)
    assert wd.forces_enabled
    wd.update(t + 0.02, False, 0.02)
    assert wd.forces_enabled  # 20 ms of silence is tolerated
    wd.update(t + 0.04, False, 0.04)
    assert wd.state is WatchdogState.TRIPPED and wd.safe_state and wd.trips == 1
    assert wd.events[-1].kind == "trip" and "40.0 ms" in wd.events[-1].reason
    wd.update(t + 0.05, False, 0.05)
    assert wd.trips == 1  # one trip per outage
    wd.update(t + 0.06, True, 0.0)
    assert wd.state is WatchdogState.RESYNCING and wd.events[-1].kind == "peer_returned"
    t = feed(wd, 5, t + 0.061, in_sync=False)
    assert wd.state is WatchdogState.RESYNCING  # enough messages, positions not matched
    wd.update(t, True, 0.001, in_sync=True)
    assert wd.forces_enabled
    assert [e.kind for e in wd.events] == [
        "forces_enabled", "trip", "peer_returned", "forces_enabled"
    ]


def test_a_gap_during_resync_restarts_the_count():
    wd = PeerWatchdog(AGE, resync_messages=5)
    feed(wd, 4, 0.0)
    wd.update(0.1, False, 0.05)  # silence longer than max age while resyncing
    assert wd.fresh_in_row == 0
    feed(wd, 4, 0.2)
    assert not wd.forces_enabled
    feed(wd, 1, 0.3)
    assert wd.forces_enabled


def test_lost_liveliness_trips_at_once():
    wd = PeerWatchdog(AGE, resync_messages=1)
    wd.update(0.0, True, 0.0)
    assert wd.forces_enabled
    wd.update(0.001, False, 0.001, peer_alive=False)
    assert wd.state is WatchdogState.TRIPPED
    assert "liveliness" in wd.events[-1].reason


def test_invalid_arguments():
    with pytest.raises(ValueError):
        PeerWatchdog(0.0, 1)
    with pytest.raises(ValueError):
        PeerWatchdog(0.03, 0)
