"""The phase lock at its edges (common/wire/phase_lock.py): its settings' bounds, the
conversions to ns, the wrap and the deadband at their ties, the smallest correction, the
limit, and the summary's figures; tests/common/wire/test_phase_lock.py tests it locking."""

from __future__ import annotations

import dataclasses

import pytest

from haptic.common.wire.phase_lock import PhaseLock, PhaseLockSettings


def test_the_settings_defaults_are_pinned_and_frozen() -> None:
    assert dataclasses.astuple(PhaseLockSettings()) == (0.00013, 0.05, 0.000002, 0.000003)
    with pytest.raises(dataclasses.FrozenInstanceError):
        PhaseLockSettings().gain = 2.0  # type: ignore[misc]


def test_the_bounds_of_period_lag_gain_and_step() -> None:
    assert PhaseLock(0.001, PhaseLockSettings(lag_s=0.0, gain=1.0)) is not None
    for period_s, settings, words in (
            (0.0, PhaseLockSettings(lag_s=0.0), "period_s"),
            (0.001, PhaseLockSettings(lag_s=0.001), "lag_s"),
            (0.001, PhaseLockSettings(lag_s=-1e-9), "lag_s"),
            (0.001, PhaseLockSettings(gain=0.0), "gain"),
            (0.001, PhaseLockSettings(gain=1.0 + 1e-9), "gain"),
            (0.001, PhaseLockSettings(max_step_s=0.0), "max_step_s")):
        with pytest.raises(ValueError, match=words):
            PhaseLock(period_s, settings)


def test_times_become_whole_ns_exactly() -> None:
    """A 1 s period and 0.6 s of lag, limit and deadband: exactly 10^9 and 6 x 10^8 ns."""
    lock = PhaseLock(1.0, PhaseLockSettings(lag_s=0.6))
    assert lock.phase_error_ns(0, 600_000_000) == 0
    assert lock.phase_error_ns(0, 1_600_000_000) == 0  # one period later: the same phase
    wide = PhaseLock(10.0, PhaseLockSettings(lag_s=0.0, gain=1.0, max_step_s=0.6,
                                             deadband_s=0.6))
    # the deadband's edges are locked, one ns beyond them is not (and meets the limit)
    assert wide.update(0, 600_000_000) == 0 and wide.update(0, -600_000_000) == 0
    assert wide.locked_ticks == 2
    assert wide.update(0, 600_000_001) == -600_000_000
    assert wide.update(0, -600_000_001) == 600_000_000
    assert wide.update(0, 2_000_000_000) == -600_000_000  # 2 s late: the limit


def test_the_wrap_puts_half_a_period_early() -> None:
    """Errors wrap into [-Ts/2, Ts/2): with a 1001 ns period, 500 ns late stays late, 501 ns
    late is 500 ns early."""
    lock = PhaseLock(1001e-9, PhaseLockSettings(lag_s=0.0))
    assert lock.phase_error_ns(0, 499) == 499
    assert lock.phase_error_ns(0, 500) == -501
    assert lock.phase_error_ns(0, 1000) == -1


def test_the_smallest_correction_is_one_ns_towards_the_lag() -> None:
    """Without a deadband, an error too small for the gain still moves the tick 1 ns."""
    lock = PhaseLock(0.001, PhaseLockSettings(lag_s=0.0, gain=0.05, deadband_s=0.0))
    assert lock.update(0, 1) == -1  # 1 ns late: 1 ns earlier
    assert lock.update(0, -1) == 1
    assert lock.update(0, 0) == 0  # on the lag: locked
    assert (lock.corrections, lock.total_shift_ns, lock.locked_ticks) == (2, 0, 1)


def test_the_summary() -> None:
    lock = PhaseLock(0.001, PhaseLockSettings(lag_s=0.0, gain=1.0, deadband_s=0.0,
                                              max_step_s=0.001))
    assert lock.summary() == {  # no update yet
        "phase_lock_enabled": True, "phase_lock_lag_s": 0.0, "phase_lock_unstamped": 0,
        "phase_lock_last_error_s": 0.0, "phase_lock_locked_ratio": 0.0,
        "phase_lock_total_shift_s": 0.0}
    assert lock.update(0, 250_000) == -250_000
    lock.update(0, 0)
    lock.skip_unmeasured()
    assert lock.summary() == {
        "phase_lock_enabled": True, "phase_lock_lag_s": 0.0, "phase_lock_unstamped": 1,
        "phase_lock_last_error_s": 0.0, "phase_lock_locked_ratio": 0.5,
        "phase_lock_total_shift_s": -0.00025}
    lock.update(0, 100_000)
    assert lock.summary()["phase_lock_last_error_s"] == pytest.approx(1e-4, rel=1e-15)
