"""The lockstep loop is the loop the sampled analysis describes, and runs are reproducible."""

from __future__ import annotations

import gc

import numpy as np
import pytest

from haptic.common.analysis.linear_loop import LinearLoopSimulator
from haptic.common.config.scenario import load_scenario
from haptic.common.model.synthesis import synthesize_axis
from haptic.common.wire.injection import InjectionConfig
from haptic.lockstep.simulator import LockstepSimulator
from haptic.master.simulated_rig.operator import parse_operator_spec


def _linear(model, gains):
    return LockstepSimulator(model, load_scenario("constant-rate"),
                             parse_operator_spec("constant:fx=0,fy=0"), np.asarray(gains, float),
                             "linear")


def test_lockstep_equals_the_reference_linear_loop(paper_model) -> None:
    """Same traces as common/analysis/linear_loop.py (up to rounding) on both axes: the rig, the
    nodes and the delay lines form exactly the loop the --sampled-analysis analysis counts."""
    ts = paper_model.sample_period_s
    delays = np.array([0, 1, 3, 14, 15])
    result = _linear(paper_model, np.full(delays.size, 19.0)).run(
        0.4, delays, excitation_N=np.full((20, 2), 1.0), record_lanes=np.arange(delays.size))
    gained = paper_model.with_gain(19.0)
    pulse = np.zeros(result.steps)
    pulse[:20] = 1.0
    for index, axis in enumerate(gained.axes):
        reference = LinearLoopSimulator(axis, synthesize_axis(axis, gained.ch1), ts).run(
            pulse, delays)
        np.testing.assert_allclose(result.traces["handle_force_N"][:, :, index],
                                   reference.handle_force_N, rtol=0, atol=1e-12)
        # The slave's force at tick k describes t_{k+1}: the reference's sample k + 1.
        np.testing.assert_allclose(result.traces["tool_force_N"][:-1, :, index],
                                   reference.tool_force_N[1:], rtol=0, atol=1e-12)
        np.testing.assert_allclose(result.traces["handle_command_m"][:, :, index],
                                   reference.handle_command_m, rtol=0, atol=1e-15)


def test_lanes_with_different_gains_equal_separate_runs(paper_model) -> None:
    """Stacked per-lane compensators change nothing: one run with k = 3 and 13 equals two
    runs with one gain each."""
    excitation = np.full((20, 2), 1.0)
    both = _linear(paper_model, [3.0, 13.0]).run(0.2, [4, 30], excitation_N=excitation,
                                                 record_lanes=[0, 1])
    for lane, (gain, delay) in enumerate([(3.0, 4), (13.0, 30)]):
        alone = _linear(paper_model, [gain]).run(0.2, delay, excitation_N=excitation,
                                                 record_lanes=[0])
        np.testing.assert_allclose(both.traces["handle_force_N"][:, lane],
                                   alone.traces["handle_force_N"][:, 0], rtol=0, atol=1e-12)


def _impaired_run(model, seed: int):
    injection = InjectionConfig(jitter_s=0.002, jitter_distribution="exponential",
                                loss_probability=0.05, burst_enter_probability=0.01,
                                burst_exit_probability=0.3)
    simulator = LockstepSimulator(model, load_scenario("constant-rate"),
                                  parse_operator_spec("regulate:fx=3.6,fy=0"),
                                  np.array([1.0, 5.0, 13.0]), "linear", force_noise_std_N=0.01)
    return simulator.run(0.3, [0, 10, 20], to_slave=injection, to_master=injection, seed=seed,
                         record_lanes=[0, 1, 2])


def test_same_seed_same_traces_bit_for_bit(paper_model) -> None:
    first, second = _impaired_run(paper_model, 7), _impaired_run(paper_model, 7)
    for name, values in first.traces.items():
        assert np.array_equal(values, second.traces[name]), name
    other = _impaired_run(paper_model, 8)
    assert not np.array_equal(first.traces["handle_force_N"], other.traces["handle_force_N"])


def test_environment_must_be_known(paper_model) -> None:
    with pytest.raises(ValueError, match="environment"):
        LockstepSimulator(paper_model, load_scenario("constant-rate"),
                          parse_operator_spec("constant:fx=0"), np.array([1.0]), "water")


class _FreezeWatch(LockstepSimulator):
    """Notes the garbage collector's frozen object count at each of its master steps."""

    frozen_during: list[int]

    def _master_step(self, run, k: int) -> None:
        self.frozen_during.append(gc.get_freeze_count())
        super()._master_step(run, k)


@pytest.mark.usefixtures("thawed_heap")
def test_a_run_freezes_the_heap_from_before_it_and_thaws_it_after(paper_model) -> None:
    """What was alive before the run is never scanned by a collection during it (a full
    collection of the program's heap would stall the run), and is collectable again after."""
    simulator = _FreezeWatch(paper_model, load_scenario("constant-rate"),
                             parse_operator_spec("constant:fx=0,fy=0"), np.array([1.0]),
                             "linear")
    simulator.frozen_during = []
    alive_before = len(gc.get_objects())
    simulator.run(0.01, 2)
    assert len(simulator.frozen_during) == 19
    assert min(simulator.frozen_during) >= alive_before
    assert gc.get_freeze_count() == 0
