"""The rig's and the operator's Warp kernels against an independent numpy oracle.

The oracle below is the rig block and the three operator models written with numpy array
calls, as :mod:`haptic.master.simulated_rig.rig_block` and
:mod:`haptic.master.simulated_rig.operator` document them
(the implementation the kernels replaced). Random targets (some non-finite), tool forces (some
NaN or infinite) and every operator kind must give the same samples and states.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from haptic.common.config import load_config
from haptic.common.model.teleop import model_from_config
from haptic.master.simulated_rig.operator import OperatorModel, parse_operator_spec
from haptic.master.simulated_rig.rig_block import RigModel


class ReferenceOperator:
    """The operator models' law in numpy, per lane (lanes first)."""

    def __init__(self, model: OperatorModel, lanes: int) -> None:
        self.model = model
        self.time_s = np.zeros(lanes)
        self.integral_N_s = np.zeros((lanes, 2))
        self.felt_N = np.zeros((lanes, 2))

    def _p(self, name: str) -> float:
        return float(self.model.params[name])

    def _envelope(self) -> np.ndarray:
        onset, rise = self._p("onset"), self._p("rise")
        if rise > 0.0:
            return np.clip((self.time_s - onset) / rise, 0.0, 1.0)[:, None]
        return (self.time_s >= onset).astype(float)[:, None]

    @np.errstate(over="ignore", invalid="ignore")
    def intent(self, offset: np.ndarray, velocity: np.ndarray, tool_force: np.ndarray,
               period_s: float) -> np.ndarray:
        kind = self.model.kind
        if kind == "constant":
            force = self._envelope() * np.array([self._p("fx"), self._p("fy")])
        elif kind == "regulate":
            envelope = self._envelope()
            target = np.array([self._p("fx"), self._p("fy")])
            lag = self._p("lag")
            alpha = 1.0 if lag == 0.0 else 1.0 - math.exp(-period_s / lag)
            self.felt_N += alpha * (np.nan_to_num(tool_force) - self.felt_N)
            error = target - self.felt_N
            limit = self._p("max")
            raw = target + self._p("kp") * error + self._p("ki") * self.integral_N_s
            limited = np.clip(raw, -limit, limit)
            pushing = (raw != limited) & (np.sign(error) == np.sign(raw))
            self.integral_N_s += np.where((envelope > 0.0) & ~pushing, error * period_s, 0.0)
            force = envelope * limited
        else:
            elapsed = np.maximum(self.time_s - self._p("onset"), 0.0)[:, None]
            started = (self.time_s >= self._p("onset"))[:, None]
            if self.model.params["shape"] == "ramp":
                rate = np.array([self._p("vx"), self._p("vy")])
                reference, reference_rate = rate * elapsed, np.where(started, rate, 0.0)
            else:
                amplitude = np.array([self._p("ax"), self._p("ay")])
                omega = 2.0 * math.pi * self._p("freq")
                reference = amplitude * np.sin(omega * elapsed)
                reference_rate = np.where(started, amplitude * omega * np.cos(omega * elapsed),
                                          0.0)
            force = np.clip(self._p("kp") * (reference - offset) + self._p("kd") * (
                reference_rate - velocity), -self._p("max"), self._p("max"))
        self.time_s = self.time_s + period_s
        return force


class ReferenceRig:
    """The rig block's step in numpy, on the rig's own matrices."""

    def __init__(self, rig: RigModel, start: np.ndarray) -> None:
        self.rig = rig
        self.plant = start @ rig._equilibrium
        self.applied = start / rig.dc_gains
        self.grasp = start.copy()
        self.operator = ReferenceOperator(rig.operator, start.shape[0])

    def step(self, target: np.ndarray, tool_force: np.ndarray) -> np.ndarray:
        rig = self.rig
        self.plant = self.plant @ rig.A.T + self.applied @ rig.B.T
        self.applied = np.where(np.isfinite(target), target, self.applied)
        position = self.plant @ rig.position_C.T
        velocity = self.plant @ rig.velocity_C.T + self.applied * rig.velocity_D
        acceleration = self.plant @ rig.acceleration_C.T + self.applied * rig.acceleration_D
        offset = position - self.grasp
        intent = self.operator.intent(offset, velocity, tool_force, rig.period_s)
        mass, damping, stiffness = rig.operator_impedance.T
        force = intent - (mass * acceleration + damping * velocity + stiffness * offset)
        return np.concatenate([position, velocity, acceleration, intent, force, force], axis=1)


