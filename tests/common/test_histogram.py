"""The log histogram's percentiles against numpy's."""

from __future__ import annotations

import math

import numpy as np
import pytest

from haptic.common.histogram import LogHistogram


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
