"""The time the input guards count between a peer's messages (common/wire/send_clock.py):
never more than this host's own elapsed time allows, whatever the stamps say (issue 17: a
send time up to ``stale_after_s`` ahead passes the receive path, and counted as it stands it
gave one message room for a 50 mm jump)."""

from __future__ import annotations

import numpy as np
import pytest

from haptic.common.config import ConfigError, load_config, override
from haptic.common.wire.messages import Flags, HandleState, ToolState
from haptic.common.wire.send_clock import SendClock, receive_time_ns
from haptic.master.tool_guard import ToolGuardSettings, ToolInputGuard
from haptic.slave_sim.input_guard import InputGuard, InputGuardSettings

TS = 0.00054
TS_NS = 540_000
ALLOWANCE_NS = 5_000_000
DELAY_NS = 2_000_000  # the link's one-way delay, ns


def handle(seq: int, send_ns: int, position_m: tuple[float, float] = (0.0, 0.0)) -> HandleState:
    return HandleState(7, seq, send_ns, Flags.FORCES_ENABLED, (1.0, 0.0), position_m)


def tool(seq: int, send_ns: int, position_m: tuple[float, float] = (0.0, 0.0)) -> ToolState:
    return ToolState(7, seq, send_ns, Flags.FORCES_ENABLED, (0.0, 0.0), position_m, (0.0, 0.0),
                     0.0, 0.0)


def test_stamps_of_a_steady_link_with_jitter_and_loss_are_counted_in_full() -> None:
    """A sender whose delay varies by less than the allowance (and loses messages) is
    credited exactly its send times, lead rising or not."""
    rng = np.random.default_rng(3)
    clock = SendClock(ALLOWANCE_NS)
    for seq in range(5000):
        if rng.uniform() < 0.2:
            continue  # lost
        send_ns = 10**12 + seq * TS_NS
        now_ns = send_ns + DELAY_NS + int(rng.uniform(0, 0.9 * ALLOWANCE_NS))
        if clock.epoch is not None:
            assert clock.credit(send_ns, now_ns) == send_ns
        clock.accept(7, send_ns, now_ns)
        assert clock.credited_ns == send_ns


def test_stamps_ahead_of_the_senders_usual_lead_count_only_the_allowance() -> None:
    clock = SendClock(ALLOWANCE_NS)
    clock.accept(7, 0, DELAY_NS)  # usual lead: -2 ms
    now_ns = DELAY_NS + TS_NS
    ahead_ns = 50_000_000  # what the receive path still lets through
    assert clock.credit(TS_NS + ahead_ns, now_ns) == now_ns - DELAY_NS + ALLOWANCE_NS
    span = clock.span_s(7, TS_NS + ahead_ns, now_ns, TS)
    assert span == pytest.approx((TS_NS + ALLOWANCE_NS) * 1e-9)
    assert clock.span_s(8, TS_NS + ahead_ns, now_ns, TS) is None  # another epoch
    assert clock.span_s(7, 0, now_ns, TS) == TS  # at least the least span


def test_a_sender_that_creeps_ahead_gains_the_allowance_once() -> None:
    """Each stamp a little further ahead than the last (each step within the allowance):
    over the whole run the credited time is at most the receiver's elapsed time x 1.01
    plus the allowance, where the stamps claim 50 ms more."""
    clock = SendClock(ALLOWANCE_NS)
    clock.accept(7, 0, DELAY_NS)
    start_ns = clock.credited_ns
    for seq in range(1, 101):
        now_ns = DELAY_NS + seq * TS_NS
        stamp_ns = seq * TS_NS + seq * 500_000  # 0.5 ms further ahead each message
        clock.accept(7, stamp_ns, now_ns)
    elapsed_ns = 100 * TS_NS
    assert stamp_ns - start_ns == elapsed_ns + 50_000_000
    assert clock.credited_ns - start_ns <= elapsed_ns * 1.01 + ALLOWANCE_NS
    assert clock.credited_ns - start_ns >= elapsed_ns  # the receiver's time: nothing lost


def test_a_delay_that_falls_for_good_is_counted_in_full_again_later() -> None:
    """The link's delay falls by 20 ms and stays there: the lead rises at 1 % of the
    elapsed time; once it has, stamps count in full again."""
    clock = SendClock(ALLOWANCE_NS)
    clock.accept(7, 0, 25_000_000)
    seq = 0
    for seq in range(1, 10_000):
        send_ns = seq * TS_NS
        clock.accept(7, send_ns, send_ns + 5_000_000)
        if clock.credited_ns == send_ns:
            break
    assert clock.credited_ns == send_ns
    # 20 ms - 5 ms allowance at 1 % of the time: about 1.5 s
    assert 1.4 < seq * TS < 1.7


