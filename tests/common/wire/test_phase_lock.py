"""The slave's phase lock: its error measure, its bounded corrections, and the closed loop with
the real runner on an injected clock (a master sending at a fixed phase, the slave's ticks
converging to the set lag after each delivery)."""

from __future__ import annotations

import pytest

from haptic.common.runtime.runner import RealTimeRunner
from haptic.common.wire.phase_lock import PhaseLock, PhaseLockSettings

PERIOD_S = 0.00054
PERIOD_NS = 540_000
US = 1_000


def test_phase_error_is_the_lag_beyond_the_target_wrapped_to_half_a_period():
    lock = PhaseLock(PERIOD_S, PhaseLockSettings(lag_s=50e-6))
    delivery = 10_000_000
    assert lock.phase_error_ns(delivery, delivery + 50 * US) == 0
    assert lock.phase_error_ns(delivery, delivery + 60 * US) == 10 * US  # tick too late
    assert lock.phase_error_ns(delivery, delivery + 40 * US) == -10 * US  # too soon
    # used a whole period after it came: the message just missed the previous tick, so the
    # tick must come *later* (by 5 us + the lag), not a period earlier
    assert lock.phase_error_ns(delivery, delivery + PERIOD_NS - 5 * US) == -55 * US
    # the largest errors are +-Ts/2
    for lag_us in range(0, 1100, 7):
        error = lock.phase_error_ns(delivery, delivery + lag_us * US)
        assert -PERIOD_NS // 2 <= error < PERIOD_NS // 2


def test_corrections_are_proportional_bounded_and_signed():
    settings = PhaseLockSettings(lag_s=50e-6, gain=0.1, max_step_s=2e-6, deadband_s=1e-6)
    lock = PhaseLock(PERIOD_S, settings)
    assert lock.update(0, 50 * US) == 0  # on target
    assert lock.update(0, 50 * US + 500) == 0  # inside the dead band
    assert lock.update(0, 60 * US) == -1_000  # 10 us late: 10 % of it, earlier
    assert lock.update(0, 40 * US) == 1_000
    assert lock.update(0, 250 * US) == -2_000  # capped at max_step_s
    assert lock.update(0, 5 * US) == 2_000
    summary = lock.summary()
    assert summary["phase_lock_lag_s"] == 50e-6
    assert summary["phase_lock_locked_ratio"] == pytest.approx(2 / 6)
    assert summary["phase_lock_total_shift_s"] == pytest.approx(0.0)
    slow = PhaseLock(PERIOD_S, PhaseLockSettings(lag_s=50e-6, gain=1e-4, deadband_s=1e-6))
    assert slow.update(0, 52 * US) == -1  # never a zero step outside the dead band


@pytest.mark.parametrize("settings, message", [
    (PhaseLockSettings(lag_s=PERIOD_S), "lag_s"),
    (PhaseLockSettings(lag_s=-1e-6), "lag_s"),
    (PhaseLockSettings(gain=0.0), "gain"),
    (PhaseLockSettings(gain=1.5), "gain"),
    (PhaseLockSettings(max_step_s=0.0), "max_step_s"),
])
def test_invalid_settings_are_refused(settings, message):
    with pytest.raises(ValueError, match=message):
        PhaseLock(PERIOD_S, settings)


class SharedClock:
    """One host's clock: 1 us per read, the requested time per sleep."""

    def __init__(self) -> None:
        self.now = 1_000_000_000

    def clock(self) -> int:
        self.now += US
        return self.now

    def sleep(self, seconds: float) -> None:
        self.now += round(seconds * 1e9)


def run_locked_slave(master_phase_ns: int, lag_s: float, rate_ratio: float = 1.0,
                     duration_s: float = 0.5) -> tuple[list[int], list[int]]:
    """The slave's runner on a fake clock, locking to a master whose messages are delivered
    at ``master_phase_ns`` + k Ts (on the master's clock, which runs ``rate_ratio`` times
    the slave's). Returns the delivery-to-use lag of every tick (ns) and the tick starts."""
    clock = SharedClock()
    start = clock.now
    lock = PhaseLock(PERIOD_S, PhaseLockSettings(lag_s=lag_s))
    lags: list[int] = []
    starts: list[int] = []
    master_period_ns = PERIOD_NS / rate_ratio

    def step(_tick: int, now_ns: int) -> None:
        starts.append(now_ns)
        # the newest delivery at or before this poll
        k = (now_ns - start - master_phase_ns) // master_period_ns
        delivery = round(start + master_phase_ns + k * master_period_ns)
        lags.append(now_ns - delivery)
        runner.shift_schedule(lock.update(delivery, now_ns))

    runner = RealTimeRunner(PERIOD_S, step, duration_s=duration_s, spin_s=0.0001,
                            clock_ns=clock.clock, sleep=clock.sleep, handle_signals=False,
                            show_status=False)
    runner.run()
    return lags, starts


@pytest.mark.parametrize("master_phase_us", [0, 100, 260, 280, 400, 530])
def test_the_slave_converges_to_the_lag_after_the_masters_messages(master_phase_us):
    lags, starts = run_locked_slave(master_phase_us * US, lag_s=50e-6)
    settled = lags[len(lags) // 2:]  # 0.25 s in; the worst start needs ~165 ticks
    assert all(abs(lag - 50 * US) <= 5 * US for lag in settled), (min(settled), max(settled))
    # each correction is at most 2 us: the period never moves by more than that (+ the
    # fake clock's 1 us per read)
    periods = [b - a for a, b in zip(starts, starts[1:], strict=False)]
    assert max(abs(p - PERIOD_NS) for p in periods) <= 4 * US


def test_the_lock_follows_a_master_whose_clock_runs_faster():
    lags, _ = run_locked_slave(300 * US, lag_s=100e-6, rate_ratio=1.0 + 50e-6, duration_s=1.0)
    settled = lags[len(lags) // 2:]
    assert all(abs(lag - 100 * US) <= 5 * US for lag in settled)


def test_without_the_lock_the_lag_stays_wherever_the_loops_started():
    clock = SharedClock()
    start = clock.now
    lags = []

    def step(_tick: int, now_ns: int) -> None:
        k = (now_ns - start - 300 * US) // PERIOD_NS
        lags.append(now_ns - (start + 300 * US + k * PERIOD_NS))

    RealTimeRunner(PERIOD_S, step, duration_s=0.2, clock_ns=clock.clock, sleep=clock.sleep,
                   handle_signals=False, show_status=False).run()
    assert min(lags[10:]) > 200 * US  # never near 50 us: the phase is the start's accident


def test_unmeasured_deliveries_are_counted_not_corrected():
    lock = PhaseLock(PERIOD_S)
    lock.skip_unmeasured()
    lock.skip_unmeasured()
    summary = lock.summary()
    assert summary["phase_lock_enabled"] is True
    assert summary["phase_lock_unstamped"] == 2
    assert summary["phase_lock_total_shift_s"] == 0.0 and lock.updates == 0
