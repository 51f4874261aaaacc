"""The slave's node part per node step (``SlaveTick.note_node_time``, the program's summary's
``node_times``): every tick counted by its node steps, the time split over them."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from haptic.common.config import load_config
from haptic.common.config.scenario import load_scenario
from haptic.common.model.teleop import model_from_config
from haptic.common.runtime.stage_times import StepSplitTimes
from haptic.common.wire.messages import Flags, HandleState
from haptic.slave_sim.input_guard import InputGuard, InputGuardSettings
from haptic.slave_sim.node import SlaveNode
from haptic.slave_sim.pacing import MasterSamplePacing, PacingSettings
from haptic.slave_sim.supervisor import SlaveSupervisor
from haptic.slave_sim.tick import SlaveLaneInputs, SlaveTick


def test_split_times_per_step_and_by_steps() -> None:
    times = StepSplitTimes()
    for steps, duration_ns in ((0, 2_000), (1, 40_000), (1, 60_000), (3, 150_000)):
        times.record(steps, duration_ns)
    summary = times.summary()
    assert summary["per_step"]["ticks"] == 3
    assert summary["per_step"]["max_s"] == pytest.approx(60e-6)
    assert summary["per_step"]["mean_s"] == pytest.approx((40e-6 + 60e-6 + 50e-6) / 3)
    by_steps = summary["by_steps"]
    assert list(by_steps) == ["0", "1", "3"]
    assert by_steps["0"] == {"ticks": 1}  # no step: no time split
    assert by_steps["1"]["ticks"] == 2
    assert by_steps["3"]["p99_s"] == pytest.approx(150e-6, rel=0.01)


def test_each_tick_is_noted_with_its_node_steps() -> None:
    config = load_config()
    model = model_from_config(config)
    scenario = load_scenario("constant-rate")
    ts = model.sample_period_s
    node = SlaveNode(model, scenario, "linear")
    ratio = tuple(float(a.position_ratio_ah1) for a in model.axes)
    tick = SlaveTick(node, node.initial_state(1),
                     [SlaveSupervisor(ratio, 0.001, (-1.0, 1.0, -1.0, 1.0), 1.0, 3)],
                     [InputGuard(InputGuardSettings.from_config(config), ts)])
    tick.handle_position_m[...] = np.asarray(scenario.tool.start_position_m) / np.asarray(ratio)
    tick.start(synced=True)
    tick.configure_lane(MasterSamplePacing(PacingSettings(True, 4, 32)))
    clock = itertools.count(0, 1000).__next__  # 1 us a reading
    inputs = SlaveLaneInputs(silence_s=0.0)
    seq = 0
    steps_seen = []
    for index, size in enumerate([1, 1, 0, 2, 0, 0, 3, 1]):
        delivered = [HandleState(1, seq + k, int((seq + k) * ts * 1e9), Flags.FORCES_ENABLED,
                                 (0.5, 0.0), (0.0, 0.0)) for k in range(size)]
        seq += size
        inputs.now_s = index * ts
        inputs.message = delivered[-1] if delivered else None
        inputs.earlier = delivered[:-1]
        before = tick._lane.outputs.sample_time_s
        outputs = tick.step_lane(inputs, clock)
        steps_seen.append(round((outputs.sample_time_s - before) / ts))
        assert outputs.node_steps == steps_seen[-1]
        assert outputs.node_end_ns - outputs.supervised_ns == 1000  # one reading later
        tick.note_node_time()
    assert steps_seen == [1, 1, 0, 2, 0, 0, 3, 1]
    by_steps = tick.node_times.summary()["by_steps"]
    assert {k: v["ticks"] for k, v in by_steps.items()} == {"0": 3, "1": 3, "2": 1, "3": 1}
    assert tick.node_times.summary()["per_step"]["max_s"] == pytest.approx(1e-6)
