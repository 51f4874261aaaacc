"""The receive path's limits at the value: staleness and clock skew at their thresholds, ties
in send time and sequence, the counts each drop adds, and the statistics' exact figures."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from haptic.common.wire.injection import InjectionConfig
from haptic.common.wire.messages import KIND_HANDLE, Flags, HandleState, encode
from haptic.common.wire.receive import ReceivePath

MS = 1_000_000
T0 = 1_700_000_000_000_000_000
STALE_S = 0.05


def handle(seq: int, send_ns: int, epoch: int = 1) -> bytes:
    return encode(HandleState(epoch, seq, send_ns, Flags(0), (1.0, -1.0), (0.01, 0.02)))


def path(stale_s: float = STALE_S) -> ReceivePath:
    return ReceivePath(KIND_HANDLE, InjectionConfig(), np.random.default_rng(0), stale_s)


@pytest.mark.parametrize("stale_ms", [50, 1000])
def test_a_message_exactly_stale_after_old_is_delivered_one_ns_more_is_dropped(stale_ms) -> None:
    p = path(stale_ms / 1e3)
    p.accept(handle(0, T0), T0 + stale_ms * MS)
    assert p.release(T0 + stale_ms * MS) is not None
    p.accept(handle(1, T0 + MS), T0 + MS + stale_ms * MS + 1)
    assert p.release(T0 + 2 * stale_ms * MS) is None
    stats = p.stats()
    assert stats.dropped["stale"] == 1 and stats.delivered == 1
    assert stats.network_lost == 0  # a stale message is sent, not lost


def test_clock_skew_counts_beyond_one_ms_into_the_future() -> None:
    p = path()
    p.accept(handle(0, T0 + MS), T0)  # 1 ms early: tolerated
    p.accept(handle(1, T0 + 2 * MS + 1), T0 + MS)  # 1 ms + 1 ns early: skew
    p.accept(handle(2, T0 + 2 * MS), T0 + 3 * MS)  # late, as normal
    stats = p.stats()
    assert stats.clock_skew == 1
    assert stats.dropped["stale"] == 0


def test_a_duplicate_is_out_of_order_once_and_never_undoes_a_loss() -> None:
    p = path()
    p.accept(handle(0, T0), T0)
    p.accept(handle(2, T0 + 2 * MS), T0 + 2 * MS)  # seq 1 missing: one lost
    assert p.stats().network_lost == 1
    p.accept(handle(2, T0 + 2 * MS), T0 + 2 * MS)  # a duplicate of the highest
    stats = p.stats()
    assert (stats.reordered, stats.dropped["out_of_order"], stats.network_lost) == (1, 1, 1)
    p.accept(handle(1, T0 + MS), T0 + 3 * MS)  # the missing one, late: fills the gap
    stats = p.stats()
    assert (stats.reordered, stats.network_lost) == (2, 0)
    p.accept(handle(1, T0 + MS), T0 + 3 * MS)  # once more: no loss left to undo
    assert p.stats().network_lost == 0
    assert p.stats().reordered == 3


def test_a_new_epoch_at_the_same_send_time_is_a_late_message_of_the_old_one() -> None:
    p = path()
    p.accept(handle(5, T0 + 10 * MS, epoch=1), T0 + 10 * MS)
    p.accept(handle(0, T0 + 10 * MS, epoch=2), T0 + 10 * MS)  # same send time: not newer
    stats = p.stats()
    assert (stats.peer_restarts, stats.reordered, stats.dropped["out_of_order"]) == (0, 1, 1)
    p.accept(handle(0, T0 + 10 * MS + 1, epoch=2), T0 + 11 * MS)  # 1 ns later: a restart
    stats = p.stats()
    assert (stats.peer_restarts, stats.reordered) == (1, 1)
    assert p.release(T0 + 12 * MS).epoch == 2  # the old epoch's pending one was cleared
    # expected: the old epoch's one message (seq 5..5) and the new epoch's one (seq 0..0)
    stats = p.stats()
    assert (stats.expected, stats.delivered) == (2, 1)


def test_expected_counts_each_epochs_span_of_sequence_numbers() -> None:
    p = path()
    for seq in (3, 4, 6):
        p.accept(handle(seq, T0 + seq * MS, epoch=7), T0 + seq * MS)
    p.release(T0 + 10 * MS)
    stats = p.stats()
    assert stats.expected == 4  # seq 3..6
    assert stats.delivered == 3 and stats.network_lost == 1
    assert stats.loss_ratio == pytest.approx(0.25, rel=1e-12)
    assert stats.network_loss_ratio == pytest.approx(0.25, rel=1e-12)
    for seq in (10, 11):
        p.accept(handle(seq, T0 + (20 + seq) * MS, epoch=8), T0 + (20 + seq) * MS)
    p.release(T0 + 40 * MS)
    stats = p.stats()
    assert stats.expected == 4 + 2 and stats.peer_restarts == 1


def test_one_delivered_message_gives_finite_statistics() -> None:
    p = path()
    assert math.isnan(p.stats().loss_ratio) and p.stats().expected == 0
    p.accept(handle(0, T0), T0 + 2 * MS)
    assert p.release(T0 + 3 * MS) is not None
    stats = p.stats()
    assert stats.expected == 1 and stats.loss_ratio == 0.0 and stats.network_loss_ratio == 0.0
    assert stats.one_way_delay_max_s == pytest.approx(2e-3, rel=0.05)
    assert stats.age_at_use_p50_s == pytest.approx(3e-3, rel=0.05)


def test_release_keeps_only_the_newest_and_counts_the_superseded() -> None:
    p = path()
    for seq in range(4):
        p.accept(handle(seq, T0 + seq * MS), T0 + seq * MS)
    assert p.release(T0 + 1 * MS).seq == 1
    assert p.release(T0 + 10 * MS).seq == 3
    stats = p.stats()
    assert (stats.delivered, stats.superseded) == (4, 2)
    assert p.last_delivery_ns == T0 + 3 * MS


def test_release_hands_over_every_delivered_message_in_order() -> None:
    """The slave steps each delivered sample with its own force (slave_sim/pacing.py): the
    superseded ones are kept in ``released``, in order, the returned newest last."""
    p = path()
    for seq in (0, 2, 1, 3):  # 1 arrives after 2: dropped out of order
        p.accept(handle(seq, T0 + seq * MS), T0 + 3 * MS)
    newest = p.release(T0 + 10 * MS)
    assert [m.seq for m in p.released] == [0, 2, 3] and p.released[-1] is newest
    assert p.release(T0 + 11 * MS) is None and p.released == []


def test_delay_percentiles_are_the_50th_and_99th() -> None:
    p = path(stale_s=1.0)
    delays_ms = [1] * 90 + [20] * 9 + [100]
    for seq, delay in enumerate(delays_ms):
        send = T0 + seq * 200 * MS
        p.accept(handle(seq, send), send + delay * MS)
        p.release(send + delay * MS)
    stats = p.stats()
    assert stats.one_way_delay_p50_s == pytest.approx(1e-3, rel=0.1)
    assert stats.one_way_delay_p99_s == pytest.approx(20e-3, rel=0.1)
    assert stats.one_way_delay_max_s == pytest.approx(0.1, rel=0.1)
    assert stats.age_at_use_p99_s == pytest.approx(20e-3, rel=0.1)


def test_stats_are_frozen() -> None:
    stats = path().stats()
    with pytest.raises(dataclasses.FrozenInstanceError):
        stats.delivered = 3


def test_release_after_reordering_counts_each_late_one_and_goes_on_to_the_newest() -> None:
    """Jitter without order preservation: a message due after a newer one was handed over
    is dropped and counted once; the release still reaches the newest due message."""
    receive = ReceivePath(KIND_HANDLE, InjectionConfig(jitter_s=0.01, preserve_order=False),
                          np.random.default_rng(1), STALE_S)
    for seq in range(300):
        receive.accept(handle(seq, T0 + seq * 100_000), T0 + seq * 100_000)
    last = None
    for step in range(1200):
        now_ns = T0 + step * 50_000
        message = receive.release(now_ns)
        last = message or last
        assert receive.release(now_ns) is None  # everything due was handled at once
    stats = receive.stats()
    assert stats.reordered == stats.dropped["out_of_order"] > 0
    assert receive.pending == 0 and stats.delivered + stats.reordered == 300
    assert last is not None and last.seq == 299  # the newest of all was handed over last


def test_a_stale_duplicate_changes_no_loss_count() -> None:
    p = path()
    p.accept(handle(0, T0), T0)
    p.accept(handle(1, T0 + MS), T0 + MS)
    p.accept(handle(1, T0 + MS), T0 + MS + 60 * MS)  # the same message again, now stale
    stats = p.stats()
    assert stats.network_lost == 0 and stats.dropped["stale"] == 1


def test_a_single_stale_message_is_a_total_loss() -> None:
    p = path()
    p.accept(handle(0, T0), T0 + 60 * MS)
    stats = p.stats()
    assert stats.expected == 1 and stats.delivered == 0
    assert stats.loss_ratio == 1.0 and stats.network_loss_ratio == 0.0


def test_the_median_is_the_50th_percentile() -> None:
    p = path(stale_s=1.0)
    delays_ms = [1] * 50 + [20] * 50
    for seq, delay in enumerate(delays_ms):
        send = T0 + seq * 200 * MS
        p.accept(handle(seq, send), send + delay * MS)
        p.release(send + delay * MS)
    stats = p.stats()
    assert stats.one_way_delay_p50_s == pytest.approx(1e-3, rel=0.1)
    assert stats.age_at_use_p50_s == pytest.approx(1e-3, rel=0.1)


# One message must not be able to spoil the order for the messages after it (found by fuzzing
# the receive path): a send time far ahead of this host's clock made every later restart look
# old, a sequence number near 2**63 made every later message out of order, and replays of old
# sequence numbers took losses back.


def test_a_message_from_beyond_stale_after_ahead_is_implausible_and_takes_no_order() -> None:
    p = path()
    p.accept(handle(0, T0), T0)
    p.accept(handle(1, T0 + 50 * MS + MS), T0 + MS)  # exactly stale_after_s ahead: taken
    p.accept(handle(2, T0 + 51 * MS + 2 * MS), T0 + 2 * MS)  # 1 ns more: dropped
    p.accept(handle(3, 2**63 - 1), T0 + 3 * MS)  # the far future
    stats = p.stats()
    assert stats.dropped["implausible"] == 2 and stats.clock_skew == 3
    assert p.release(T0 + 3 * MS).seq == 1
    # the peer restarts: its new epoch is taken, as if the far-future message never came
    p.accept(handle(0, T0 + 60 * MS, epoch=2), T0 + 60 * MS)
    assert p.stats().peer_restarts == 1
    assert p.release(T0 + 60 * MS).epoch == 2


def test_a_sequence_number_beyond_the_sender_s_rate_is_implausible() -> None:
    p = path()
    for seq in range(3):
        p.accept(handle(seq, T0 + seq * MS), T0 + seq * MS)
    p.accept(handle(2**63 - 1, T0 + 3 * MS), T0 + 3 * MS)
    p.accept(handle(10**6, T0 - 60 * MS), T0 + 3 * MS)  # stale too: still no order taken
    # 1 ms after the newest, 20 kHz allows 20 more, plus the slack of 64
    p.accept(handle(2 + 64 + 20 + 1, T0 + 3 * MS), T0 + 3 * MS)
    stats = p.stats()
    assert stats.dropped["implausible"] == 3 and stats.network_lost == 0
    for seq in range(3, 10):
        p.accept(handle(seq, T0 + seq * MS), T0 + seq * MS)
    stats = p.stats()
    assert stats.dropped["out_of_order"] == 0 and stats.network_lost == 0
    assert p.release(T0 + 9 * MS).seq == 9
    p.accept(handle(9 + 64 + 20, T0 + 10 * MS), T0 + 10 * MS)  # the most it allows: taken
    assert p.stats().network_lost == 64 + 20 - 1


def test_replays_never_take_a_loss_back_and_a_late_one_takes_it_back_once() -> None:
    p = path()
    p.accept(handle(0, T0), T0)
    p.accept(handle(5, T0 + 5 * MS), T0 + 5 * MS)  # 1..4 lost
    for _ in range(4):
        p.accept(handle(0, T0), T0 + 5 * MS)  # replays of a message already received
    assert p.stats().network_lost == 4
    p.accept(handle(3, T0 + 3 * MS), T0 + 6 * MS)  # a late one: one loss less
    p.accept(handle(3, T0 + 3 * MS), T0 + 6 * MS)  # and again: no change
    stats = p.stats()
    assert stats.network_lost == 3 and stats.reordered == 6
    # beyond the remembered window nothing is taken back
    p.accept(handle(5 + 2000, T0 + 200 * MS), T0 + 200 * MS)
    lost = p.stats().network_lost
    p.accept(handle(4, T0 + 4 * MS), T0 + 200 * MS)
    assert p.stats().network_lost == lost


def test_what_waits_when_the_peer_restarts_is_counted_as_dropped() -> None:
    injection = InjectionConfig(delay_s=0.01)
    p = ReceivePath(KIND_HANDLE, injection, np.random.default_rng(0), STALE_S)
    for seq in range(3):
        p.accept(handle(seq, T0 + seq * MS), T0 + seq * MS)
    assert p.pending == 3
    p.accept(handle(0, T0 + 3 * MS, epoch=2), T0 + 3 * MS)
    stats = p.stats()
    assert stats.peer_restarts == 1 and stats.dropped["peer_restart"] == 3
    assert stats.received == 4 and p.pending == 1
    p.pin_epoch(3)  # an authenticated re-pairing drops what waits, too
    assert p.stats().dropped["peer_restart"] == 4 and p.pending == 0


@pytest.mark.parametrize("stale_ns", [130_000, 2_070_000])
def test_stale_after_is_the_nearest_ns_not_one_short(stale_ns) -> None:
    """Limits whose seconds are no exact binary fraction (0.00013 s * 1e9 is 129999.99...):
    a message exactly ``stale_after_s`` old, or sent exactly that far ahead, is taken."""
    p = path(stale_ns / 1e9)
    p.accept(handle(0, T0), T0 + stale_ns)
    assert p.release(T0 + stale_ns) is not None
    p.accept(handle(1, T0 + MS + stale_ns), T0 + MS)
    p.accept(handle(2, T0 + 2 * MS), T0 + 2 * MS + stale_ns + 1)
    stats = p.stats()
    assert stats.dropped["implausible"] == 0 and stats.dropped["stale"] == 1
    assert p.release(T0 + 2 * MS).seq == 1
