"""The receive path without a network: counting, ordering, injected delay and loss."""

from __future__ import annotations

import math

import msgpack
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from haptic.common.wire.injection import InjectionConfig
from haptic.common.wire.messages import (
    KIND_HANDLE,
    KIND_TOOL,
    SCHEMA_VERSION,
    DropReason,
    Flags,
    HandleState,
    encode,
)
from haptic.common.wire.receive import ReceivePath

MS = 1_000_000
T0 = 1_700_000_000_000_000_000  # a CLOCK_REALTIME-like origin, ns


def handle(seq: int, send_ns: int, epoch: int = 1) -> bytes:
    return encode(HandleState(epoch, seq, send_ns, Flags(0), (1.0, -1.0), (0.01, 0.02)))


def path(injection: InjectionConfig | None = None, seed: int = 0, stale_s: float = 0.05):
    return ReceivePath(
        KIND_HANDLE, injection or InjectionConfig(), np.random.default_rng(seed), stale_s
    )


# -- fuzzing: every bad payload is counted under the right reason ------------------------------

def _fields(seq: int) -> list:
    return [SCHEMA_VERSION, KIND_HANDLE, 1, seq, T0 + seq * MS, 0, 1.0, 2.0, 0.1, 0.2, 13.0,
            0.0, 1.0]


bad_value = st.sampled_from(["x", None, [1.0], b"\x00", {"a": 1}, True])


@st.composite
def bad_payload(draw, seq: int):
    """(payload, reason) with the reason known by construction."""
    fields = _fields(seq)
    kind = draw(st.sampled_from(
        ["random", "truncated", "version", "kind", "non_finite", "wrong_type", "extra"]
    ))
    if kind == "random":
        raw = draw(st.binary(min_size=0, max_size=40))
        # msgpack of anything other than a long list is malformed; prefix a nil so no random
        # draw can ever be a valid message
        return b"\xc0" + raw if raw else b"", DropReason.MALFORMED
    if kind == "truncated":
        cut = draw(st.integers(0, len(fields) - 1))
        return msgpack.packb(fields[:cut]), DropReason.MALFORMED
    if kind == "version":
        fields[0] = draw(st.integers(SCHEMA_VERSION + 1, 2**31)
                         | st.integers(-(2**31), SCHEMA_VERSION - 1))
        return msgpack.packb(fields), DropReason.UNKNOWN_VERSION
    if kind == "kind":
        fields[1] = draw(st.sampled_from([KIND_TOOL, 0, 3, 99]))
        return msgpack.packb(fields), DropReason.WRONG_KIND
    if kind == "non_finite":
        fields[draw(st.integers(6, 10))] = draw(st.sampled_from([math.nan, math.inf, -math.inf]))
        return msgpack.packb(fields), DropReason.NON_FINITE
    if kind == "wrong_type":
        fields[draw(st.integers(2, 10))] = draw(bad_value)
        return msgpack.packb(fields, use_bin_type=True), DropReason.MALFORMED
    fields.append(draw(st.floats()))
    return msgpack.packb(fields), DropReason.MALFORMED


@st.composite
def mixed_stream(draw):
    """A stream of valid messages (increasing seq) interleaved with bad payloads."""
    items = []
    for seq in range(draw(st.integers(1, 30))):
        if draw(st.booleans()):
            items.append((handle(seq, T0 + seq * MS), None))
        else:
            items.append(draw(bad_payload(seq)))
    return items


