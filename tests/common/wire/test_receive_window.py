"""The receive path's replay window and sequence plausibility at their edges: a gap taken back
exactly SEQUENCE_WINDOW - 1 behind and not SEQUENCE_WINDOW behind, a jump of exactly the
window, nothing taken back below an epoch's first message, stale late messages, the window's
bits, and the implausible-sequence and far-future limits to the unit."""

from __future__ import annotations

import numpy as np
import pytest

from haptic.common.wire.injection import InjectionConfig
from haptic.common.wire.messages import KIND_HANDLE, Flags, HandleState, encode
from haptic.common.wire.receive import SEQUENCE_WINDOW, ReceivePath

MS = 1_000_000
S = 1_000_000_000
T0 = 1_700_000_000_000_000_000
#: Sequence numbers start here: a sum mistaken for a difference lands outside the window.
BASE = 10_000


def handle(seq: int, send_ns: int, epoch: int = 1) -> bytes:
    return encode(HandleState(epoch, seq, send_ns, Flags(0), (1.0, -1.0), (0.01, 0.02)))


def path(stale_s: float = 1.0) -> ReceivePath:
    return ReceivePath(KIND_HANDLE, InjectionConfig(), np.random.default_rng(0), stale_s)


def late_arrival(send_ns: int, stale: bool) -> int:
    """An arrival time for a message sent at ``send_ns``: in time, or stale (stale_s 1.0)."""
    return send_ns + (2 * S if stale else MS)


@pytest.mark.parametrize("stale", [False, True], ids=["in_time", "stale"])
def test_a_late_message_1023_behind_takes_its_loss_back_1024_behind_does_not(stale) -> None:
    """Only the last 1024 sequence numbers are remembered: 1023 behind is, 1024 is not."""
    p = path()
    p.accept(handle(BASE, T0), T0)
    p.accept(handle(BASE + 1025, T0 + 60 * MS), T0 + 60 * MS)  # BASE+1 .. BASE+1024 lost
    assert p.stats().network_lost == 1024
    p.accept(handle(BASE + 1, T0 + MS), late_arrival(T0 + MS, stale))  # 1024 behind
    assert p.stats().network_lost == 1024
    p.accept(handle(BASE + 2, T0 + 2 * MS), late_arrival(T0 + 2 * MS, stale))  # 1023 behind
    assert p.stats().network_lost == 1023
    stats = p.stats()
    assert (stats.reordered, stats.dropped["out_of_order"], stats.dropped["stale"]) == (
        (0, 0, 2) if stale else (2, 2, 0))


def test_a_jump_of_exactly_the_window_remembers_only_the_new_highest() -> None:
    """A jump of 1024: the new highest counts as received, the 1023 between as lost."""
    p = path()
    p.accept(handle(BASE, T0), T0)
    p.accept(handle(BASE + 1024, T0 + 60 * MS), T0 + 60 * MS)
    assert p.stats().network_lost == 1023
    p.accept(handle(BASE + 1024, T0 + 60 * MS), T0 + 61 * MS)  # a duplicate of the highest
    assert p.stats().network_lost == 1023
    p.accept(handle(BASE, T0), T0 + 61 * MS)  # 1024 behind: forgotten, nothing to take back
    assert p.stats().network_lost == 1023
    p.accept(handle(BASE + 1, T0 + MS), T0 + 61 * MS)  # 1023 behind: a loss taken back
    p.accept(handle(BASE + 1, T0 + MS), T0 + 61 * MS)  # and only once
    stats = p.stats()
    assert (stats.network_lost, stats.reordered) == (1022, 4)


def test_a_jump_beyond_the_window_remembers_only_the_new_highest() -> None:
    """A jump of more than 1024: a duplicate of the new highest takes nothing back."""
    p = path()
    p.accept(handle(BASE, T0), T0)
    p.accept(handle(BASE + 5000, T0 + 300 * MS), T0 + 300 * MS)
    assert p.stats().network_lost == 4999
    p.accept(handle(BASE + 5000, T0 + 300 * MS), T0 + 301 * MS)
    p.accept(handle(BASE + 4999, T0 + 299 * MS), T0 + 301 * MS)  # 1 behind: taken back
    stats = p.stats()
    assert (stats.network_lost, stats.reordered) == (4998, 2)


