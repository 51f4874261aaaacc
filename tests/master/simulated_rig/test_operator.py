"""Operator models: spec parsing and the three scripted intents."""

from __future__ import annotations

import numpy as np
import pytest

from haptic.common.config import ConfigError
from haptic.common.config.operator_spec import check_operator_spec
from haptic.master.simulated_rig.operator import parse_operator_spec

TS = 0.00054


def test_specs_parse_with_defaults_and_overrides() -> None:
    constant = parse_operator_spec("constant:fx=3.0, fy=-1")
    assert constant.kind == "constant" and constant.params["fx"] == 3.0
    assert constant.params["fy"] == -1.0 and constant.params["onset"] == 0.0
    regulate = parse_operator_spec("regulate:fx=3.6")
    assert regulate.params["kp"] == 0.5 and regulate.params["fx"] == 3.6
    track = parse_operator_spec("track:shape=sine,ax=0.02,freq=1")
    assert track.params["shape"] == "sine"


@pytest.mark.parametrize("spec", [
    "push:fx=1", "constant:fz=1", "constant:fx", "constant:fx=abc", "constant:fx=nan",
    "regulate:lag=-0.1", "track:shape=square", "constant:onset=inf",
])
def test_bad_specs_raise_config_error_naming_the_key(spec: str) -> None:
    with pytest.raises(ConfigError) as caught:
        parse_operator_spec(spec, "master.sim.operator")
    assert caught.value.key == "master.sim.operator"
    assert check_operator_spec(spec) is not None


def _run(spec: str, steps: int, tool_force=None, offset=None, velocity=None) -> np.ndarray:
    model = parse_operator_spec(spec)
    state = model.initial_state(1)
    zeros = np.zeros((1, 2))
    forces = []
    for k in range(steps):
        ft = zeros if tool_force is None else tool_force(k, forces)
        forces.append(model.intent_force(state, zeros if offset is None else offset,
                                         zeros if velocity is None else velocity, ft, TS)[0])
    return np.array(forces)


def test_constant_force_starts_at_onset_and_ramps_over_rise() -> None:
    forces = _run("constant:fx=2,fy=-1,onset=0.01,rise=0.01", 200)
    onset, rise = round(0.01 / TS), 0.01 / TS
    assert np.all(forces[:onset - 1] == 0.0)
    mid = onset + int(rise / 2)
    assert forces[mid, 0] == pytest.approx(2.0 * (mid * TS - 0.01) / 0.01)
    np.testing.assert_allclose(forces[-1], [2.0, -1.0])


def test_regulating_operator_brings_the_felt_tool_force_to_the_target() -> None:
    # A toy environment: the tool force is half the operator's force, one sample late.
    def tool(k: int, history: list) -> np.ndarray:
        return 0.5 * history[-1][None, :] if history else np.zeros((1, 2))

    forces = _run("regulate:fx=3.6,fy=-1,kp=0.5,ki=4,lag=0.05,max=20", round(5.0 / TS), tool)
    np.testing.assert_allclose(0.5 * forces[-1], [3.6, -1.0], rtol=2e-3)


def test_regulating_operator_does_not_wind_up_against_its_limit() -> None:
    model = parse_operator_spec("regulate:fx=3.6,kp=0.5,ki=4,lag=0,max=5")
    state = model.initial_state(1)
    zeros = np.zeros((1, 2))
    for _ in range(round(2.0 / TS)):  # no contact: the felt force stays zero
        force = model.intent_force(state, zeros, zeros, zeros, TS)
    assert force[0, 0] == pytest.approx(5.0)
    integral_when_limited = state.integral_N_s[0, 0]
    assert integral_when_limited < 1.0  # it stopped integrating once at the limit
    # Contact: the felt force jumps over the target, the force comes off the limit at once.
    force = model.intent_force(state, zeros, zeros, np.array([[6.0, 0.0]]), TS)
    assert force[0, 0] < 5.0


def test_tracking_operator_is_a_spring_damper_towards_the_trajectory() -> None:
    model = parse_operator_spec("track:shape=ramp,vx=0.04,vy=-0.02,kp=200,kd=20,max=50")
    state = model.initial_state(2)
    offset = np.array([[0.0, 0.0], [0.001, 0.0]])
    velocity = np.array([[0.0, 0.0], [0.04, -0.02]])
    for _ in range(100):
        force = model.intent_force(state, offset, velocity, np.zeros((2, 2)), TS)
    t = 99 * TS
    expected0 = 200 * np.array([0.04, -0.02]) * t + 20 * np.array([0.04, -0.02])
    np.testing.assert_allclose(force[0], expected0)
    np.testing.assert_allclose(force[1], 200 * (np.array([0.04, -0.02]) * t - [0.001, 0.0]))
    sine = parse_operator_spec("track:shape=sine,ax=1,freq=1,kp=200,kd=0,max=30")
    state = sine.initial_state(1)
    forces = [sine.intent_force(state, np.zeros((1, 2)), np.zeros((1, 2)), np.zeros((1, 2)),
                                TS)[0, 0] for _ in range(round(0.5 / TS))]
    assert max(forces) == pytest.approx(30.0)  # limited to max