def test_the_lead_rises_by_whole_ns_and_never_falls() -> None:
    clock = SendClock(ALLOWANCE_NS)
    clock.accept(7, 0, DELAY_NS)
    assert clock.lead_ns == -DELAY_NS
    clock.accept(7, 1_540_050, 540_050 + DELAY_NS)  # 1 ms faster, 540.05 us on: 5400 ns
    assert clock.lead_ns == -DELAY_NS + 5_400 and type(clock.lead_ns) is int
    clock.accept(7, 2_000_000, 3_000_000 + DELAY_NS)  # slower: kept
    assert clock.lead_ns == -DELAY_NS + 5_400
    clock.accept(7, 2_100_000, 1_000_000)  # a receive time going back: kept
    assert clock.lead_ns == -DELAY_NS + 5_400 and clock.received_ns == 1_000_000


def test_a_new_epoch_starts_its_lead_afresh() -> None:
    """After the peer's restart (a new epoch, through the link's pairing), its lead is the
    new epoch's first message's: a restarted peer whose clock now leads by 30 ms more is
    counted in full from its second message on."""
    clock = SendClock(ALLOWANCE_NS)
    clock.accept(7, 0, DELAY_NS)
    clock.accept(8, 40_000_000, 10_000_000)  # leads by 30 ms
    assert (clock.epoch, clock.lead_ns, clock.credited_ns) == (8, 30_000_000, 40_000_000)
    assert clock.span_s(8, 40_540_000, 10_540_000, TS) == pytest.approx(TS)
    assert clock.credit(40_540_000, 10_540_000) == 40_540_000


def test_receive_time_ns_truncates_as_the_kernel_does() -> None:
    assert receive_time_ns(1.5) == 1_500_000_000
    assert receive_time_ns(12.345678901) == int(12.345678901 * 1e9)


@pytest.mark.parametrize("side", ["slave", "master"])
def test_a_message_stamped_ahead_earns_no_room_for_a_jump(side: str) -> None:
    """The attack the receive path lets through: one message stamped 50 ms ahead, moved
    30 mm (the stamps alone allowed 1 m/s x 50 ms + margin = 51 mm): a fault on both sides.
    The same 30 mm over 50 ms of this host's time is an input."""
    config = load_config()
    if side == "slave":
        guard = InputGuard(InputGuardSettings.from_config(config), TS)
        build = handle
    else:
        guard = ToolInputGuard(ToolGuardSettings.from_config(config), TS)
        build = tool
    assert guard.settings.jitter_allowance_s == 0.005
    start_s = 100.0
    start_ns = receive_time_ns(start_s) - DELAY_NS
    assert guard.admit(build(0, start_ns), start_s)
    assert not guard.admit(build(1, start_ns + 50_000_000 + TS_NS, (0.03, 0.0)), start_s + TS)
    assert guard.faulted and guard.counters.faults == 1
    # over 5.54 ms (0.54 ms of this host's time + the 5 ms allowance), not 50.54 ms
    assert guard.events[-1]["reason"] == (
        "handle position jumped 30 mm in 5.54 ms (at most 6.54 mm)" if side == "slave" else
        "tool position jumped 30 mm in 5.54 ms (the tool moves at most 13.1 mm)")
    # honest: 50 ms later by both clocks
    other = InputGuard(InputGuardSettings.from_config(config), TS) if side == "slave" \
        else ToolInputGuard(ToolGuardSettings.from_config(config), TS)
    assert other.admit(build(0, start_ns), start_s)
    assert other.admit(build(1, start_ns + 50_000_000, (0.03, 0.0)), start_s + 0.05)
    assert not other.faulted


def test_the_slaves_force_rate_counts_the_credited_time() -> None:
    """The rate limit's step spans the credited time: at 1000 N/s, a message stamped 50 ms
    ahead moves the bounded force by one 5.54 ms step (5.54 N), not to the 19 N it asks."""
    settings = InputGuardSettings(force_rate_limit_N_per_s=1000.0)
    guard = InputGuard(settings, TS)
    start_s = 100.0
    start_ns = receive_time_ns(start_s) - DELAY_NS
    assert guard.admit(HandleState(7, 0, start_ns, Flags.FORCES_ENABLED, (0.0, 0.0),
                                   (0.0, 0.0)), start_s)
    assert guard.admit(HandleState(7, 1, start_ns + 50_000_000, Flags.FORCES_ENABLED,
                                   (19.0, 0.0), (0.0, 0.0)), start_s + TS)
    assert guard.force_N[0] == pytest.approx(1000.0 * (ALLOWANCE_NS * 1e-9 + TS), rel=1e-6)
    assert guard.counters.rate_limited == 1


@pytest.mark.parametrize("key", ["slave.safety.jitter_allowance_s",
                                 "master.tool_input.jitter_allowance_s"])
def test_the_allowance_is_validated(key: str) -> None:
    config = load_config()
    for bad in (-0.001, 2.0, float("nan")):
        with pytest.raises(ConfigError, match=key):
            override(config, key, bad)
    assert override(config, key, 0.0) is not None


def test_the_allowance_in_whole_ns() -> None:
    for settings in (InputGuardSettings, ToolGuardSettings):
        assert settings(jitter_allowance_s=1.0).jitter_allowance_ns == 10**9
        assert settings(jitter_allowance_s=0.0049999999).jitter_allowance_ns == 5_000_000
