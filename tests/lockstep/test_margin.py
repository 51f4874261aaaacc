"""The lockstep and the sampled analysis agree on the delay margin within 5 %."""

from __future__ import annotations

import numpy as np
import pytest

from haptic.lockstep.sweep import analytic_margin_s, lockstep_margin


@pytest.mark.parametrize("gain_k", [13.0, 19.0])
def test_lockstep_margin_matches_the_sampled_analysis(paper_model, gain_k) -> None:
    ts = paper_model.sample_period_s
    analytic = analytic_margin_s(paper_model, gain_k, ts)  # worst axis (y)
    centre = analytic / ts
    delays = np.arange(int(centre * 0.85), int(centre * 1.15) + 2)
    measured = lockstep_margin(paper_model, gain_k, delays, duration_s=3.0)
    assert measured.growing_samples == measured.bounded_samples + 1
    assert abs(measured.margin_s - analytic) <= 0.05 * analytic, (measured, analytic)
