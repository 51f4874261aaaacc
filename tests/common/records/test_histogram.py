"""The log histogram's percentiles against numpy's."""

from __future__ import annotations

import math

import numpy as np
import pytest

from haptic.common.records.histogram import LogHistogram


def test_percentiles_match_numpy_within_the_bin_width():
    rng = np.random.default_rng(1)
    values = rng.lognormal(mean=math.log(200e-6), sigma=0.7, size=20000)
    h = LogHistogram()
    for v in values:
        h.record(float(v))
    for q in (1, 50, 90, 99, 99.9):
        assert h.percentile(q) == pytest.approx(np.percentile(values, q), rel=0.01)
    assert h.max_s == values.max()
    assert h.count == values.size
    assert h.mean_s == pytest.approx(values.mean())


def test_empty_tiny_and_huge_values():
    h = LogHistogram()
    assert math.isnan(h.percentile(50))
    h.record(0.0)
    h.record(-1.0)
    assert h.percentile(50) == 0.0
    h.record(1e6)
    assert h.percentile(100) == 1e6


def test_merge():
    a, b = LogHistogram(), LogHistogram()
    for v in (1e-3, 2e-3):
        a.record(v)
    b.record(3e-3)
    a.merge(b)
    assert a.count == 3 and a.max_s == 3e-3
    with pytest.raises(ValueError):
        a.merge(LogHistogram(low_s=1e-6))


def _reference_percentile(h: LogHistogram, q: float) -> float:
    """The percentile by a cumulative sum over every bin (the former implementation)."""
    cumulative = np.cumsum(h._counts)
    index = int(np.searchsorted(cumulative, max(q / 100.0 * h.count, 1e-12), side="left"))
    if index == 0:
        return 0.0
    if index >= h._nbins - 1:
        return h.max_s
    return min(math.exp(h._log_low + (index - 0.5) * h._step), h.max_s)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_percentiles_over_the_occupied_bins_equal_a_scan_of_all_bins(seed):
    rng = np.random.default_rng(seed)
    h = LogHistogram()
    values = np.concatenate([rng.lognormal(math.log(20e-6), 1.0, 3000), [0.0, 1e-12, 500.0]])
    for v in rng.permutation(values):
        h.record(float(v))
    qs = (0.0, 0.01, 1.0, 50.0, 99.0, 99.99, 100.0)
    assert h.percentiles(qs) == tuple(_reference_percentile(h, q) for q in qs)
    assert h.percentile(50.0) == _reference_percentile(h, 50.0)


def test_merged_histograms_keep_their_occupied_range():
    low, high = LogHistogram(), LogHistogram()
    for v in (1e-6, 2e-6):
        low.record(v)
    for v in (1e-3, 3e-3):
        high.record(v)
    high.merge(low)
    assert high.percentiles((0.0, 100.0)) == (
        _reference_percentile(high, 0.0), _reference_percentile(high, 100.0))
    assert high.percentile(25.0) == pytest.approx(1e-6, rel=0.01)
    assert math.isnan(LogHistogram().percentiles((50.0,))[0])
