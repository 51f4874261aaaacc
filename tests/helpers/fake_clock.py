"""A fake monotonic clock for the runners' logic: no timing is asserted, every time is exact."""

from __future__ import annotations


class FakeClock:
    """A clock in integer ns that moves 1 us per read and, per sleep, by the requested time
    plus ``late_ns`` (a sleep that always wakes that late); a step may move ``now`` itself to
    charge its own duration."""

    def __init__(self, late_ns: int = 0) -> None:
        self.now = 1_000_000_000
        self.late_ns = late_ns
        self.sleeps = 0

    def clock(self) -> int:
        """The time in ns, 1 us later than the previous read."""
        self.now += 1_000
        return self.now

    def sleep(self, seconds: float) -> None:
        """Advance by ``seconds`` (s) plus ``late_ns``."""
        self.sleeps += 1
        self.now += round(seconds * 1e9) + self.late_ns
