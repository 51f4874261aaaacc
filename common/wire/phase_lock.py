"""Phase lock: keep this loop's ticks a set lag after the peer's messages arrive.

The master and the slave each tick every Ts on their own clock, so with free-running loops the
slave's tick falls anywhere in the master's period: the master's message waits between 0 and
Ts (uniformly, run to run different) for the slave's next tick, and on a shared host the two
loops' busy parts overlap at random with each other and with the link's network threads.

:class:`PhaseLock` runs on the slave. Each tick that delivers a fresh master message it
measures the lag from the message's delivery (its arrival, or the injected target) to the poll
that used it, and nudges the runner's schedule so that this lag converges to ``lag_s``: a
proportional correction, at most ``max_step_s`` per tick, wrapped to the nearest equivalent
phase (a lag near Ts means the message came just after the tick; the tick moves later, not a
whole period earlier). The period error this adds is at most ``max_step_s`` per tick, and
nothing while locked within ``deadband_s``. Clock rates that differ (two hosts, tens of ppm)
become a slow phase drift the correction follows.

Effects: the master's sample is used a fixed ``lag_s`` after it arrives (the round trip's
age at use becomes deterministic instead of uniform over a period), and on one host the
slave's busy part of the period no longer lands on the master's sends. All times in ns on the
link's clock (:func:`time.time_ns`); the runner's clock need only have the same rate.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class PhaseLockSettings:
    """``lag_s``: delivery of the peer's message to the tick that uses it, s. ``gain``: the
    fraction of the phase error corrected per tick (0..1]. ``max_step_s``: the largest
    correction per tick, s. ``deadband_s``: errors smaller than this are left alone, s."""

    lag_s: float = 0.00013
    gain: float = 0.05
    max_step_s: float = 0.000002
    deadband_s: float = 0.000003


class PhaseLock:
    """Measures the delivery-to-use lag and returns the schedule corrections (ns) for the
    runner. ``period_s``: the loop's period Ts, s."""

    def __init__(self, period_s: float, settings: PhaseLockSettings | None = None) -> None:
        settings = settings or PhaseLockSettings()
        if not period_s > 0.0:
            raise ValueError(f"period_s must be > 0 (got {period_s})")
        if not 0.0 <= settings.lag_s < period_s:
            raise ValueError(f"lag_s must be in [0, Ts) (got {settings.lag_s} s, Ts {period_s} s)")
        if not 0.0 < settings.gain <= 1.0:
            raise ValueError(f"gain must be in (0, 1] (got {settings.gain})")
        if not settings.max_step_s > 0.0:
            raise ValueError(f"max_step_s must be > 0 (got {settings.max_step_s})")
        self.settings = settings
        self._period_ns = round(period_s * 1e9)
        self._lag_ns = round(settings.lag_s * 1e9)
        self._max_step_ns = round(settings.max_step_s * 1e9)
        self._deadband_ns = round(settings.deadband_s * 1e9)
        self._gain = settings.gain
        self.last_error_ns = 0
        self.corrections = 0
        self.total_shift_ns = 0
        self.locked_ticks = 0
        self.updates = 0
        self.unmeasured = 0

    def phase_error_ns(self, delivery_ns: int, use_ns: int) -> int:
        """The lag from ``delivery_ns`` to ``use_ns`` minus ``lag_s``, wrapped into
        [-Ts/2, Ts/2), ns. Positive: the tick comes too late after the message."""
        period = self._period_ns
        error = (use_ns - delivery_ns - self._lag_ns) % period
        return error - period if error >= period // 2 else error

    def update(self, delivery_ns: int, use_ns: int) -> int:
        """The schedule correction (ns; negative: the next tick comes earlier) for a fresh
        message delivered at ``delivery_ns`` and used by the tick that polled at ``use_ns``."""
        error = self.phase_error_ns(delivery_ns, use_ns)
        self.last_error_ns = error
        self.updates += 1
        if -self._deadband_ns <= error <= self._deadband_ns:
            self.locked_ticks += 1
            return 0
        step = round(-self._gain * error)
        limit = self._max_step_ns
        step = max(-limit, min(limit, step))
        if step == 0:
            step = -1 if error > 0 else 1
        self.corrections += 1
        self.total_shift_ns += step
        return step

    def skip_unmeasured(self) -> None:
        """A fresh message whose delivery time is not a measurement (no arrival stamp): no
        correction, counted in the summary."""
        self.unmeasured += 1

    def summary(self) -> dict[str, object]:
        """The run summary's keys: the target lag, the last error, how often it was locked."""
        return {
            "phase_lock_enabled": True,
            "phase_lock_lag_s": self.settings.lag_s,
            "phase_lock_unstamped": self.unmeasured,
            "phase_lock_last_error_s": self.last_error_ns * 1e-9,
            "phase_lock_locked_ratio": self.locked_ticks / self.updates if self.updates else 0.0,
            "phase_lock_total_shift_s": self.total_shift_ns * 1e-9,
        }
