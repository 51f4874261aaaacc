"""The tool's wall (SlaveNode, issue 16): the tool stays inside the work area both sides
hold, as the master's handle command is clamped to the same box, so at a bound both stop at
the same place."""

from __future__ import annotations

import numpy as np
import pytest

from haptic.common.config import load_config
from haptic.common.config.scenario import load_scenario
from haptic.slave_sim.node import SlaveNode

PUSH_N = 5.0


def _node(paper_model, bounds) -> SlaveNode:
    return SlaveNode(paper_model, load_scenario("constant-rate"), "linear", device="cpu",
                     tool_bounds_m=bounds)


def _push(node: SlaveNode, state, force_x_N: float, force_y_N: float, steps: int) -> np.ndarray:
    positions = []
    for _ in range(steps):
        out = node.step(state, np.array([[force_x_N, force_y_N]]), state.handle_position_m)
        positions.append(out.tool_position_m[0].copy())
    return np.array(positions)


def test_a_pushed_tool_stops_on_the_wall_and_leaves_it_at_once(paper_model) -> None:
    node = _node(paper_model, ((-0.01, -0.03), (0.02, 0.03)))
    state = node.initial_state(1, np.array([0.0, 0.0]))
    path = _push(node, state, PUSH_N, 0.0, 4000)
    assert path[:, 0].max() == 0.02  # exactly on the wall, never past it
    reached = int(np.argmax(path[:, 0] == 0.02))
    assert reached < 3900 and np.all(path[reached:, 0] == 0.02)
    assert state.tool[0, 1] == 0.0  # no velocity into the wall
    # the operator pulls back: the tool leaves the wall in the step its actuator force turns
    # (Ch2's own dynamics decide when), never held there by the wall
    actuator, position = [], []
    for _ in range(3000):
        out = node.step(state, np.array([[-PUSH_N, 0.0]]), state.handle_position_m)
        actuator.append(out.actuator_force_N[0, 0])
        position.append(out.tool_position_m[0, 0])
    turned = int(np.argmax(np.array(actuator) < 0.0))
    assert actuator[turned] < 0.0
    assert np.all(np.array(position[:turned]) == 0.02)
    assert position[turned] < 0.02 and position[-1] < 0.0


def test_each_wall_of_both_axes_holds(paper_model) -> None:
    low, high = (-0.01, -0.03), (0.02, 0.03)
    node = _node(paper_model, (low, high))
    for force, index, bound in ((-PUSH_N, 0, low[0]), (PUSH_N, 0, high[0])):
        state = node.initial_state(1, np.array([0.0, 0.0]))
        path = _push(node, state, force, 0.0, 3000)
        assert path[-1, index] == bound and state.tool[0, 1] == 0.0
    for force, bound in ((-PUSH_N, low[1]), (PUSH_N, high[1])):
        state = node.initial_state(1, np.array([0.0, 0.0]))
        path = _push(node, state, 0.0, force, 4000)
        assert path[-1, 1] == bound and state.tool[0, 3] == 0.0


def test_without_bounds_the_tool_passes_where_the_wall_would_be(paper_model) -> None:
    node = _node(paper_model, None)
    state = node.initial_state(1, np.array([0.0, 0.0]))
    path = _push(node, state, PUSH_N, 0.0, 4000)
    assert path[-1, 0] > 0.03


def test_a_lane_on_its_wall_leaves_the_other_lanes_alone(paper_model) -> None:
    node = _node(paper_model, ((-0.01, -0.03), (0.02, 0.03)))
    state = node.initial_state(2, np.array([[0.019, 0.0], [0.0, 0.0]]))
    for _ in range(200):
        node.step(state, np.array([[PUSH_N, 0.0], [PUSH_N, 0.0]]), state.handle_position_m)
    assert state.tool[0, 0] == 0.02 and state.tool[0, 1] == 0.0
    assert 0.0 < state.tool[1, 0] < 0.02 and state.tool[1, 1] > 0.0


def test_the_configured_node_holds_the_shared_work_area() -> None:
    node = SlaveNode.from_config(load_config(), load_scenario("constant-rate"))
    low, high = node.tool_bounds_m
    assert low == pytest.approx([-0.01, -0.03]) and high == pytest.approx([0.15, 0.03])
