"""Delay lines: exact whole-sample delays, jitter within its bound, loss keeps the last."""

from __future__ import annotations

import numpy as np

from haptic.common.wire.injection import InjectionConfig
from haptic.lockstep.delay_line import DelayLine, source_schedule

TS = 0.001


def test_plain_delay_is_exact() -> None:
    schedule = source_schedule(50, np.array([0, 3]), 1, TS)
    ticks = np.arange(50)
    np.testing.assert_array_equal(schedule[:, 0], np.where(ticks >= 1, ticks - 1, -1))
    np.testing.assert_array_equal(schedule[:, 1], np.where(ticks >= 4, ticks - 4, -1))


def test_jitter_is_bounded_and_keeps_order() -> None:
    injection = InjectionConfig(delay_s=0.002, jitter_s=0.003)
    schedule = source_schedule(2000, np.array([5]), 0, TS, injection,
                               np.random.default_rng(1))[:, 0]
    ticks = np.arange(2000)
    lag = (ticks - schedule)[schedule >= 0]
    assert lag.min() >= 5 + 2 and lag.max() <= 5 + 2 + 3 + 1
    assert np.all(np.diff(schedule) >= 0)


def test_lost_messages_leave_the_previous_one() -> None:
    injection = InjectionConfig(loss_probability=0.3)
    schedule = source_schedule(1000, np.array([2]), 0, TS, injection,
                               np.random.default_rng(3))[:, 0]
    ticks = np.arange(1000)
    held = schedule < ticks - 2
    assert 0.2 < held[10:].mean() < 0.4
    assert np.all(np.diff(schedule) >= 0)
    line = DelayLine(schedule[:, None], 1)
    for tick in range(1000):
        line.send(tick, np.array([[float(tick)]]))
        received = line.receive(tick)[0, 0]
        assert received == (schedule[tick] if schedule[tick] >= 0 else 0.0)


def test_every_lane_reads_its_own_newest_message_before_and_after_all_have_one() -> None:
    """Lanes of different delays, jitter and loss: each lane reads the message its schedule
    names (the initial value before its first), through the run-up and after it, with what
    the receiver's link would say of it: fresh or not, the silence since the last fresh one,
    its send tick and time, its flags and its columns with the send tick."""
    delays = np.array([0, 1, 4, 7, 2])
    injection = InjectionConfig(jitter_s=0.002, loss_probability=0.1)
    schedule = source_schedule(300, delays, 1, TS, injection, np.random.default_rng(5))
    started = np.flatnonzero((schedule >= 0).all(axis=1))
    assert 0 < started[0] < 300  # the run-up, then every lane with a message
    initial = np.arange(5 * 3, dtype=float).reshape(5, 3) - 100.0
    line = DelayLine(schedule, 3, initial, period_s=TS, runup_lag=delays + 1,
                     message_columns=2, flag_column=1)
    previous = np.full(5, -2)
    last_fresh = np.zeros(5, int)
    for tick in range(300):
        line.send(tick, tick + np.arange(5)[:, None] * 0.01 + np.arange(3) * 0.001)
        received = line.receive(tick)
        for lane in range(5):
            source = schedule[tick, lane]
            expected = initial[lane] if source < 0 else (
                source + lane * 0.01 + np.arange(3) * 0.001)
            np.testing.assert_array_equal(received[lane], expected)
            fresh = source != previous[lane] or source < 0
            previous[lane] = source
            if fresh:
                last_fresh[lane] = tick
            sent = source if source >= 0 else tick - delays[lane] - 1
            assert line.fresh[lane] == fresh
            assert line.silence_s[lane] == (tick - last_fresh[lane]) * TS
            assert line.sent[lane] == sent
            assert line.send_time_ns[lane] == int(sent * (TS * 1e9))
            assert line.flags[lane] == int(expected[1])
            np.testing.assert_array_equal(line.columns[lane], [*expected[:2], sent])


def test_a_plain_schedule_is_the_scatter_of_an_injected_one_that_adds_nothing() -> None:
    """Without injection the schedule is computed directly (tick t reads t - offset - delay);
    an injection that is active but adds no whole sample (1e-12 s) goes through the scatter
    of arrivals: the two agree, run-up included."""
    rng = np.random.default_rng(0)
    nothing = InjectionConfig(delay_s=1e-12)
    assert nothing.active
    for steps in (0, 1, 7, 300):
        for offset in (0, 1):
            for delays in ([0], [5], np.arange(0, 40, 3), [400]):
                plain = source_schedule(steps, delays, offset, TS)
                scattered = source_schedule(steps, delays, offset, TS, nothing, rng)
                assert plain.dtype == scattered.dtype == np.int64
                assert np.array_equal(plain, scattered), (steps, offset, delays)
    assert source_schedule(6, [2], 1, TS)[:, 0].tolist() == [-1, -1, -1, 0, 1, 2]
