"""The in-process rig block: ZOH axis dynamics, the timing contract, the operator force."""

from __future__ import annotations

import control
import numpy as np
import pytest

from haptic.common.config import load_config
from haptic.common.model.lti import discretize
from haptic.common.model.teleop import model_from_config
from haptic.master.simulated_rig.operator import parse_operator_spec
from haptic.master.simulated_rig.rig_block import RigModel


@pytest.fixture(scope="module")
def model():
    return model_from_config(load_config())


def _rig(model, spec: str = "constant:fx=0,fy=0", noise: float = 0.0) -> RigModel:
    return RigModel.from_model(model, parse_operator_spec(spec), noise)


def _gh(model, axis: str, omega: np.ndarray) -> np.ndarray:
    gh = model.axis(axis).handle_actuator_gh
    return np.array([complex(control.evalfr(gh, 1j * w)) for w in omega])


def test_discretised_axes_match_gh_within_1_db_and_5_degrees_to_50_rad_s(model) -> None:
    rig = _rig(model)
    omega = np.logspace(-2, np.log10(50.0), 200)
    response = rig.frequency_response(omega)
    for index, axis in enumerate("xy"):
        ratio = response[index] / _gh(model, axis, omega)
        assert np.max(np.abs(20 * np.log10(np.abs(ratio)))) < 1.0
        assert np.max(np.abs(np.degrees(np.angle(ratio)))) < 5.0
        # The same plant as the shared ZOH discretisation of Gh.
        shared = discretize(model.axis(axis).handle_actuator_gh, model.sample_period_s, "zoh")
        z = np.exp(1j * omega * model.sample_period_s)
        shared_response = np.array([
            (shared.C @ np.linalg.solve(zi * np.eye(shared.n_states) - shared.A, shared.B)
             + shared.D)[0, 0] for zi in z])
        np.testing.assert_allclose(response[index], shared_response, rtol=1e-6)


def test_simulated_sinusoids_match_gh_within_1_db_and_5_degrees(model) -> None:
    """Drive the block itself with sine commands, one lane per frequency, and fit."""
    rig = _rig(model)
    omega = np.array([1.0, 3.0, 10.0, 20.0, 35.0, 50.0])
    ts = model.sample_period_s
    steps = round(9.0 / ts)
    state = rig.initial_state(np.zeros((omega.size, 2)), np.random.default_rng(0))
    amplitude_m = 0.001
    window = round(2 * np.pi / omega[0] / ts)  # one period of the slowest sine
    times = np.arange(steps) * ts
    positions = np.empty((window, omega.size, 2))
    zero_force = np.zeros((omega.size, 2))
    for k in range(steps):
        target = amplitude_m * np.sin(omega * times[k])[:, None] * np.ones((1, 2))
        sample = rig.step(state, target, zero_force)
        if k >= steps - window:
            positions[k - (steps - window)] = sample.handle_position_m
    t = times[steps - window:]
    for lane, w in enumerate(omega):
        # Regress on sin, cos and a slow drift (the nearly cancelled pole at -1/18 rad/s).
        basis = np.column_stack([np.sin(w * t), np.cos(w * t), np.ones_like(t), t])
        for index, axis in enumerate("xy"):
            coefficients = np.linalg.lstsq(basis, positions[:, lane, index], rcond=None)[0]
            measured = complex(coefficients[0], coefficients[1]) / amplitude_m
            expected = _gh(model, axis, np.array([w]))[0]
            ratio = measured / expected
            assert abs(20 * np.log10(abs(ratio))) < 1.0, (axis, w)
            assert abs(np.degrees(np.angle(ratio))) < 5.0, (axis, w)


def test_initial_state_holds_its_position(model) -> None:
    rig = _rig(model)
    start = np.array([[0.01, -0.02], [0.0, 0.05]])
    state = rig.initial_state(start, np.random.default_rng(0))
    for _ in range(100):
        sample = rig.step(state, start, np.zeros((2, 2)))
    np.testing.assert_allclose(sample.handle_position_m, start, atol=1e-12)
    np.testing.assert_allclose(sample.handle_force_N, 0.0, atol=1e-9)


def test_a_target_acts_from_its_sync_and_shows_in_position_one_sample_later(model) -> None:
    rig = _rig(model)
    state = rig.initial_state(np.zeros((1, 2)), np.random.default_rng(0))
    zeros = np.zeros((1, 2))
    rig.step(state, zeros, zeros)
    step = np.array([[0.001, 0.0]])
    sample_k = rig.step(state, step, zeros)
    # Position and velocity at t_k do not depend on the target applied from t_k ...
    assert sample_k.handle_position_m[0, 0] == 0.0
    assert sample_k.handle_velocity_m_per_s[0, 0] == 0.0
    # ... the acceleration does (Gh has relative degree 2): that is what the arm feels.
    assert sample_k.handle_acceleration_m_per_s2[0, 0] > 0.0
    sample_next = rig.step(state, step, zeros)
    assert sample_next.handle_position_m[0, 0] > 0.0
    assert sample_next.handle_position_m[0, 1] == 0.0