@settings(max_examples=200, deadline=None)
@given(mixed_stream())
def test_fuzzed_receive_path_counts_every_bad_message(items):
    receive = path(stale_s=3600.0)
    for i, (payload, _reason) in enumerate(items):
        receive.accept(payload, T0 + i * MS + MS // 10)
        receive.release(T0 + i * MS + MS // 5)
    stats = receive.stats()
    expected = {r.value: 0 for r in DropReason}
    for _payload, reason in items:
        if reason is not None:
            expected[reason.value] += 1
    assert stats.dropped == expected
    valid = sum(reason is None for _payload, reason in items)
    assert stats.received == len(items)
    assert stats.delivered == valid


@settings(max_examples=200, deadline=None)
@given(st.lists(st.binary(max_size=64), max_size=50))
def test_random_bytes_never_escape_and_are_all_counted(payloads):
    receive = path()
    for payload in payloads:
        receive.accept(payload, T0)
    assert receive.release(T0) is None
    stats = receive.stats()
    assert stats.received == len(payloads)
    assert sum(stats.dropped.values()) == len(payloads)


# -- ordering, staleness, restarts -------------------------------------------------------------

def test_out_of_order_and_duplicates_are_dropped():
    receive = path()
    for seq in (0, 1, 3, 2, 3, 4):
        receive.accept(handle(seq, T0 + seq * MS), T0 + seq * MS + 100_000)
    newest = receive.release(T0 + 10 * MS)
    assert newest is not None and newest.seq == 4
    stats = receive.stats()
    assert stats.dropped["out_of_order"] == 2
    assert stats.reordered == 2
    assert stats.delivered == 4 and stats.superseded == 3
    assert stats.network_lost == 0  # seq 2 came, late: not lost on the wire
    assert stats.expected == 5
    assert stats.loss_ratio == pytest.approx(1 - 4 / 5)


def test_stale_messages_are_dropped():
    receive = path(stale_s=0.05)
    receive.accept(handle(0, T0), T0 + 60 * MS)
    receive.accept(handle(1, T0 + 1 * MS), T0 + 2 * MS)
    assert receive.release(T0 + 61 * MS).seq == 1
    assert receive.stats().dropped["stale"] == 1


def test_stale_limit_includes_the_injected_delay():
    receive = path(InjectionConfig(delay_s=0.1, jitter_s=0.02), stale_s=0.05)
    receive.accept(handle(0, T0), T0 + 160 * MS)  # 160 ms < 50 + 100 + 20
    receive.accept(handle(1, T0), T0 + 171 * MS)  # older than 170 ms: stale
    assert receive.stats().dropped["stale"] == 1


def test_sequence_gaps_are_network_loss():
    receive = path()
    for seq in (0, 1, 5, 6):
        receive.accept(handle(seq, T0 + seq * MS), T0 + seq * MS)
    receive.release(T0 + 10 * MS)
    stats = receive.stats()
    assert stats.network_lost == 3
    assert stats.expected == 7
    assert stats.network_loss_ratio == pytest.approx(3 / 7)
    assert stats.loss_ratio == pytest.approx(3 / 7)


def test_new_epoch_restarts_the_sequence():
    receive = path()
    for seq in range(5):
        receive.accept(handle(seq, T0 + seq * MS, epoch=1), T0 + seq * MS)
    receive.release(T0 + 5 * MS)
    receive.accept(handle(0, T0 + 10 * MS, epoch=2), T0 + 10 * MS)  # peer restarted
    assert receive.release(T0 + 10 * MS).epoch == 2
    receive.accept(handle(5, T0 + 4 * MS, epoch=1), T0 + 11 * MS)  # late, old epoch
    assert receive.release(T0 + 12 * MS) is None
    stats = receive.stats()
    assert stats.peer_restarts == 1
    assert stats.dropped["out_of_order"] == 1
    assert stats.delivered == 6


# -- injection -------------------------------------------------------------------------------

@pytest.mark.parametrize("distribution", ["uniform", "normal", "exponential"])
def test_injected_delay_is_delivered_within_the_jitter_bounds(distribution):
    delay, jitter = 0.02, 0.005
    receive = path(InjectionConfig(delay_s=delay, jitter_s=jitter,
                                   jitter_distribution=distribution, preserve_order=False))
    delivered = {}
    sent = {}
    now = T0
    for seq in range(400):
        send = T0 + seq * MS // 2
        sent[seq] = send
        receive.accept(handle(seq, send), send + 50_000)  # 50 us real link delay
    while now < T0 + 300 * MS:  # poll every 10 us
        message = receive.release(now)
        if message is not None:
            delivered[message.seq] = now
        now += 10_000
    delays = np.array([delivered[s] - sent[s] for s in delivered]) * 1e-9
    assert delays.min() >= delay
    assert delays.max() <= delay + jitter + 10e-6  # + one poll step
    stats = receive.stats()
    assert delay <= stats.one_way_delay_p50_s <= delay + jitter
    assert stats.delivered + stats.dropped["out_of_order"] == 400


def test_real_link_delay_counts_towards_the_injected_delay():
    receive = path(InjectionConfig(delay_s=0.01))
    receive.accept(handle(0, T0), T0 + 4 * MS)  # the network took 4 ms already
    assert receive.release(T0 + 9 * MS) is None
    assert receive.release(T0 + 10 * MS).seq == 0
    receive.accept(handle(1, T0 + MS), T0 + 30 * MS)  # the network took 29 ms: no extra wait
    assert receive.release(T0 + 30 * MS).seq == 1
    assert receive.stats().one_way_delay_max_s == pytest.approx(0.029, rel=0.01)


def test_preserve_order_never_reorders():
    receive = path(InjectionConfig(delay_s=0.001, jitter_s=0.01, preserve_order=True))
    for seq in range(500):
        receive.accept(handle(seq, T0 + seq * 100_000), T0 + seq * 100_000)
    last = -1
    for step in range(2000):
        message = receive.release(T0 + step * 50_000)
        if message is not None:
            assert message.seq > last
            last = message.seq
    stats = receive.stats()
    assert stats.dropped["out_of_order"] == 0 and stats.reordered == 0
    assert stats.delivered == 500


def test_jitter_without_order_preservation_reorders_and_counts_it():
    receive = path(InjectionConfig(jitter_s=0.01, preserve_order=False))
    for seq in range(500):
        receive.accept(handle(seq, T0 + seq * 100_000), T0 + seq * 100_000)
    for step in range(2000):
        receive.release(T0 + step * 50_000)
    stats = receive.stats()
    assert stats.dropped["out_of_order"] > 0
    assert stats.delivered + stats.dropped["out_of_order"] == 500


def test_injected_independent_loss_is_measured_back():
    p, n = 0.2, 2000
    receive = path(InjectionConfig(loss_probability=p), seed=42)
    for seq in range(n):
        receive.accept(handle(seq, T0 + seq * MS), T0 + seq * MS)
        receive.release(T0 + seq * MS)
    stats = receive.stats()
    tolerance = 4 * math.sqrt(p * (1 - p) / n)
    assert abs(stats.loss_ratio - p) <= tolerance
    assert stats.dropped["injected_loss"] == n - stats.delivered
    assert stats.network_lost == 0


def _loss_runs(lost: list[bool]) -> list[int]:
    runs, current = [], 0
    for flag in lost:
        if flag:
            current += 1
        elif current:
            runs.append(current)
            current = 0
    if current:
        runs.append(current)
    return runs


def test_gilbert_elliott_loss_comes_in_bursts():
    n = 20000
    bursty = InjectionConfig(burst_enter_probability=0.01, burst_exit_probability=0.1)
    receive = path(bursty, seed=3)
    lost = []
    for seq in range(n):
        receive.accept(handle(seq, T0 + seq * MS), T0 + seq * MS)
        lost.append(receive.release(T0 + seq * MS) is None)
    runs = _loss_runs(lost)
    # stationary loss p/(p+r) = 0.01/0.11; mean burst 1/r = 10 messages
    assert np.mean(lost) == pytest.approx(0.01 / 0.11, rel=0.25)
    assert np.mean(runs) == pytest.approx(10.0, rel=0.3)
    # the same loss rate drawn independently has mean runs of about 1.1
    independent = path(InjectionConfig(loss_probability=float(np.mean(lost))), seed=3)
    lost_independent = []
    for seq in range(n):
        independent.accept(handle(seq, T0 + seq * MS), T0 + seq * MS)
        lost_independent.append(independent.release(T0 + seq * MS) is None)
    assert np.mean(_loss_runs(lost_independent)) < 1.5


def test_injection_is_reproducible_from_the_seed():
    def run(seed: int) -> list[bool]:
        receive = path(InjectionConfig(loss_probability=0.3, jitter_s=0.001), seed=seed)
        out = []
        for seq in range(300):
            receive.accept(handle(seq, T0 + seq * MS), T0 + seq * MS)
            out.append(receive.release(T0 + seq * MS + 2 * MS) is None)
        return out

    assert run(5) == run(5)
    assert run(5) != run(6)


@pytest.mark.parametrize(
    "kwargs",
    [{"delay_s": -1.0}, {"jitter_s": -0.1}, {"jitter_distribution": "pareto"},
     {"loss_probability": 1.5}, {"burst_exit_probability": 0.0}],
)
def test_invalid_injection_is_refused(kwargs):
    with pytest.raises(ValueError):
        InjectionConfig(**kwargs)
