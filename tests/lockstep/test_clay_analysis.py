"""The clay linearised about steady cutting (common/model/clay_contact.py) against the simulated
clay loop: below the predicted delay margin the cut's oscillation decays, above it it does
not; and the per-block analysis of ``haptic-analyze --environment clay``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from haptic.common.analysis.clay import clay_block_stability, clay_model, workpiece_bounds
from haptic.common.analysis.cli import main as analyze_main
from haptic.common.analysis.report import AnalysisSettings, analyse
from haptic.common.config.scenario import load_scenario
from haptic.common.model.clay_contact import clay_impedance, passivity_margin_N_s_per_m
from haptic.lockstep.simulator import TRANSPARENT_SAFETY, LockstepSimulator
from haptic.lockstep.sweep import (
    CLAY_GROWTH_THRESHOLD,
    CLAY_OPERATOR,
    analytic_margin_s,
    sweep_model,
)
from haptic.lockstep.verdict import growth_verdict
from haptic.master.simulated_rig.operator import parse_operator_spec


def test_clay_impedance_is_b_s_at_low_frequency_and_softer_above() -> None:
    num, den = clay_impedance(100.0)
    s = 1j * np.array([1e-3, 66.0])
    tt = np.polyval(num, s) / np.polyval(den, s)
    assert tt[0] == pytest.approx(100.0 * s[0], rel=1e-4)  # the paper's viscous clay
    # at the loop's oscillation frequency the damping (Re Tt / w) is below B
    assert (tt[1] / s[1]).real < 0.9 * 100.0
    assert passivity_margin_N_s_per_m(100.0, 0.00054) == pytest.approx(100 - 0.54 - 50)


@pytest.mark.parametrize("damping_N_s_per_m", [0.0, 1.0, 20.0])
def test_clay_impedance_coefficients_and_no_clay(damping_N_s_per_m) -> None:
    """No clay (B = 0) renders no force: the polynomial pair 0 / 1; any B > 0, even 1 N s/m,
    is the series damper-spring-damper B s (K + b s) / (K + (B + b) s)."""
    num, den = clay_impedance(damping_N_s_per_m, 2000.0, 50.0)
    if damping_N_s_per_m == 0.0:
        assert (num.tolist(), den.tolist()) == ([0.0], [1.0])
        return
    c = damping_N_s_per_m
    assert num.tolist() == [c * 50.0, c * 2000.0, 0.0]
    assert den.tolist() == [c + 50.0, 2000.0]


def test_the_proxy_contact_stabilises_the_paper_loop_at_k_1(paper_model) -> None:
    """The plain damper B s has a 12 ms margin at k = 1 and no stable k above 1.25; the
    contact's linearisation is stable for every delay at k = 1."""
    settings = AnalysisSettings()
    damper = sweep_model(paper_model, "linear")
    axes = tuple(axis.with_environment(np.array([100.0, 0.0])) for axis in damper.axes)
    plain = analyse(type(paper_model)(paper_model.sample_period_s, 1.0, paper_model.ch1_num,
                                      paper_model.ch1_den, axes), 1.0, 0.0, settings)
    contact = analyse(clay_model(paper_model, 100.0), 1.0, 0.0, settings)
    assert plain.delay_margin_s == pytest.approx(0.0122, rel=0.02)
    assert contact.stable and contact.delay_margin_s is None
    assert contact.k_max > 2.5 * plain.k_max


def test_simulated_clay_decays_below_the_margin_and_not_above(paper_model) -> None:
    """k = 2: sampled margin 9.3 ms. The cut's handle-force oscillation decays at 2 ms (far
    below) and is sustained at 14 ms (above: the contact opens and closes in a limit cycle,
    the one-sided clay's form of growth)."""
    ts = paper_model.sample_period_s
    margin = analytic_margin_s(sweep_model(paper_model, "clay"), 2.0, ts)
    assert margin == pytest.approx(0.0093, rel=0.02)
    below, above = int(round(0.002 / ts)), int(round(0.014 / ts))
    simulator = LockstepSimulator(paper_model, load_scenario("constant-rate"),
                                  parse_operator_spec(CLAY_OPERATOR), np.array([2.0, 2.0]),
                                  "clay", TRANSPARENT_SAFETY, device="cpu")
    result = simulator.run(2.25, np.array([below, above]))
    verdict = growth_verdict(result, 1.0, CLAY_GROWTH_THRESHOLD)
    assert verdict.energy_ratio[0] < 0.1
    assert verdict.energy_ratio[1] > CLAY_GROWTH_THRESHOLD
    assert list(verdict.growing) == [False, True]


def test_per_block_analysis_orders_the_blocks(paper_model) -> None:
    blocks = [("p100", 100.0), ("p20", 20.0), ("air", 0.0)]
    result = clay_block_stability(paper_model, blocks, 1.0, 0.0, AnalysisSettings())
    assert [b.block for b in result] == ["p100", "p20"]  # no clay, nothing to analyse
    stiff, soft = result
    assert stiff.k_max_delay_independent < soft.k_max_delay_independent
    assert stiff.k_max < soft.k_max
    bounds = workpiece_bounds(result)
    assert bounds["k_max"] == stiff.k_max and bounds["stable"]


def test_analyze_cli_environment_clay(capsys) -> None:
    assert analyze_main(["--environment", "clay", "--scenario", "constant-rate", "--k", "2",
                         "--round-trip-delay", "0.012", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    (block,) = data["blocks"]
    assert block["damping_N_s_per_m"] == 100.0
    assert not block["stable"]  # continuous margin at k = 2 is about 10 ms
    assert 0.008 < block["delay_margin_s"] < 0.012
    assert data["workpiece"]["stable"] is False
    assert analyze_main(["--environment", "clay", "--scenario", "constant-rate"]) == 0
    assert "workpiece: STABLE" in capsys.readouterr().out
    with pytest.raises(SystemExit) as error:
        analyze_main(["--scenario", "constant-rate"])
    assert error.value.code == 2