@pytest.mark.parametrize("stale", [False, True], ids=["in_time", "stale"])
def test_a_message_below_the_epoch_s_first_takes_no_loss_back(stale) -> None:
    """Sequence numbers below an epoch's first were never counted lost: none is taken back."""
    p = path()
    p.accept(handle(BASE + 5, T0 + 5 * MS), T0 + 5 * MS)
    for seq in (BASE + 4, BASE + 3, BASE):
        p.accept(handle(seq, T0 + (seq - BASE) * MS), late_arrival(T0 + (seq - BASE) * MS, stale))
    assert p.stats().network_lost == 0
    p.accept(handle(BASE + 7, T0 + 7 * MS), T0 + 7 * MS)  # BASE+6 lost
    p.accept(handle(BASE + 6, T0 + 6 * MS), late_arrival(T0 + 6 * MS, stale))  # taken back
    assert p.release(T0 + 10 * MS).seq == BASE + 7
    stats = p.stats()
    assert (stats.network_lost, stats.network_loss_ratio, stats.expected) == (0, 0.0, 3)
    # after a peer restart the new epoch starts with nothing to take back either
    p.accept(handle(3, T0 + 20 * MS, epoch=2), T0 + 20 * MS)
    p.accept(handle(2, T0 + 19 * MS, epoch=2), late_arrival(T0 + 19 * MS, stale))
    assert (p.stats().peer_restarts, p.stats().network_lost) == (1, 0)


def test_a_stale_message_that_fills_a_gap_takes_the_loss_back_once() -> None:
    """A stale message was sent, not lost: a late one fills its gap once, like one in time."""
    p = path(stale_s=0.05)
    p.accept(handle(BASE, T0), T0)
    p.accept(handle(BASE + 3, T0 + 3 * MS), T0 + 3 * MS)  # BASE+1, BASE+2 lost
    assert p.stats().network_lost == 2
    p.accept(handle(BASE + 1, T0 + MS), T0 + 100 * MS)  # stale: one loss less
    assert p.stats().network_lost == 1
    p.accept(handle(BASE + 1, T0 + MS), T0 + 101 * MS)  # stale again: no change
    p.accept(handle(BASE + 1, T0 + 100 * MS), T0 + 101 * MS)  # its number in time: none
    assert p.stats().network_lost == 1
    p.accept(handle(BASE + 2, T0 + 2 * MS), T0 + 102 * MS)  # the other gap, stale
    stats = p.stats()
    assert (stats.network_lost, stats.dropped["stale"], stats.reordered) == (0, 3, 1)


def test_the_window_keeps_exactly_its_1024_bits() -> None:
    """The window's bitmap never holds a bit at or above 1024 (its memory stays bounded)."""
    assert SEQUENCE_WINDOW == 1024
    p = path()
    seq = BASE
    send = T0
    for step in [1] * 1100 + [3, 1000, 1023, 1024, 1025, 1500] + [1] * 1100:
        seq += step
        send += 100 * MS if step > 1 else 10_000
        p.accept(handle(seq, send), send)
        bits = p._seq.received_bits
        assert 0 <= bits < 1 << 1024
    assert bits == (1 << 1024) - 1  # 1100 in a row since the last gap: all 1024 received


def test_the_sequence_limit_after_one_second_is_slack_plus_the_rate_exactly() -> None:
    """1 s after the highest, 64 + 20000 further is plausible, one more is not."""
    p = path(stale_s=0.05)
    p.accept(handle(BASE, T0), T0)
    p.accept(handle(BASE + 64 + 20_000 + 1, T0 + S), T0 + S)
    assert p.stats().dropped["implausible"] == 1
    p.accept(handle(BASE + 64 + 20_000, T0 + S), T0 + S)
    stats = p.stats()
    assert (stats.dropped["implausible"], stats.network_lost) == (1, 64 + 20_000 - 1)


def test_the_sequence_limit_for_no_newer_send_time_is_the_slack_exactly() -> None:
    """Sent at or before the highest's send time: 64 further is plausible, 65 is not."""
    p = path(stale_s=0.05)
    p.accept(handle(BASE, T0 + 10 * MS), T0 + 10 * MS)
    p.accept(handle(BASE + 65, T0 + 10 * MS), T0 + 10 * MS)  # the same send time
    p.accept(handle(BASE + 65, T0 + 9 * MS), T0 + 10 * MS)  # an earlier one
    assert p.stats().dropped["implausible"] == 2
    p.accept(handle(BASE + 64, T0 + 9 * MS), T0 + 10 * MS)
    stats = p.stats()
    assert (stats.dropped["implausible"], stats.network_lost) == (2, 63)


def test_a_send_time_more_than_stale_after_ahead_is_implausible_to_the_ns() -> None:
    """At stale_after_s = 1 s: a send time exactly 1 s ahead is taken, 1 s + 1 ns is not."""
    p = path(stale_s=1.0)
    p.accept(handle(BASE, T0), T0)
    p.accept(handle(BASE + 1, T0 + MS + S), T0 + MS)  # exactly 1 s ahead
    p.accept(handle(BASE + 2, T0 + 2 * MS + S + 1), T0 + 2 * MS)  # 1 ns more
    stats = p.stats()
    assert (stats.dropped["implausible"], stats.clock_skew) == (1, 2)
    assert p.release(T0 + 2 * MS).seq == BASE + 1
