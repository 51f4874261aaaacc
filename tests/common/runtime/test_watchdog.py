"""The peer watchdog's state machine and the resync protocol."""

from __future__ import annotations

import pytest

from haptic.common.runtime.watchdog import PeerWatchdog, WatchdogState

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


# --- the limits pinned: just under, at and just over the age, in every state ---------------


@pytest.mark.parametrize("age", [0.03, 0.05, 0.3])
def test_ok_trips_only_beyond_the_age(age):
    """Silence up to and including ``max_age_s`` is tolerated; a nanosecond more trips."""
    wd = PeerWatchdog(age, resync_messages=1)
    wd.update(0.0, True, 0.0)
    assert wd.state is WatchdogState.OK
    wd.update(0.5, False, age * (1.0 - 1e-9))
    wd.update(0.6, False, age)
    assert wd.state is WatchdogState.OK and wd.trips == 0 and wd.forces_enabled
    wd.update(0.7, False, age + 1e-9)
    assert wd.state is WatchdogState.TRIPPED and wd.trips == 1 and not wd.forces_enabled
    event = wd.events[-1]
    assert (event.time_s, event.kind) == (0.7, "trip")
    assert event.reason == (f"no fresh message for {(age + 1e-9) * 1e3:.1f} ms "
                            f"(max {age * 1e3:.1f} ms)")
    assert wd.fresh_in_row == 0


def test_a_fresh_message_does_not_excuse_a_silence_beyond_the_age():
    """The silence is what counts: a message delivered this tick after a long gap still
    trips (the caller measures the gap before the delivery)."""
    wd = PeerWatchdog(AGE, resync_messages=1)
    wd.update(0.0, True, 0.0)
    wd.update(0.1, True, AGE + 1e-6)
    assert wd.state is WatchdogState.TRIPPED


def test_resync_count_survives_a_gap_at_the_age_and_restarts_beyond_it():
    wd = PeerWatchdog(AGE, resync_messages=4)
    feed(wd, 2, 0.0)
    assert wd.fresh_in_row == 2
    wd.update(0.01, False, AGE)  # exactly the age: not silent, nothing new
    assert wd.fresh_in_row == 2 and wd.state is WatchdogState.WAITING
    wd.update(0.02, True, AGE)  # fresh at exactly the age: counts on
    assert wd.fresh_in_row == 3
    wd.update(0.03, False, AGE + 1e-9)  # silent: the count restarts
    assert wd.fresh_in_row == 0 and wd.state is WatchdogState.WAITING
    wd.update(0.04, True, AGE + 1e-9)  # fresh after a silence: the first of a new row
    assert wd.fresh_in_row == 1
    feed(wd, 2, 0.05)
    assert wd.fresh_in_row == 3 and wd.state is WatchdogState.WAITING
    feed(wd, 1, 0.06)
    assert wd.state is WatchdogState.OK and wd.fresh_in_row == 4


@pytest.mark.parametrize("needed", [1, 2, 7])
def test_exactly_resync_messages_are_needed(needed):
    wd = PeerWatchdog(AGE, resync_messages=needed)
    feed(wd, needed - 1, 0.0)
    assert wd.state is WatchdogState.WAITING and wd.fresh_in_row == needed - 1
    wd.update(0.5, False, 0.001)  # a tick without a message neither counts nor resets
    assert wd.fresh_in_row == needed - 1
    feed(wd, 1, 0.6)
    assert wd.state is WatchdogState.OK
    assert wd.events[-1].reason == (f"{needed} fresh messages and positions in sync "
                                    "(after waiting)")


def test_after_a_trip_the_return_counts_as_the_first_message_of_the_resync():
    wd = PeerWatchdog(AGE, resync_messages=3)
    t = feed(wd, 3, 0.0)
    wd.update(t + 0.1, False, 0.1)
    assert wd.state is WatchdogState.TRIPPED
    wd.update(t + 0.2, False, 0.2)  # still silent: stays tripped, no new event
    wd.update(t + 0.21, True, 0.0, peer_alive=False)  # a message, but the token is gone
    assert wd.state is WatchdogState.TRIPPED and len(wd.events) == 2
    wd.update(t + 0.22, True, 0.0)
    assert wd.state is WatchdogState.RESYNCING and wd.fresh_in_row == 1
    feed(wd, 1, t + 0.23)
    assert wd.state is WatchdogState.RESYNCING and wd.fresh_in_row == 2
    feed(wd, 1, t + 0.24)
    assert wd.state is WatchdogState.OK
    assert wd.events[-1].reason == "3 fresh messages and positions in sync (after resyncing)"
    assert wd.trips == 1