OPERATORS = (
    "constant:fx=3,fy=-1,onset=0.01,rise=0.02",
    "constant:fx=2,fy=1,onset=0.005",
    "regulate:fx=3.6,fy=1,kp=0.5,ki=4,lag=0.01,max=5,onset=0.005,rise=0.01",
    "regulate:fx=2,fy=0,kp=2,ki=40,lag=0,max=3",
    "track:shape=ramp,vx=0.05,vy=-0.02,kp=200,kd=20,max=8,onset=0.01",
    "track:shape=sine,ax=0.01,ay=0.02,freq=3,kp=300,kd=10,max=6,onset=0.002",
)


@pytest.mark.parametrize("spec", OPERATORS)
def test_rig_kernel_matches_the_numpy_oracle(spec: str) -> None:
    model = model_from_config(load_config())
    rig = RigModel.from_model(model, parse_operator_spec(spec))
    rng = np.random.default_rng(abs(hash(spec)) % 2**32)
    lanes, steps = 4, 300
    start = rng.normal(0.0, 0.01, (lanes, 2))
    state = rig.initial_state(start, np.random.default_rng(0))
    oracle = ReferenceRig(rig, start)
    for _ in range(steps):
        target = start + rng.normal(0.0, 0.003, (lanes, 2))
        target[rng.random((lanes, 2)) < 0.05] = np.nan
        tool_force = rng.normal(0.0, 4.0, (lanes, 2))
        tool_force[rng.random((lanes, 2)) < 0.02] = np.nan
        tool_force[rng.random((lanes, 2)) < 0.02] = np.inf
        sample = rig.step(state, target, tool_force)
        expected = oracle.step(target, tool_force)
        got = np.concatenate([sample.handle_position_m, sample.handle_velocity_m_per_s,
                              sample.handle_acceleration_m_per_s2,
                              sample.operator_intent_force_N, sample.handle_force_N,
                              sample.handle_force_measured_N], axis=1)
        np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(state.plant, oracle.plant, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(state.operator.integral_N_s, oracle.operator.integral_N_s,
                               rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(state.operator.felt_tool_force_N, oracle.operator.felt_N,
                               rtol=1e-9, atol=1e-15)


def test_sensor_noise_is_the_seeded_generators_draws() -> None:
    model = model_from_config(load_config())
    rig = RigModel.from_model(model, parse_operator_spec("constant:fx=1"), 0.05)
    state = rig.initial_state(np.zeros((2, 2)), np.random.default_rng(11))
    draws = np.random.default_rng(11)
    for _ in range(20):
        sample = rig.step(state, np.full((2, 2), np.nan), np.zeros((2, 2)))
        noise = 0.05 * draws.standard_normal((2, 2))
        np.testing.assert_allclose(sample.handle_force_measured_N - sample.handle_force_N,
                                   noise, atol=1e-12)


def test_samples_returned_by_step_are_not_overwritten_by_the_next() -> None:
    model = model_from_config(load_config())
    rig = RigModel.from_model(model, parse_operator_spec("constant:fx=3"))
    state = rig.initial_state(np.zeros((1, 2)), np.random.default_rng(0))
    first = rig.step(state, np.array([[0.001, 0.0]]), np.zeros((1, 2)))
    kept = first.handle_position_m.copy()
    for _ in range(10):
        rig.step(state, np.array([[0.002, 0.0]]), np.zeros((1, 2)))
    np.testing.assert_array_equal(first.handle_position_m, kept)
