"""The receive path of the link, without the network: validate, order, inject, deliver, count.

:class:`ReceivePath` takes raw payloads with their arrival time and hands the control loop the
newest message whose (injected) delivery time has come. It is pure bookkeeping, so the fuzz
tests and the link share it. All times are ``CLOCK_REALTIME`` ns (:func:`time.time_ns`), the
clock of the messages' ``send_time_ns``.

Per received payload, in order:

1. decode (:func:`haptic.common.wire.messages.decode`): ``malformed``, ``unknown_version``,
   ``wrong_kind``, ``non_finite`` drops;
2. ``implausible``: sent more than ``stale_after_s`` ahead of this host's clock (no sender's
   clock may be that far ahead: the staleness check already needs the hosts' clocks within
   that much the other way), so a single message stamped in the far future cannot make every
   later one look old;
3. a new sender ``epoch`` with a newer send time means the peer restarted: ordering starts
   again (``peer_restarts``; what was waiting for its delivery time is dropped
   ``peer_restart``); an old epoch's late message is ``out_of_order``;
4. ``implausible`` too: a sequence number further above the highest than the sender could
   have sent since (:data:`MAX_SEND_RATE_HZ` over the send times' advance, plus
   :data:`SEQUENCE_SLACK`), so one message cannot make every later one ``out_of_order``;
5. ``stale``: older at arrival than ``stale_after_s`` plus the largest injected delay (sent,
   so not lost: one that fills a gap counted as lost takes it back, as in 6);
6. ``out_of_order``: a sequence number not above the highest already accepted (a duplicate or
   a reordered message; also counted in ``reordered``); one that fills a gap counted as lost
   takes it back from ``network_lost``, once: the last :data:`SEQUENCE_WINDOW` sequence
   numbers are remembered, so a duplicate or a replay never does (nor one below the epoch's
   first sequence number, which no count included);
7. ``injected_loss``: the loss models drop it;
8. it waits in a queue ordered by delivery time, ``max(arrival, send + delay + jitter)``.

:meth:`ReceivePath.release` pops every message whose delivery time has come; one older than a
message already delivered is dropped ``out_of_order`` (jitter without ``preserve_order`` can
reorder); the newest is returned and the others count as ``superseded`` (delivered before the
newest in the same release). :attr:`ReceivePath.released` holds every message of the last
release in delivery order, the newest last: a loop that must use every sample (the slave's
pacing, slave_sim/pacing.py) takes them from there.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from haptic.common.records.histogram import LogHistogram
from haptic.common.wire.injection import Impairment, InjectionConfig
from haptic.common.wire.messages import DecodeError, DropReason, Message, decode

_CLOCK_SKEW_TOLERANCE_NS = 1_000_000
#: The most messages a second a sender may send (the programs send one a tick: 1852 Hz at the
#: paper's Ts, 4 kHz at the fastest period tested), with room to spare.
MAX_SEND_RATE_HZ = 20_000.0
#: Sequence numbers a message may skip beyond what that rate allows (a burst, a clock step).
SEQUENCE_SLACK = 64
#: How many sequence numbers below the highest are remembered as received or not.
SEQUENCE_WINDOW = 1024
_WINDOW_MASK = (1 << SEQUENCE_WINDOW) - 1
_MAX_PAYLOAD_BYTES = 1024
_MALFORMED = DropReason.MALFORMED.value


@dataclass(frozen=True)
class LinkStats:
    """What the receiving link really delivered. Delays in s, ratios in 0..1.

    ``one_way_delay_*``: send time to delivery time (arrival, or the injected target if later):
    the delay the link imposed, injection included. ``age_at_use_*``: send time to the poll
    that handed the message to the loop (adds the wait for the loop's next tick).
    ``loss_ratio``: 1 - delivered / messages sent (from the sequence numbers);
    ``network_loss_ratio``: the part missing at arrival, before injection and validation.
    """

    received: int
    delivered: int
    superseded: int
    expected: int
    dropped: dict[str, int]
    reordered: int
    network_lost: int
    peer_restarts: int
    clock_skew: int
    loss_ratio: float
    network_loss_ratio: float
    one_way_delay_p50_s: float
    one_way_delay_p99_s: float
    one_way_delay_max_s: float
    age_at_use_p50_s: float
    age_at_use_p99_s: float

    def as_summary(self) -> dict[str, object]:
        """The summary keys (``link_*`` and ``loss_ratio``) for the run's JSON summary."""
        return {
            "link_one_way_delay_p50_s": self.one_way_delay_p50_s,
            "link_one_way_delay_p99_s": self.one_way_delay_p99_s,
            "link_one_way_delay_max_s": self.one_way_delay_max_s,
            "link_age_at_use_p50_s": self.age_at_use_p50_s,
            "link_age_at_use_p99_s": self.age_at_use_p99_s,
            "loss_ratio": self.loss_ratio,
            "link_network_loss_ratio": self.network_loss_ratio,
            "link_received": self.received,
            "link_delivered": self.delivered,
            "link_superseded": self.superseded,
            "link_expected": self.expected,
            "link_dropped": dict(self.dropped),
            "link_reordered": self.reordered,
            "link_peer_restarts": self.peer_restarts,
            "link_clock_skew": self.clock_skew,
        }


@dataclass
class _Sequence:
    """Sequence bookkeeping of one sender epoch."""

    epoch: int
    first_seq: int
    highest_seq: int
    highest_send_ns: int
    delivered_seq: int = -1
    #: bit i set: sequence number ``highest_seq - i`` was received, or lies below
    #: ``first_seq`` (never counted lost, so never taken back) (i < SEQUENCE_WINDOW)
    received_bits: int = _WINDOW_MASK


@dataclass
class _Counters:
    received: int = 0
    delivered: int = 0
    superseded: int = 0
    reordered: int = 0
    network_lost: int = 0
    peer_restarts: int = 0
    clock_skew: int = 0
    expected_closed: int = 0
    dropped: dict[str, int] = field(default_factory=lambda: {r.value: 0 for r in DropReason})


class ReceivePath:
    """Validation, ordering, injection and statistics for one direction of the link.

    ``expected_kind`` is the message kind this side receives; ``stale_after_s`` the largest age
    (s) a message may have at arrival beyond the injected delay; ``rng`` feeds the injection;
    ``decoder(payload, expected_kind)`` parses and validates a payload, raising only
    :class:`~haptic.common.wire.messages.DecodeError` (default: the programs' messages; the
    lane laws' have their own schema, common/wire/law_messages.py).
    """

    def __init__(
        self,
        expected_kind: int,
        injection: InjectionConfig,
        rng: np.random.Generator,
        stale_after_s: float,
        decoder: Callable[[bytes, int], Message] = decode,
    ) -> None:
        self.expected_kind = expected_kind
        self._decode = decoder
        self.injection = injection
        self._impairment = Impairment(injection, rng)
        self._inject = injection.active
        # to the nearest ns: int() would cut 0.00013 s to 129999 ns
        self._stale_ns = round((stale_after_s + injection.max_extra_delay_s) * 1e9)
        self._future_ns = round(stale_after_s * 1e9)
        self._pending: list[tuple[int, int, Message]] = []
        self._seq: _Sequence | None = None
        self._n = _Counters()
        self._delay = LogHistogram()
        self._age = LogHistogram()
        self.last_delivered: Message | None = None
        self.last_delivery_ns: int | None = None
        #: every message the last :meth:`release` delivered, in order (the newest last); the
        #: list is reused: read it before the next release
        self.released: list[Message] = []
        self._pinned_epoch: int | None = None
        self._epochs_pinned = False
        self.last_unknown_version: int | None = None
        """The version of the latest message dropped ``unknown_version`` (a mismatched peer)."""

    def _drop(self, reason: DropReason) -> None:
        self._n.dropped[reason.value] += 1

    def pin_epoch(self, epoch: int) -> None:
        """Authenticated link: accept messages of ``epoch`` only, from now on; a new epoch
        comes only from here (an authenticated re-pairing), never from a newer send time.
        Pinning another epoch than the current one is a peer restart."""
        self._epochs_pinned = True
        if self._pinned_epoch == epoch:
            return
        self._pinned_epoch = epoch
        seq_state = self._seq
        if seq_state is not None and seq_state.epoch != epoch:
            self._restart(seq_state)
            self._seq = None

    def _restart(self, seq_state: _Sequence) -> None:
        """The peer restarted: close the old epoch's counts and drop what waits undelivered."""
        n = self._n
        n.peer_restarts += 1
        n.expected_closed += seq_state.highest_seq - seq_state.first_seq + 1
        n.dropped[DropReason.PEER_RESTART.value] += len(self._pending)
        self._pending.clear()

    def drop(self, reason: DropReason) -> None:
        """Count one received payload dropped before :meth:`accept` (its tag, its pairing)."""
        self._n.received += 1
        self._drop(reason)

    def rejects_at_once(self, payload: bytes) -> bool:
        """The flood filter, before anything costly (the arrival stamp, msgpack): a payload
        that cannot be a message (every message is a msgpack array of 6 to 31 items: a
        fixarray up to 15, an array16 header ``dc 00 nn`` above; at most 1024 bytes) is
        counted (received, ``malformed``) and True is returned; False: hand it to
        :meth:`accept`."""
        if payload and len(payload) <= _MAX_PAYLOAD_BYTES:
            first = payload[0]
            if 0x96 <= first <= 0x9F or (first == 0xDC and len(payload) > 3
                                         and payload[1] == 0 and 16 <= payload[2] <= 31):
                return False
        self._n.received += 1
        self._n.dropped[_MALFORMED] += 1
        return True

    def accept(self, payload: bytes, arrival_ns: int) -> None:
        """Take one received payload that arrived at ``arrival_ns``. Never raises."""
        n = self._n
        n.received += 1
        try:
            message = self._decode(payload, self.expected_kind)
        except DecodeError as error:
            self._drop(error.reason)
            if error.reason is DropReason.UNKNOWN_VERSION:
                self.last_unknown_version = error.version
            return
        send_ns = message.send_time_ns
        if self._epochs_pinned and message.epoch != self._pinned_epoch:
            self._drop(DropReason.UNPAIRED)  # a new epoch only through an explicit pairing
            return
        age_ns = arrival_ns - send_ns
        if age_ns < -_CLOCK_SKEW_TOLERANCE_NS:
            n.clock_skew += 1
            if age_ns < -self._future_ns:
                self._drop(DropReason.IMPLAUSIBLE)  # from the future: no order state taken
                return
        seq_state = self._seq
        if seq_state is None or message.epoch != seq_state.epoch:
            if seq_state is not None and send_ns <= seq_state.highest_send_ns:
                n.reordered += 1
                self._drop(DropReason.OUT_OF_ORDER)  # a late message of an older epoch
                return
            if seq_state is not None:
                self._restart(seq_state)
            seq_state = self._seq = _Sequence(message.epoch, message.seq, message.seq - 1, 0)
        elif message.seq - seq_state.highest_seq > SEQUENCE_SLACK + MAX_SEND_RATE_HZ * max(
                send_ns - seq_state.highest_send_ns, 0) * 1e-9:
            self._drop(DropReason.IMPLAUSIBLE)  # further ahead than the sender could send
            return
        if age_ns > self._stale_ns:
            self._note_sequence(seq_state, message.seq, send_ns)
            self._drop(DropReason.STALE)
            return
        if message.seq <= seq_state.highest_seq:
            self._arrived_late(seq_state, message.seq)
            n.reordered += 1
            self._drop(DropReason.OUT_OF_ORDER)
            return
        self._note_sequence(seq_state, message.seq, send_ns)
        if self._inject:
            if self._impairment.lost():
                self._drop(DropReason.INJECTED_LOSS)
                return
            target_ns = self._impairment.target_ns(send_ns)
            delivery_ns = arrival_ns if arrival_ns > target_ns else target_ns
        else:
            delivery_ns = arrival_ns
        heapq.heappush(self._pending, (delivery_ns, message.seq, message))

    def _note_sequence(self, seq_state: _Sequence, seq: int, send_ns: int) -> None:
        """A message of sequence number ``seq`` was received (delivered or stale)."""
        if seq > seq_state.highest_seq:
            skipped = seq - seq_state.highest_seq
            self._n.network_lost += skipped - 1
            seq_state.highest_seq = seq
            seq_state.received_bits = (seq_state.received_bits << skipped | 1) & _WINDOW_MASK \
                if skipped < SEQUENCE_WINDOW else 1
        else:
            self._arrived_late(seq_state, seq)
        if send_ns > seq_state.highest_send_ns:
            seq_state.highest_send_ns = send_ns

    def _arrived_late(self, seq_state: _Sequence, seq: int) -> None:
        """A message of sequence number ``seq``, not above the highest, was received (in time
        or stale): one that fills a gap counted as lost takes it back, once."""
        behind = seq_state.highest_seq - seq
        if behind < SEQUENCE_WINDOW and not seq_state.received_bits >> behind & 1:
            seq_state.received_bits |= 1 << behind
            self._n.network_lost -= 1

    def release(self, now_ns: int) -> Message | None:
        """The newest message whose delivery time is at or before ``now_ns``, or ``None``."""
        pending = self._pending
        released = self.released
        if released:
            released.clear()
        if not pending or pending[0][0] > now_ns:
            return None
        seq_state = self._seq
        assert seq_state is not None
        newest: Message | None = None
        newest_delivery_ns = 0
        while pending and pending[0][0] <= now_ns:
            delivery_ns, seq, message = heapq.heappop(pending)
            if seq <= seq_state.delivered_seq:
                self._n.reordered += 1
                self._drop(DropReason.OUT_OF_ORDER)
                continue
            seq_state.delivered_seq = seq
            self._n.delivered += 1
            self._delay.record((delivery_ns - message.send_time_ns) * 1e-9)
            if newest is not None:
                self._n.superseded += 1
            newest = message
            released.append(message)
            newest_delivery_ns = delivery_ns
        if newest is not None:
            self._age.record((now_ns - newest.send_time_ns) * 1e-9)
            self.last_delivered = newest
            self.last_delivery_ns = newest_delivery_ns
        return newest

    @property
    def pending(self) -> int:
        """Messages accepted and waiting for their delivery time."""
        return len(self._pending)

    def stats(self) -> LinkStats:
        """A snapshot of the counters and delay percentiles."""
        n = self._n
        expected = n.expected_closed
        if self._seq is not None:
            expected += self._seq.highest_seq - self._seq.first_seq + 1
        expected -= len(self._pending)  # still in flight: neither delivered nor lost yet
        loss = 1.0 - n.delivered / expected if expected > 0 else math.nan
        network_loss = n.network_lost / expected if expected > 0 else math.nan
        delay_p50, delay_p99 = self._delay.percentiles((50.0, 99.0))
        age_p50, age_p99 = self._age.percentiles((50.0, 99.0))
        return LinkStats(
            received=n.received,
            delivered=n.delivered,
            superseded=n.superseded,
            expected=expected,
            dropped=dict(n.dropped),
            reordered=n.reordered,
            network_lost=n.network_lost,
            peer_restarts=n.peer_restarts,
            clock_skew=n.clock_skew,
            loss_ratio=max(0.0, loss) if expected > 0 else math.nan,
            network_loss_ratio=network_loss,
            one_way_delay_p50_s=delay_p50,
            one_way_delay_p99_s=delay_p99,
            one_way_delay_max_s=self._delay.max_s if self._delay.count else math.nan,
            age_at_use_p50_s=age_p50,
            age_at_use_p99_s=age_p99,
        )