def test_lost_liveliness_during_resync_restarts_the_count():
    wd = PeerWatchdog(AGE, resync_messages=3)
    feed(wd, 2, 0.0)
    wd.update(0.01, True, 0.001, peer_alive=False)
    assert wd.fresh_in_row == 0 and wd.state is WatchdogState.WAITING
    feed(wd, 2, 0.02)
    assert wd.state is WatchdogState.WAITING
    feed(wd, 1, 0.03)
    assert wd.state is WatchdogState.OK


def test_out_of_sync_holds_the_resync_however_many_messages():
    wd = PeerWatchdog(AGE, resync_messages=2)
    feed(wd, 50, 0.0, in_sync=False)
    assert wd.state is WatchdogState.WAITING and wd.fresh_in_row == 50
    wd.update(0.1, False, 0.001, in_sync=True)  # in sync on a tick without a message
    assert wd.state is WatchdogState.OK


def test_safe_state_and_events_as_dicts():
    wd = PeerWatchdog(AGE, resync_messages=1)
    assert wd.safe_state and not wd.forces_enabled
    wd.update(0.25, True, 0.0)
    assert not wd.safe_state
    assert wd.events[0].as_dict() == {"time_s": 0.25, "kind": "forces_enabled",
                                      "reason": "1 fresh messages and positions in sync "
                                      "(after waiting)"}


@pytest.mark.parametrize("age", [-0.01, float("nan")])
def test_invalid_ages(age):
    with pytest.raises(ValueError, match="max_age_s"):
        PeerWatchdog(age, 1)
    with pytest.raises(ValueError, match="resync_messages"):
        PeerWatchdog(0.03, -1)


@pytest.mark.parametrize("side", ["master", "slave"])
def test_both_sides_watch_with_the_shipped_30_ms(paper_config, side):
    """The age each program gives its watchdog: link.watchdog.max_message_age_s, 30 ms as
    shipped, the same on both sides."""
    from haptic.common.wire.link_config import link_config_from

    config = link_config_from(paper_config, side)
    assert config.max_message_age_s == 0.03
    assert config.resync_messages == 20


def test_events_are_immutable_records():
    import dataclasses

    wd = PeerWatchdog(AGE, resync_messages=1)
    wd.update(0.0, True, 0.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        wd.events[0].kind = "trip"


def test_the_peers_last_message_is_a_safe_state_but_not_a_trip():
    """An orderly end (the peer's message with Flags.STOPPING): safe state at once, one
    ``peer_ended`` event, no trip; its liveliness then going away adds nothing, and a new
    run of the peer resyncs as after a trip."""
    wd = PeerWatchdog(AGE, resync_messages=3)
    t = feed(wd, 3, 0.0)
    assert wd.forces_enabled
    assert wd.update(t, True, 0.0, peer_stopping=True) is WatchdogState.TRIPPED
    assert wd.safe_state and wd.trips == 0 and wd.peer_ends == 1
    assert wd.events[-1].kind == "peer_ended" and "ended its run" in wd.events[-1].reason
    wd.update(t + 0.001, False, 0.001, peer_alive=False)
    wd.update(t + 0.1, False, 0.1, peer_alive=False)
    assert wd.trips == 0 and wd.peer_ends == 1 and len(wd.events) == 2
    assert wd.peer_ended and wd.state_text() == "the peer ended its run"
    wd.update(t + 0.2, True, 0.0, peer_stopping=True)  # a second goodbye changes nothing
    assert wd.peer_ends == 1 and len(wd.events) == 2
    wd.update(t + 0.3, True, 0.0)
    assert wd.state is WatchdogState.RESYNCING and wd.events[-1].kind == "peer_returned"
    assert not wd.peer_ended and wd.state_text() == "watchdog resyncing"
    feed(wd, 2, t + 0.301)
    assert wd.forces_enabled and wd.trips == 0


@pytest.mark.parametrize("fed", [0, 1])
def test_a_peer_stopping_before_the_forces_came_on_restarts_the_count(fed):
    """Waiting or resyncing: the goodbye is no fresh message, the count starts again and the
    return is counted from its first message."""
    wd = PeerWatchdog(AGE, resync_messages=3)
    t = feed(wd, fed, 0.0)
    wd.update(t, True, 0.0, peer_stopping=True)
    assert wd.state is WatchdogState.TRIPPED and wd.fresh_in_row == 0
    assert wd.trips == 0 and wd.peer_ends == 1
    t = feed(wd, 3, t + 0.001)
    assert wd.forces_enabled


def test_a_trip_is_told_as_the_watchdogs_state():
    wd = PeerWatchdog(AGE, resync_messages=1)
    feed(wd, 1, 0.0)
    wd.update(0.1, False, 0.1)
    assert not wd.peer_ended and wd.state_text() == "watchdog tripped"
