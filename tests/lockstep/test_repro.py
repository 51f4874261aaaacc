"""The reproduction of the paper's section 4 stays within its stated tolerances."""

from __future__ import annotations

import json

import pytest

from haptic.lockstep.repro import report_markdown, reproduce, write_report

REQUIRED = {
    "contact_time_s", "cutting_force_N", "cutting_velocity_m_s",
    "cutting_force_ripple_ratio", "cutting_velocity_reversals", "steady_cutting_force_N",
    "steady_cutting_speed_m_s",
    *(f"variable_rate_velocity_m_s_p{p}" for p in (100, 80, 60, 40, 20)),
    *(f"variable_rate_velocity_over_F_per_B_p{p}" for p in (100, 80, 60, 40, 20)),
    "k3_peak_force_N", "k13_peak_force_N", "k19_peak_force_N", "assumed_loop_delay_s",
}
#: Rows computed from a fitted parameter: the loop delay was fitted to the k = 13 trace, the
#: operator's gains chosen so that it holds 3 N on the staircase.
FITTED = {"k13_peak_force_N", "k13_time_above_7N_s",
          *(f"variable_rate_velocity_m_s_p{p}" for p in (100, 80, 60, 40, 20))}
#: Predicted rows outside their tolerance, documented in docs/lockstep.md: k = 19 grows far
#: faster than the paper's (no single loop delay fits both k = 13 and k = 19).
KNOWN_DEPARTURES = {"k19_peak_force_N"}


@pytest.fixture(scope="module")
def repro(paper_config):
    return reproduce(paper_config)


def test_predicted_rows_are_within_tolerance_and_fits_are_not_counted(repro) -> None:
    rows = {row.name: row for row in repro.rows}
    assert REQUIRED <= set(rows)
    assert {name for name, row in rows.items() if row.basis == "fitted"} == FITTED
    assert all(rows[name].fitted_by for name in FITTED)
    # the fitted delay itself is a parameter, not judged against anything
    delay = rows["assumed_loop_delay_s"]
    assert delay.basis == "parameter" and delay.within_tolerance is None
    assert not delay.counts_as_agreement
    outside = {row.name for row in repro.rows
               if row.basis == "predicted" and not row.within_tolerance}
    assert outside == KNOWN_DEPARTURES, [(n, rows[n].paper, rows[n].ours) for n in outside]
    counts = repro.agreement()
    predicted = [row for row in repro.rows if row.basis == "predicted"]
    assert counts["predicted_rows"] == len(predicted)
    assert counts["predicted_within_tolerance"] == len(predicted) - len(KNOWN_DEPARTURES)
    assert counts["fitted_rows"] == len(FITTED) and counts["parameters"] == 1
    # a fitted row never counts as agreement, even within its tolerance
    assert all(not rows[name].counts_as_agreement for name in FITTED)
    assert rows["k13_peak_force_N"].within_tolerance


def test_constant_rate_cut_is_steady(repro) -> None:
    """Issue 15: over the steady part of the cut, ripple <= 10 %, no reversal, 3.6 +- 0.4 N
    at 34-42 mm/s."""
    rows = {row.name: row for row in repro.rows}
    assert rows["cutting_force_ripple_ratio"].ours <= 0.10
    assert rows["cutting_velocity_reversals"].ours == 0
    assert rows["steady_cutting_force_N"].ours == pytest.approx(3.6, abs=0.4)
    assert 0.034 <= rows["steady_cutting_speed_m_s"].ours <= 0.042


def test_staircase_within_ten_percent_on_every_step(repro) -> None:
    for row in repro.rows:
        if row.name.startswith("variable_rate_velocity_m_s_"):
            assert row.ours == pytest.approx(row.paper, rel=0.10), row.name


def test_gain_experiment_is_explained_by_the_analysis(repro) -> None:
    """At the assumed delay the analysis calls k = 3 stable and k = 13, 19 unstable, as the
    traces show; its delay-independent bound is above the paper's k <= 5."""
    a = repro.analysis
    assert a["k3_delay_margin_sampled_s"] is None
    assert a["k19_delay_margin_sampled_s"] < a["k13_delay_margin_sampled_s"] < (
        repro.assumed_loop_delay_s)
    assert a["k_max_delay_independent_sampled"] > a["paper_k_bound"]


def test_report_files(repro, tmp_path) -> None:
    write_report(repro, tmp_path)
    for name in ("report.md", "report.json", "constant_force_time.png",
                 "constant_velocity_position.png", "constant_force_position.png",
                 "variable_velocity_position.png", "gain_force_time.png"):
        assert (tmp_path / name).stat().st_size > 0, name
    data = json.loads((tmp_path / "report.json").read_text())
    assert {row["name"] for row in data["rows"]} >= REQUIRED
    by_name = {row["name"]: row for row in data["rows"]}
    assert by_name["assumed_loop_delay_s"]["within_tolerance"] is None
    assert by_name["k13_peak_force_N"]["basis"] == "fitted"
    assert by_name["k13_peak_force_N"]["counts_as_agreement"] is False
    assert data["agreement"] == repro.agreement()
    markdown = report_markdown(repro)
    assert "| contact_time_s |" in markdown
    assert "| k13_peak_force_N | N | 20 |" in markdown and "| fitted |" in markdown
