"""A log-binned histogram for percentiles of long runs in constant memory.

Used for one-way delays and period errors: recording is O(1) and allocation-free apart from
Python's own floats; percentiles are exact to within the bin's relative width (0.5 %).
"""

from __future__ import annotations

import bisect
import math
from itertools import accumulate


class LogHistogram:
    """Counts of positive values (seconds) in logarithmic bins from ``low_s`` to ``high_s``.

    Values at or below ``low_s`` (including zero and negatives) fall in the first bin,
    values above ``high_s`` in the last; ``max_s`` and ``count`` are exact.
    """

    def __init__(self, low_s: float = 1e-9, high_s: float = 100.0, rel_width: float = 0.005):
        if not 0.0 < low_s < high_s or not 0.0 < rel_width < 1.0:
            raise ValueError("need 0 < low_s < high_s and 0 < rel_width < 1")
        self.low_s = low_s
        self._log_low = math.log(low_s)
        self._inv_log_step = 1.0 / math.log1p(rel_width)
        self._step = math.log1p(rel_width)
        self._nbins = int(math.ceil(math.log(high_s / low_s) * self._inv_log_step)) + 2
        self._counts = [0] * self._nbins
        self._first = self._nbins  # lowest and highest bin above the underflow holding a value
        self._last = -1
        self.count = 0
        self.max_s = -math.inf
        self.sum_s = 0.0

    def record(self, value_s: float) -> None:
        """Add one value, s."""
        if value_s > self.low_s:
            index = int((math.log(value_s) - self._log_low) * self._inv_log_step) + 1
            if index >= self._nbins:
                index = self._nbins - 1
        else:
            index = 0
        self._counts[index] += 1
        if index:
            if index < self._first:
                self._first = index
            if index > self._last:
                self._last = index
        self.count += 1
        self.sum_s += value_s
        if value_s > self.max_s:
            self.max_s = value_s

    def percentile(self, q: float) -> float:
        """The ``q``-th percentile (0..100), s; NaN when empty. Returns the geometric centre of
        the bin holding it (0 for the underflow bin), capped at the exact maximum."""
        return self.percentiles((q,))[0]

    def percentiles(self, qs: tuple[float, ...]) -> tuple[float, ...]:
        """Several percentiles (0..100) in one pass over the occupied bins, s. Cheap enough to
        call from a real-time loop: it scans only the bins between the smallest and largest
        value recorded (tens of us for delays spanning two decades)."""
        if self.count == 0:
            return tuple(math.nan for _ in qs)
        underflow = self._counts[0]
        first = self._first
        cumulative = list(accumulate(self._counts[first:self._last + 1], initial=underflow))
        results = []
        for q in qs:
            rank = max(q / 100.0 * self.count, 1e-12)
            if rank <= underflow:
                results.append(0.0)
                continue
            index = first - 1 + bisect.bisect_left(cumulative, rank)
            if index >= self._nbins - 1:
                results.append(self.max_s)
            else:
                centre = math.exp(self._log_low + (index - 0.5) * self._step)
                results.append(min(centre, self.max_s))
        return tuple(results)

    @property
    def mean_s(self) -> float:
        return self.sum_s / self.count if self.count else math.nan

    def merge(self, other: LogHistogram) -> None:
        """Add ``other``'s counts (same bins) into this histogram."""
        if other._nbins != self._nbins or other.low_s != self.low_s:
            raise ValueError("histograms have different bins")
        for i, c in enumerate(other._counts):
            self._counts[i] += c
        self._first = min(self._first, other._first)
        self._last = max(self._last, other._last)
        self.count += other.count
        self.sum_s += other.sum_s
        self.max_s = max(self.max_s, other.max_s)
