"""The paper mode's drift coupling (common/model/drift.py): off it is not there at all; on, the
sampled analysis's delay margin with it is the lockstep's (the coupling is in the analysed
loop), and it pulls the tool to the handle."""

from __future__ import annotations

import numpy as np
import pytest

from haptic.common.analysis.report import AnalysisSettings, axis_loop
from haptic.common.analysis.stability import delay_margin
from haptic.common.config import load_config
from haptic.common.config.control_schema import drift_coupling
from haptic.common.config.scenario import load_scenario
from haptic.common.model.drift import DriftCoupling
from haptic.common.model.teleop import model_from_config
from haptic.lockstep.simulator import LockstepSimulator
from haptic.lockstep.verdict import growth_verdict
from haptic.master.simulated_rig.operator import parse_operator_spec
from haptic.slave_sim.node import SlaveNode

STRONG = (10000.0, 50.0)  # kp N/m, wc rad/s: strong enough to move the margin by samples


def test_off_by_default_so_the_paper_loop_is_unchanged() -> None:
    config = load_config(None)
    assert drift_coupling(config, 0.00054) is None
    assert SlaveNode.from_config(config).initial_state(2).drift is None


def test_the_analysis_margin_with_the_coupling_is_the_locksteps() -> None:
    model = model_from_config(load_config(None))
    ts = model.sample_period_s
    margins = {}
    for drift in (None, STRONG):
        settings = AnalysisSettings(sample_period_s=ts, drift=drift)
        margins[drift] = min(delay_margin(axis_loop(model, axis, 13.0, settings), 1.0,
                                          settings.grid).delay_margin_s for axis in model.axes)
    # the coupling costs margin: 14.31 ms -> 13.51 ms (26.5 -> 25.0 samples)
    assert margins[STRONG] < margins[None] - 1.0 * ts
    samples = np.array([24, 26, 28])
    growing = {}
    for drift in (None, STRONG):
        coupling = None if drift is None else DriftCoupling(*drift, ts)
        sim = LockstepSimulator(model, load_scenario("constant-rate"),
                                parse_operator_spec("constant:fx=0,fy=0"),
                                np.full(samples.size, 13.0), "linear", drift=coupling)
        result = sim.run(3.0, samples, excitation_N=np.full((20, 2), 1.0))
        growing[drift] = growth_verdict(result).growing.tolist()
    # 26 samples: inside the paper's margin, outside the coupled loop's, as analysed
    assert samples[1] * ts < margins[None] and samples[1] * ts > margins[STRONG]
    assert growing[None] == [False, False, True]
    assert growing[STRONG] == [False, True, True]


@pytest.mark.parametrize("kp", [0.0, 200.0])
def test_the_coupling_pulls_the_tool_to_the_handle(kp) -> None:
    """A tool displaced from Ah1 yh with no force anywhere: the paper's scheme keeps the
    offset (no position feedback), the coupling removes it."""
    model = model_from_config(load_config(None))
    ts = model.sample_period_s
    scenario = load_scenario("constant-rate")  # the tool starts in free space before the clay
    node = SlaveNode(model, scenario, "clay", "numpy", "cpu",
                     drift=DriftCoupling(kp, 2.0, ts) if kp else None)
    start = np.asarray(scenario.tool.start_position_m, float)
    state = node.initial_state(1, start)
    state.tool[0, 0] -= 0.005  # 5 mm off the handle, away from the clay
    handle = (start / node.position_ratio)[None, :]
    zero = np.zeros((1, 2))
    for _ in range(int(round(6.0 / ts))):
        node.step(state, zero, handle)
    gap = abs(state.tool[0, 0] - start[0])
    if kp:
        assert gap < 0.001
    else:
        assert gap > 0.001
