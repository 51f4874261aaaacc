"""Every master sample delivered is stepped with its own force (slave_sim/pacing.py,
``SlaveTick.control_samples``): a slave that receives the master's messages bunched by jitter
ends in exactly the state of one that received them one per tick. Before, a tick stepped each
of its samples with the newest one's force, and the two drifted apart."""

from __future__ import annotations

import numpy as np
import pytest

from haptic.common.config import load_config
from haptic.common.config.scenario import load_scenario
from haptic.common.model.teleop import model_from_config
from haptic.common.wire.messages import Flags, HandleState
from haptic.slave_sim.input_guard import InputGuard, InputGuardSettings
from haptic.slave_sim.node import SlaveNode
from haptic.slave_sim.pacing import MasterSamplePacing, PacingSettings
from haptic.slave_sim.supervisor import SlaveSupervisor
from haptic.slave_sim.tick import SlaveTick

SAMPLES = 1200


@pytest.fixture(scope="module")
def setup():
    config = load_config()
    model = model_from_config(config)
    scenario = load_scenario("constant-rate")
    ts = model.sample_period_s
    start = np.asarray(scenario.tool.start_position_m, float)
    rng = np.random.default_rng(11)
    # a smooth push with noise on it, and the handle moving with it
    t = np.arange(SAMPLES) * ts
    force = np.column_stack((1.5 * np.sin(2 * np.pi * 2.0 * t), 0.8 * np.cos(2 * np.pi * 3.0 * t)))
    force += rng.normal(0.0, 0.2, force.shape)
    position = start + np.cumsum(force, axis=0) * 1e-6
    messages = [HandleState(7, seq, int(seq * ts * 1e9), Flags.FORCES_ENABLED,
                            tuple(force[seq]), tuple(position[seq])) for seq in range(SAMPLES)]
    return config, model, scenario, messages


def _slave(config, model, scenario) -> tuple[SlaveTick, MasterSamplePacing]:
    node = SlaveNode(model, scenario, "linear")
    ratio = tuple(float(a.position_ratio_ah1) for a in model.axes)
    start = np.asarray(scenario.tool.start_position_m, float)[None, :]
    ts = model.sample_period_s
    tick = SlaveTick(node, node.initial_state(1, start),
                     [SlaveSupervisor(ratio, 0.001, (-1.0, 1.0, -1.0, 1.0), 1.0, 3)],
                     [InputGuard(InputGuardSettings.from_config(config), ts)])
    tick.handle_position_m[...] = start / np.asarray(ratio)
    tick.start(synced=True)
    return tick, MasterSamplePacing(PacingSettings(True, 4, 32))


def _run(setup, groups: list[int], own_force: bool = True) -> SlaveTick:
    """Deliver the messages in ``groups`` (messages per tick, in order); step each tick's
    plan (with ``own_force`` False: every step with the tick's newest force, as before)."""
    config, model, scenario, messages = setup
    tick, pacing = _slave(config, model, scenario)
    ts = model.sample_period_s
    at = 0
    for index, size in enumerate(groups + [0] * 40):  # the ticks after drain the backlog
        delivered = messages[at:at + size]
        at += size
        now_s = index * ts
        tick.supervise(now_s, [delivered[-1] if delivered else None], [0.0], [True],
                       [delivered[:-1]])
        plan = pacing.plan(bool(tick.running[0]), tick.samples[0])
        if not own_force:
            plan = [None] * len(plan)
        if plan:
            tick.control_samples(plan)
    assert at == len(messages)
    return tick


def test_bunched_samples_end_exactly_where_one_per_tick_does(setup) -> None:
    rng = np.random.default_rng(4)
    groups = []
    while sum(groups) < SAMPLES:  # 0 to 3 messages per tick, as 2 ms of jitter delivers them
        groups.append(int(min(rng.integers(0, 4), SAMPLES - sum(groups))))
    assert max(groups) == 3 and groups.count(0) > 50
    steady = _run(setup, [1] * SAMPLES)
    bunched = _run(setup, groups)
    assert bunched.state.step_count == steady.state.step_count == SAMPLES
    np.testing.assert_allclose(bunched.state.compensator, steady.state.compensator,
                               rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(bunched.state.tool, steady.state.tool, rtol=1e-12, atol=1e-15)
    # stepped with the newest force, as before: the same count, a different tool
    newest = _run(setup, groups, own_force=False)
    assert newest.state.step_count == SAMPLES
    moved_m = np.abs(steady.state.tool_position_m()[0]
                     - np.asarray(setup[2].tool.start_position_m)).max()
    drift_m = np.abs(newest.state.tool_position_m()[0] - steady.state.tool_position_m()[0]).max()
    print(f"moved {moved_m * 1e3:.3f} mm, newest-force drift {drift_m * 1e3:.4f} mm")
    assert drift_m > 0.01 * moved_m
