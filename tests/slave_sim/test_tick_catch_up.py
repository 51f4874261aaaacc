"""A catch-up tick (several master samples, one node stage: ``SlaveTick.control_samples``)
leaves the node and the clay exactly where the same samples stepped one tick each leave them,
bit for bit: its earlier samples advance the node without building outputs
(``SlaveNode.advance``), its last one with them."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from haptic.common.config import load_config
from haptic.slave_sim.input_guard import InputGuard, InputGuardSettings
from haptic.slave_sim.node import SlaveNode
from haptic.slave_sim.supervisor import SlaveSupervisor
from haptic.slave_sim.tick import SlaveTick

STEPS = 240


@pytest.fixture(scope="module")
def node() -> SlaveNode:
    return SlaveNode.from_config(load_config())  # the shipped clay grid


def _tick(node: SlaveNode) -> SlaveTick:
    config = load_config()
    ratio = tuple(float(r) for r in node.position_ratio)
    tick = SlaveTick(node, node.initial_state(1),
                     [SlaveSupervisor(ratio, 0.001, (-1.0, 1.0, -1.0, 1.0), 1.0, 3)],
                     [InputGuard(InputGuardSettings.from_config(config), node.sample_period_s)])
    tick.start(synced=True)
    return tick


def _samples() -> list[tuple[float, float, float, float, float]]:
    """A push into the clay along x, the handle moving with it, the force ramp rising."""
    t = np.arange(STEPS) * 0.00054
    return [(float(8.0 + 2.0 * np.sin(40.0 * s)), float(0.5 * np.cos(30.0 * s)),
             float(0.02 * s), float(0.001 * np.sin(30.0 * s)), float(min(1.0, 0.5 + s)))
            for s in t]


def _clay(tick: SlaveTick) -> np.ndarray:
    heights = tick.state.environment.heights
    return np.array(heights.numpy() if hasattr(heights, "numpy") else heights)


def test_a_catch_up_tick_is_its_samples_stepped_one_by_one(node: SlaveNode) -> None:
    samples = _samples()
    one_by_one, bunched = _tick(node), _tick(node)
    singles, single_flags = [], []
    for sample in samples:  # the flags' array is the tick's own, refilled each step
        singles.append(one_by_one.control_samples([sample]))
        single_flags.append(int(singles[-1].flag_values[0]))
    groups, at = [], 0
    for size in itertools.cycle((1, 3, 2, 4, 1, 3)):  # 1 to 4 samples a tick
        if at >= STEPS:
            break
        groups.append(samples[at:at + size])
        at += size
    assert sum(len(group) for group in groups) == STEPS
    at = 0
    for group in groups:
        out = bunched.control_samples(group)
        at += len(group)
        single = singles[at - 1]
        for name in ("tool_position_m", "tool_velocity_m_s", "tool_force_N",
                     "actuator_force_N", "cutting", "engagement", "removed_volume_m3",
                     "tracking_error_m"):
            np.testing.assert_array_equal(getattr(out.out, name), getattr(single.out, name))
        assert int(out.flag_values[0]) == single_flags[at - 1]
    a, b = one_by_one.state, bunched.state
    assert a.step_count == b.step_count == STEPS
    for name in ("compensator", "tool", "tool_force_N", "actuator_force_N",
                 "handle_position_m", "halted"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert bool(np.any(np.asarray(singles[-1].out.removed_volume_m3) > 0)) or any(
        bool(s.out.cutting[0]) for s in singles)  # the tool cut: the clay took part
    np.testing.assert_array_equal(_clay(one_by_one), _clay(bunched))
