"""The slave node's Warp kernels (slave_sim/node_kernels.py) against a numpy statement of the
same law: the compensators, the drift coupling, the safe state, the tool plant, the work
area's wall and the linear environment, lane by lane, with per-lane compensators and block
layouts the kernels must pad."""

from __future__ import annotations

import numpy as np
import pytest

from haptic.common.config import load_config
from haptic.common.config.scenario import load_scenario
from haptic.common.model.block_layout import CompensatorLayout, diagonal_blocks
from haptic.common.model.drift import DriftCoupling
from haptic.common.model.lti import DiscreteLTI, Path, combine
from haptic.common.model.teleop import model_from_config
from haptic.lockstep.simulator import stacked_compensators
from haptic.slave_sim.node import SlaveNode
from haptic.slave_sim.tool import POSITION_COLUMNS, VELOCITY_COLUMNS, tool_constants

LOW_M, HIGH_M = (-0.02, -0.015), (0.03, 0.012)


@pytest.fixture(scope="module")
def model():
    return model_from_config(load_config())


class Oracle:
    """The slave node's step without a TDPA layer, in numpy, as it was written before the
    kernels (SI units; every array (lanes, .))."""

    def __init__(self, node: SlaveNode, start_m: np.ndarray) -> None:
        lanes = start_m.shape[0]
        self.node = node
        self.compensator = np.zeros((lanes, node.compensators.A.shape[-1]))
        self.tool = np.zeros((lanes, 4))
        self.tool[:, POSITION_COLUMNS] = start_m
        self.tool_force_N = np.zeros((lanes, 2))
        self.drift = np.zeros((lanes, 4))
        mass, self.damping, self.stiffness = tool_constants(node.model)
        self.inv_mass = 1.0 / mass

    def step(self, handle_force_N: np.ndarray, handle_position_m: np.ndarray,
             halted: np.ndarray, scale: np.ndarray, gain: np.ndarray) -> np.ndarray:
        node = self.node
        inputs = np.concatenate((handle_force_N, self.tool_force_N), axis=1)
        inputs[:, 2:4] *= scale[:, None]
        inputs *= gain[:, None]
        actuator = node.compensators.step(self.compensator, inputs)
        if node.drift is not None:
            actuator += node.drift.force(self.drift, node.position_ratio * handle_position_m
                                         - self.tool[:, POSITION_COLUMNS])
        actuator[halted] = 0.0
        held = self.tool.copy()
        self.tool = self.tool @ node.plant.A.T + actuator @ node.plant.B.T
        self.tool[halted] = held[halted]
        low, high = np.array(LOW_M), np.array(HIGH_M)
        position = self.tool[:, POSITION_COLUMNS]
        velocity = self.tool[:, VELOCITY_COLUMNS]
        into_wall = ((position < low) & (velocity < 0.0)) | ((position > high) & (velocity > 0.0))
        velocity[into_wall] = 0.0
        self.tool[:, POSITION_COLUMNS] = np.clip(position, low, high)
        self.tool[:, VELOCITY_COLUMNS] = velocity
        position = self.tool[:, POSITION_COLUMNS]
        acceleration = (actuator - self.damping * velocity - self.stiffness * position) * (
            self.inv_mass)
        c = node.environment.coefficients
        force = c[0] * acceleration + c[1] * velocity + c[2] * position
        force[halted] = 0.0
        self.tool_force_N = force
        return actuator


