"""Two cells over the real Zenoh link (loopback, in this process), far from the boundary so a
loaded machine's late ticks cannot flip them: the verdicts match the analysis at the round
trip the link really gave, which is at least the injected one."""

from __future__ import annotations

import pytest

from haptic.lockstep.real_link import run_cell


@pytest.mark.parametrize(("injected_s", "growing"), [(0.002, False), (0.016, True)])
def test_real_link_cells_agree_with_the_analysis(paper_model, injected_s, growing) -> None:
    cell = run_cell(paper_model, 19.0, injected_s, duration_s=1.5)
    assert cell.growing is growing
    assert cell.agree
    assert cell.measured_round_trip_s >= injected_s - paper_model.sample_period_s
