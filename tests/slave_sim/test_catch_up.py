"""The one-launch catch-up (slave_sim/catch_up.py) against its reference, ``SlaveNode.step``
once per sample: the outputs, the node's state and the clay bit for bit, for groups of 1 to
10 samples (more than one launch takes), a halted tool and a governed gain; and where the
launch cannot run the whole step (an active TDPA layer, a clay contact not yet started,
several lanes, the numpy clay) it says so."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from haptic.common.config import load_config, override
from haptic.slave_sim.catch_up import MAX_SAMPLES, CatchUpStep
from haptic.slave_sim.node import SlaveNode, SlaveOutputs, SlaveState

STEPS = 200
OUTPUTS = ("tool_position_m", "tool_velocity_m_s", "tool_force_N", "actuator_force_N",
           "cutting", "engagement", "removed_volume_m3", "tracking_error_m")


@pytest.fixture(scope="module")
def node() -> SlaveNode:
    return SlaveNode.from_config(load_config())  # the shipped clay grid, paper mode (drift)


def _samples(steps: int) -> list[tuple[float, float, float, float, float]]:
    """A push into the clay along x, the handle moving with it, the force ramp rising."""
    t = np.arange(steps) * 0.00054
    return [(float(8.0 + 2.0 * np.sin(40.0 * s)), float(0.5 * np.cos(30.0 * s)),
             float(0.02 * s), float(0.001 * np.sin(30.0 * s)), float(min(1.0, 0.5 + s)))
            for s in t]


def _reference_step(node: SlaveNode, state: SlaveState,
                    sample: tuple[float, float, float, float, float],
                    zero_force: bool) -> SlaveOutputs:
    fx, fy, yx, yy, scale = sample
    state.tool_force_scale = np.array([scale])
    force = np.zeros((1, 2)) if zero_force else np.array([[fx, fy]])
    return node.step(state, force, np.array([[yx, yy]]))


def _started(node: SlaveNode) -> SlaveState:
    """A state after its first step (the clay's contact placed)."""
    state = node.initial_state(1)
    _reference_step(node, state, (0.0, 0.0, 0.0, 0.0, 1.0), False)
    return state


def _assert_same_state(a: SlaveState, b: SlaveState) -> None:
    assert a.step_count == b.step_count
    for name in ("compensator", "tool", "tool_force_N", "actuator_force_N",
                 "handle_position_m", "halted", "drift"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    clay_a, clay_b = a.environment, b.environment
    np.testing.assert_array_equal(clay_a.heights_m(), clay_b.heights_m())
    np.testing.assert_array_equal(clay_a.removed_total_m3, clay_b.removed_total_m3)
    np.testing.assert_array_equal(clay_a.proxy_position_m(), clay_b.proxy_position_m())
    np.testing.assert_array_equal(clay_a.resistance_N_s_per_m(),
                                  clay_b.resistance_N_s_per_m())


def _run(node: SlaveNode, reference: SlaveState, fused: SlaveState, catch_up: CatchUpStep,
         groups: list[list[tuple[float, float, float, float, float]]],
         zero_force: bool = False) -> None:
    for group in groups:
        for sample in group:
            expected = _reference_step(node, reference, sample, zero_force)
        assert catch_up.applies(fused)
        fused.tool_force_scale = np.array([group[-1][4]])
        out = catch_up.step(fused, group, zero_force, np.array([group[-1][2:4]]))
        for name in OUTPUTS:
            np.testing.assert_array_equal(getattr(out, name), getattr(expected, name), name)
    _assert_same_state(reference, fused)


def _groups(samples: list, sizes: tuple[int, ...]) -> list[list]:
    groups, at = [], 0
    for size in itertools.cycle(sizes):
        if at >= len(samples):
            return groups
        groups.append(samples[at:at + size])
        at += size
    return groups


def test_one_launch_steps_as_the_node_steps_each_sample(node: SlaveNode) -> None:
    reference, fused = _started(node), _started(node)
    catch_up = CatchUpStep.of(node, fused)
    assert catch_up is not None
    samples = _samples(STEPS)
    _run(node, reference, fused, catch_up,
         _groups(samples, (1, 3, 2, 4, 1, MAX_SAMPLES + 2, 1)))
    assert float(reference.environment.removed_total_m3[0]) > 0.0  # the tool cut the clay


def test_a_halted_tool_and_a_governed_gain_step_as_the_node_steps_them(node: SlaveNode
                                                                        ) -> None:
    reference, fused = _started(node), _started(node)
    catch_up = CatchUpStep.of(node, fused)
    samples = _samples(120)
    _run(node, reference, fused, catch_up, _groups(samples[:40], (2, 1, 3)))
    for state in (reference, fused):
        state.gain_ratio = np.array([0.7])
    _run(node, reference, fused, catch_up, _groups(samples[40:80], (3, 1, 2)))
    for state in (reference, fused):
        node.safe_stop(state)
    _run(node, reference, fused, catch_up, _groups(samples[80:100], (1, 2, 3)),
         zero_force=True)
    for state in (reference, fused):
        node.resume(state)
    _run(node, reference, fused, catch_up, _groups(samples[100:], (4, 1)))


def test_the_launch_applies_only_where_it_runs_the_whole_step(node: SlaveNode) -> None:
    fresh = node.initial_state(1)
    catch_up = CatchUpStep.of(node, fresh)
    assert not catch_up.applies(fresh)  # the clay's first step places its proxy in Python
    started = _started(node)
    assert not catch_up.applies(started)  # another state's buffers
    assert CatchUpStep.of(node, node.initial_state(2)) is None
    tdpa = SlaveNode.from_config(override(load_config(), "control.mode", "tdpa"))
    state = tdpa.initial_state(1)
    _reference_step(tdpa, state, (0.0, 0.0, 0.0, 0.0, 1.0), False)
    assert not CatchUpStep.of(tdpa, state).applies(state)
    numpy_clay = SlaveNode.from_config(override(load_config(), "slave.clay_impl", "numpy"))
    assert CatchUpStep.of(numpy_clay, numpy_clay.initial_state(1)) is None
