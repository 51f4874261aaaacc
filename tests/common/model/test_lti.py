"""Discrete blocks: discretisation matches the continuous response, lanes are independent."""

from __future__ import annotations

import numpy as np
import pytest

from haptic.common.model.lti import Path, combine, discretize
from haptic.common.model.teleop import evaluate_tf, tf


def discrete_response(block, omega: np.ndarray) -> np.ndarray:
    z = np.exp(1j * omega * block.period_s)
    response = []
    for point in z:
        resolvent = np.linalg.solve(point * np.eye(block.n_states) - block.A, block.B)
        response.append((block.C @ resolvent + block.D)[0, 0])
    return np.array(response)


@pytest.mark.parametrize("method", ["tustin", "zoh"])
def test_discretisation_keeps_the_frequency_response(method: str) -> None:
    system = tf([18.0, 1.0], [0.005, 0.4, 18.0, 1.0])
    block = discretize(system, 0.54e-3, method)
    omega = np.geomspace(0.1, 50.0, 30)
    continuous = evaluate_tf(system, 1j * omega)
    discrete = discrete_response(block, omega)
    assert np.allclose(20 * np.log10(np.abs(discrete)), 20 * np.log10(np.abs(continuous)),
                       atol=0.05)
    assert np.allclose(np.angle(discrete / continuous, deg=True), 0.0, atol=1.0)


def test_zoh_of_a_strictly_proper_plant_has_no_feedthrough() -> None:
    block = discretize(tf([1.0], [1.0, 100.0, 0.0]), 0.54e-3, "zoh")
    assert block.D[0, 0] == 0.0


def test_lanes_step_independently() -> None:
    block = discretize(tf([13.0], [1.0, 10.0, 0.0]), 0.54e-3, "tustin")
    rng = np.random.default_rng(4)
    inputs = rng.normal(size=(200, 3, 1))
    together = block.initial_state(3)
    outputs = np.array([block.step(together, u) for u in inputs])
    for lane in range(3):
        alone = block.initial_state(1)
        single = np.array([block.step(alone, u[lane:lane + 1]) for u in inputs])
        assert np.allclose(single[:, 0], outputs[:, lane], rtol=1e-12, atol=1e-15)


def test_combine_sums_signed_paths() -> None:
    ts = 1e-3
    first = discretize(tf([1.0], [1.0, 1.0]), ts, "tustin")
    second = discretize(tf([2.0], [1.0, 3.0]), ts, "tustin")
    both = combine([Path(first, 0, 0, 1.0), Path(second, 1, 0, -1.0)], ("a", "b"), ("y",))
    state_both = both.initial_state(1)
    state_1, state_2 = first.initial_state(1), second.initial_state(1)
    rng = np.random.default_rng(1)
    for _ in range(50):
        a, b = rng.normal(size=2)
        expected = first.step(state_1, np.array([[a]])) - second.step(state_2, np.array([[b]]))
        assert np.allclose(both.step(state_both, np.array([[a, b]])), expected)


def test_hold_state_is_an_equilibrium() -> None:
    block = discretize(tf([1.0, 2.0], [1.0, 3.0, 2.5]), 1e-3, "tustin")
    held = np.array([[0.7]])
    settled_output = np.array([[0.7 * 2.0 / 2.5]])  # DC gain 0.8
    state = block.hold_state(settled_output, held)
    before = state.copy()
    assert np.allclose(block.step(state, held), settled_output)
    assert np.allclose(state, before)