def _run_both(node: SlaveNode, steps: int, seed: int, reaches_wall: bool = True) -> None:
    """Step ``node`` and the oracle on the same random inputs (pushes towards the wall,
    halted lanes, force ramps, gain ratios, a non-finite handle position) and compare;
    ``reaches_wall``: the paper's compensators carry the pushes to the wall."""
    rng = np.random.default_rng(seed)
    lanes = node.compensators.A.shape[0] if np.ndim(node.compensators.A) == 3 else 6
    start = rng.uniform(-0.01, 0.01, (lanes, 2))
    state = node.initial_state(lanes, start)
    oracle = Oracle(node, start)
    state.tool_force_scale = np.ones(lanes)
    state.gain_ratio = np.ones(lanes)
    push_N = rng.choice([-20.0, 20.0], (lanes, 2))  # a push per lane, towards a wall
    walls = 0
    for step in range(steps):
        force = push_N + rng.normal(0.0, 4.0, (lanes, 2))
        position = state.tool[:, POSITION_COLUMNS] / node.position_ratio + rng.normal(
            0.0, 1e-3, (lanes, 2))
        if step == steps // 2:
            position[0, 1] = np.nan  # the drift coupling takes it as no gap
        state.halted[...] = rng.random(lanes) < 0.2
        state.tool_force_scale[...] = rng.uniform(0.0, 1.0, lanes)
        state.gain_ratio[...] = rng.uniform(0.5, 1.0, lanes)
        out = node.step(state, force, position)
        actuator = oracle.step(force, position, state.halted.copy(), state.tool_force_scale,
                               state.gain_ratio)
        np.testing.assert_allclose(out.actuator_force_N, actuator, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(state.tool, oracle.tool, rtol=1e-9, atol=1e-14)
        np.testing.assert_allclose(out.tool_force_N, oracle.tool_force_N, rtol=1e-9,
                                   atol=1e-12)
        walls += int(np.any((oracle.tool[:, POSITION_COLUMNS] == LOW_M)
                            | (oracle.tool[:, POSITION_COLUMNS] == HIGH_M)))
    if reaches_wall:  # the wall's clamp was exercised
        assert walls > steps // 10


def test_the_kernels_step_the_law_of_the_numpy_statement(model) -> None:
    scenario = load_scenario("constant-rate")
    drift = DriftCoupling(200.0, 5.0, model.sample_period_s)
    node = SlaveNode(model, scenario, "linear", drift=drift, tool_bounds_m=(LOW_M, HIGH_M))
    _run_both(node, 400, seed=1)


def test_per_lane_compensators_step_their_own_lane(model) -> None:
    """The lockstep's lanes: one compensator per lane (different k), stacked."""
    scenario = load_scenario("constant-rate")
    node = SlaveNode(model, scenario, "linear", tool_bounds_m=(LOW_M, HIGH_M))
    node.compensators = stacked_compensators(model, np.array([3.0, 8.0, 13.0, 19.0, 30.0]))[1]
    _run_both(node, 300, seed=2)


def _siso(order: int, rng: np.random.Generator, period_s: float) -> DiscreteLTI:
    """A stable SISO block of ``order`` states."""
    a = np.diag(rng.uniform(0.2, 0.9, order)) + np.triu(rng.normal(0.0, 0.1, (order, order)), 1)
    return DiscreteLTI(A=a, B=rng.normal(0.0, 1.0, (order, 1)), C=rng.normal(0.0, 1.0, (1, order)),
                       D=rng.normal(0.0, 1.0, (1, 1)), period_s=period_s,
                       input_names=("u",), output_names=("y",))


def test_blocks_of_different_orders_are_padded(model) -> None:
    """Paths of orders 2, 3, 1 and 5 (a layout of four blocks of five states, padded): the
    node steps what the dense matrices give."""
    rng = np.random.default_rng(3)
    ts = model.sample_period_s
    block = combine([Path(_siso(2, rng, ts), 0, 0, -1.0), Path(_siso(3, rng, ts), 2, 0),
                     Path(_siso(1, rng, ts), 1, 1, -1.0), Path(_siso(5, rng, ts), 3, 1)],
                    ("fh_x", "fh_y", "ft_x", "ft_y"), ("vt_x", "vt_y"))
    layout, packed, state_of = CompensatorLayout.of(block.A[None], block.B[None],
                                                    block.C[None], block.D[None])
    assert layout == CompensatorLayout(blocks=4, block_states=5)
    assert sorted(state_of[state_of >= 0].tolist()) == list(range(11))
    assert packed[0].shape == (1, 4, 5, 5)
    node = SlaveNode(model, load_scenario("constant-rate"), "linear",
                     tool_bounds_m=(LOW_M, HIGH_M))
    node.compensators = block
    _run_both(node, 200, seed=4, reaches_wall=False)


def test_diagonal_blocks_split_only_where_nothing_couples() -> None:
    pattern = np.zeros((6, 6), bool)
    pattern[0:2, 0:2] = True
    pattern[2, 2] = True
    pattern[3:6, 3:6] = True
    assert diagonal_blocks(pattern) == [(0, 2), (2, 3), (3, 6)]
    pattern[5, 0] = True  # a coupling from the first block to the last joins everything
    assert diagonal_blocks(pattern) == [(0, 6)]
    assert diagonal_blocks(np.zeros((3, 3), bool)) == [(0, 1), (1, 2), (2, 3)]