def test_operator_force_is_intent_minus_arm_impedance(model) -> None:
    rig = _rig(model, "constant:fx=2,fy=-1")
    state = rig.initial_state(np.array([[0.01, 0.02]]), np.random.default_rng(0))
    zeros = np.zeros((1, 2))
    for k in range(50):
        sample = rig.step(state, np.array([[0.01 + 1e-5 * k, 0.02]]), zeros)
    th = model.axis("x").operator_impedance_th_N_per_m  # [0.25, 2, 6]
    expected = 2.0 - (th[0] * sample.handle_acceleration_m_per_s2[0, 0]
                      + th[1] * sample.handle_velocity_m_per_s[0, 0]
                      + th[2] * (sample.handle_position_m[0, 0] - 0.01))
    assert sample.handle_force_N[0, 0] == pytest.approx(expected)
    assert sample.handle_force_N[0, 1] == pytest.approx(-1.0)
    np.testing.assert_array_equal(sample.operator_intent_force_N, [[2.0, -1.0]])


def test_sensor_noise_is_seeded_and_has_the_configured_spread(model) -> None:
    def run(seed: int) -> np.ndarray:
        rig = _rig(model, noise=0.2)
        state = rig.initial_state(np.zeros((1, 2)), np.random.default_rng(seed))
        zeros = np.zeros((1, 2))
        return np.array([rig.step(state, zeros, zeros).handle_force_measured_N[0]
                         for _ in range(4000)])

    first, again, other = run(1), run(1), run(2)
    np.testing.assert_array_equal(first, again)
    assert not np.array_equal(first, other)
    assert np.std(first) == pytest.approx(0.2, rel=0.05)


def test_non_finite_target_keeps_the_applied_command(model) -> None:
    rig = _rig(model)
    state = rig.initial_state(np.zeros((1, 2)), np.random.default_rng(0))
    rig.step(state, np.array([[0.002, 0.0]]), np.zeros((1, 2)))
    rig.step(state, np.array([[np.nan, np.inf]]), np.zeros((1, 2)))
    np.testing.assert_array_equal(state.applied_command_m, [[0.002, 0.0]])


def test_rig_refuses_an_improper_or_integrating_gh() -> None:
    operator = parse_operator_spec("constant")
    impedance = [[0.25, 2.0, 6.0]] * 2
    with pytest.raises(ValueError, match="strictly proper"):
        RigModel([control.tf([1.0], [1.0]), control.tf([1.0], [1.0, 1.0])], impedance,
                 0.001, operator)
    with pytest.raises(ValueError, match="pole at s = 0"):
        RigModel([control.tf([1.0], [1.0, 0.0]), control.tf([1.0], [1.0, 1.0])], impedance,
                 0.001, operator)


def _lockstep_closed_loop_error(model, divisor: int) -> float:
    """Max deviation (m) of the lockstep rig + master node from the continuous closed loop
    Gh Ch1 / (1 + Gh Ch1 Th) for a ramped constant operator force, at Ts / divisor."""
    import dataclasses

    from haptic.master.node import MasterNode
    from haptic.master.settings import master_settings

    model = dataclasses.replace(model, sample_period_s=model.sample_period_s / divisor)
    safety = dataclasses.replace(master_settings(load_config()).safety, ramp_time_s=0.0)
    node = MasterNode.from_model(model, safety)
    rig = _rig(model, "constant:fx=0.6,fy=0,onset=0.05,rise=0.05")
    rig_state = rig.initial_state(np.zeros((1, 2)), np.random.default_rng(0))
    node_state = node.initial_state(np.zeros((1, 2)))
    command = np.zeros((1, 2))
    ts = model.sample_period_s
    steps = round(0.6 / ts)
    positions = np.empty(steps)
    for k in range(steps):
        sample = rig.step(rig_state, command, np.zeros((1, 2)))
        command = node.step(node_state, sample.handle_force_measured_N,
                            sample.handle_position_m, np.zeros((1, 2)))
        positions[k] = sample.handle_position_m[0, 0]
    times = np.arange(steps) * ts
    parts = model.axis("x")
    closed = control.feedback(parts.handle_actuator_gh * model.ch1,
                              control.tf(parts.operator_impedance_th_N_per_m, [1.0]))
    intent = 0.6 * np.clip((times - 0.05) / 0.05, 0.0, 1.0)
    _, predicted = control.forced_response(closed, times, intent)
    return float(np.max(np.abs(positions - predicted)))


def test_lockstep_closed_loop_converges_to_the_continuous_model_as_ts_shrinks(model) -> None:
    coarse = _lockstep_closed_loop_error(model, 1)
    fine = _lockstep_closed_loop_error(model, 4)
    assert coarse < 5e-4
    assert 3.0 < coarse / fine < 5.0  # first order in Ts
