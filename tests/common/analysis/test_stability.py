"""The exact delay analysis: root counts agree with polynomial roots, and the delay margin
agrees with a time-domain simulation of the same loop through a delay line."""

from __future__ import annotations

import warnings

import control
import numpy as np
import pytest
from scipy.signal import BadCoefficients

from haptic.common.analysis.linear_loop import LinearLoopSimulator, growth_ratio
from haptic.common.analysis.loop import AxisLoop, sample
from haptic.common.analysis.report import AnalysisSettings, analyse
from haptic.common.analysis.stability import (
    FrequencyGrid,
    delay_margin,
    is_stable,
    unstable_root_count,
)
from haptic.common.model.synthesis import synthesize_axis
from haptic.common.model.teleop import TeleopModel, tf_coefficients

GRID = FrequencyGrid(20000.0)


def loop_for(model: TeleopModel, k: float, sample_period_s: float | None = None,
             axis_index: int = 0) -> AxisLoop:
    gained = model.with_gain(k)
    axis = gained.axes[axis_index]
    return AxisLoop(axis, synthesize_axis(axis, gained.ch1), sample_period_s)


@pytest.mark.parametrize("spring_N_per_m", [6.0, -2.0, -40.0, -400.0])
@pytest.mark.parametrize("k", [1.0, 13.0])
def test_delay_free_root_count_matches_the_polynomial(paper_model, spring_N_per_m, k) -> None:
    """At tau = 0 Delta = 1 + U11 (Th + Tt); a negative operator spring can destabilise it.
    The argument principle must count exactly the right-half-plane roots of its numerator."""
    from dataclasses import replace

    axis = replace(paper_model.axes[0],
                   operator_impedance_th_N_per_m=np.array([0.25, 2.0, spring_N_per_m]))
    gained = paper_model.with_gain(k)
    compensators = synthesize_axis(axis, gained.ch1)
    num, den = tf_coefficients(axis.handle_actuator_gh * compensators.ch1)
    impedance = np.polyadd(axis.operator_impedance_th_N_per_m,
                           axis.environment_impedance_tt_N_per_m)
    characteristic = np.polyadd(den, np.polymul(num, impedance))
    expected = int(np.sum(np.roots(characteristic).real > 0))
    assert unstable_root_count(AxisLoop(axis, compensators), 0.0, GRID) == expected


def test_small_gains_are_stable_for_every_delay(paper_model) -> None:
    for k in (1.0, 3.0, 5.0):
        margin = delay_margin(loop_for(paper_model, k), 1.0, GRID)
        assert margin.stable_without_delay and margin.delay_independent
        assert margin.delay_margin_s is None
        assert is_stable(loop_for(paper_model, k), 0.5, GRID)


@pytest.mark.parametrize("k", [13.0, 19.0, 30.0])
def test_sampled_margin_matches_the_sampled_loop_simulation(paper_model, k) -> None:
    """The simulator runs the loop the sampled analysis describes, at Ts, so the verdicts
    must flip within a sample of the analytic margin."""
    ts = paper_model.sample_period_s
    loop = loop_for(paper_model, k, ts)
    margin = delay_margin(loop, 1.0, GRID).delay_margin_s
    assert margin is not None
    below = int(np.floor(0.95 * margin / ts))
    above = int(np.ceil(1.05 * margin / ts))
    simulator = LinearLoopSimulator(loop.axis, loop.compensators, ts)
    steps = int(5.0 / ts)
    pulse = np.zeros(steps)
    pulse[:20] = 1.0  # a 1 N, 10.8 ms push by the operator
    traces = simulator.run(pulse, np.array([below, above]))
    ratio = growth_ratio(traces.handle_force_N, int(1.0 / ts))
    assert ratio[0] < 0.5, f"k={k}: {below} samples should decay (ratio {ratio[0]:.3g})"
    assert ratio[1] > 2.0, f"k={k}: {above} samples should grow (ratio {ratio[1]:.3g})"


@pytest.mark.parametrize("k", [13.0, 19.0])
def test_continuous_margin_matches_a_finely_sampled_simulation(paper_model, k) -> None:
    """The default (continuous, exact delay) analysis against the same loop simulated at
    Ts/10, where sampling moves the margin by about 2 %: 10 % either side must flip."""
    dt = paper_model.sample_period_s / 10.0
    loop = loop_for(paper_model, k)
    margin = delay_margin(loop, 1.0, GRID).delay_margin_s
    assert margin is not None
    simulator = LinearLoopSimulator(loop.axis, loop.compensators, dt)
    steps = int(4.0 / dt)
    pulse = np.zeros(steps)
    pulse[:200] = 1.0
    traces = simulator.run(pulse, np.array([round(0.9 * margin / dt), round(1.1 * margin / dt)]))
    ratio = growth_ratio(traces.handle_force_N, int(1.0 / dt))
    assert ratio[0] < 0.5 and ratio[1] > 2.0, ratio


def test_gain_bounds_bracket_the_boundary(paper_model) -> None:
    settings = AnalysisSettings(max_gain_k=100.0)
    result = analyse(paper_model, 13.0, 0.02, settings)
    assert not result.stable  # the paper's k = 13 needs under about 18 ms
    assert result.k_max is not None and result.k_max < 13.0
    for axis in paper_model.axes:
        gained = paper_model.with_gain(result.k_max * 0.99)
        below = AxisLoop(axis, synthesize_axis(axis, gained.ch1))
        assert is_stable(below, 0.02, GRID)
    assert result.k_max_delay_independent is not None
    assert 5.0 < result.k_max_delay_independent < result.k_max
    k_di = result.k_max_delay_independent
    assert delay_margin(loop_for(paper_model, 0.99 * k_di), 1.0, GRID).delay_independent
    assert not delay_margin(loop_for(paper_model, 1.01 * k_di), 1.0, GRID).delay_independent


def test_eq30_cannot_hold_with_an_integrating_ch1(paper_model) -> None:
    result = analyse(paper_model, 1.0, 0.0, AnalysisSettings(max_gain_k=50.0))
    assert not result.eq30_satisfied
    assert all(axis.eq30_unbounded_at_low_frequency for axis in result.axes)
    assert result.stable


def test_a_free_tool_is_sampled_as_zero_without_a_warning(paper_model) -> None:
    """Tt = 0 (free space, the comparison's free-sine task): Pt is zero, and so is its
    sampled form, without SciPy's warning that a conversion of it may be meaningless; the
    loop's delayed term B = Ph Ct1 Pt Ch2 is then zero, and sampling a non-zero part is
    python-control's own."""
    axis = paper_model.axes[0].with_environment(np.array([0.0]))
    ts = paper_model.sample_period_s
    with warnings.catch_warnings():
        warnings.simplefilter("error", BadCoefficients)
        loop = AxisLoop(axis, synthesize_axis(axis, paper_model.ch1), ts)
        zero = sample(control.tf([0.0], [1.0]), ts, "zoh")
    assert zero.dt == ts and not np.any(tf_coefficients(zero)[0])
    s = 1j * np.array([1.0, 100.0, 1000.0]) + 1e-3
    terms = loop.terms_at(s)
    assert np.all(terms.b == 0.0) and np.all(np.isfinite(terms.a))
    plant = control.tf([1.0], [1.0, 2.0, 0.0])
    ours, theirs = sample(plant, ts, "zoh"), control.sample_system(plant, ts, method="zoh")
    for mine, reference in zip(tf_coefficients(ours), tf_coefficients(theirs), strict=True):
        np.testing.assert_array_equal(mine, reference)
