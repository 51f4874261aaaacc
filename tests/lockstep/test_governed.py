"""The margin governor in lockstep: a one-way delay that steps from 2 ms to 40 ms at t = 3 s
takes the paper's k = 13 loop (tau* 14.3 ms sampled) far past its margin; ungoverned it grows
without bound, governed (k lowered to a delay-independent gain on both sides) it stays
bounded."""

from __future__ import annotations

import numpy as np
import pytest

from haptic.common.analysis.margin_table import build_margin_table
from haptic.common.config.scenario import load_scenario
from haptic.common.model.delay_profile import parse_delay_profile
from haptic.common.wire.injection import InjectionConfig
from haptic.lockstep.simulator import LockstepSimulator
from haptic.lockstep.verdict import growth_verdict
from haptic.master.margin_governor import GovernorSettings, MarginGovernor
from haptic.master.simulated_rig.operator import parse_operator_spec

DURATION_S = 6.0
STEP_AT_S = 3.0


@pytest.fixture(scope="module")
def k13(paper_model):
    return paper_model.with_gain(13.0)


@pytest.fixture(scope="module")
def table(k13, paper_config):
    return build_margin_table(k13, paper_config["analysis"], min_gain_k=1.0, step_ratio=0.8)


def _run(model, governors=None):
    ts = model.sample_period_s
    steps = int(round(DURATION_S / ts))
    pulse = np.zeros((steps, 2))  # a push at the start and one right at the step
    pulse[:20] = 1.0
    at = int(round(STEP_AT_S / ts))
    pulse[at:at + 20] = 1.0
    simulator = LockstepSimulator(model, load_scenario("constant-rate"),
                                  parse_operator_spec("constant:fx=0,fy=0"),
                                  np.array([13.0]), "linear")
    return simulator.run(
        DURATION_S, 0, to_slave=InjectionConfig(delay_s=0.002),
        to_master=InjectionConfig(delay_profile=parse_delay_profile(
            f"step 0:0.002 {STEP_AT_S}:0.040")),
        excitation_N=pulse, governors=governors)


def test_the_analysis_puts_the_step_beyond_k13_and_within_a_lower_k(table) -> None:
    assert table.margin_s(13.0) < 0.042 < table.margin_s(table.entries[-1].k)
    assert table.margin_s(13.0) > 0.004 + 0.0006  # before the step: inside the margin


def test_ungoverned_the_step_makes_the_loop_unbounded(k13) -> None:
    result = _run(k13)
    verdict = growth_verdict(result, STEP_AT_S + 0.5)
    assert verdict.growing[0]
    assert result.peak_handle_force_N.max() > 1e3  # from a 1 N push


def test_governed_the_loop_stays_bounded_and_both_sides_follow_k(k13, table) -> None:
    governor = MarginGovernor(GovernorSettings(enabled=True, recover_after_s=0.0), table)
    result = _run(k13, [governor])
    verdict = growth_verdict(result, STEP_AT_S + 0.5)
    assert not verdict.growing[0] and not result.diverged[0]
    assert result.peak_handle_force_N.max() < 2.0  # the 1 N pushes, nothing grows
    gains = result.governed.gains_k[:, 0]
    ts = k13.sample_period_s
    assert np.all(gains[:int(STEP_AT_S / ts)] == 13.0)  # 4 ms round trip: k untouched
    assert gains[-1] == table.entries[-1].k and table.entries[-1].delay_margin_s is None
    assert np.max(np.abs(np.diff(gains))) < 0.2  # lowered smoothly, no jump
    first = result.governed.events[0]
    assert first["kind"] == "governor_lower_k"
    # acted within the round trip's silence after the step: before the late messages came
    assert STEP_AT_S < first["time_s"] < STEP_AT_S + 0.040
    assert governor.max_rtt_s == pytest.approx(0.042 + ts, abs=2 * ts)


def test_scaled_inputs_are_the_design_at_the_lower_gain(paper_model) -> None:
    """Both sides' compensators at k0 = 13 with inputs scaled by 8/13 step exactly as the ones
    synthesised at k = 8 (Sh = St = 0: the design is linear in k), master and slave."""
    from haptic.lockstep.simulator import TRANSPARENT_SAFETY
    from haptic.master.node import MasterNode
    from haptic.slave_sim.node import SlaveNode

    rng = np.random.default_rng(3)
    inputs = rng.normal(0.0, 1.0, (400, 1, 6)) * [1.0, 1.0, 0.0, 0.0, 1.0, 1.0]
    commands = []
    for gain, ratio in ((13.0, 8.0 / 13.0), (8.0, 1.0)):
        node = MasterNode.from_model(paper_model.with_gain(gain), TRANSPARENT_SAFETY)
        state = node.initial_state(np.zeros((1, 2)))
        state.gain_ratio[:] = ratio
        commands.append(np.array([node.step(state, u[:, 0:2], u[:, 2:4], u[:, 4:6])
                                  for u in inputs]))
    np.testing.assert_allclose(commands[0], commands[1], rtol=1e-9, atol=1e-12)
    assert np.abs(commands[1]).max() > 1e-4
    forces = []
    scenario = load_scenario("constant-rate")
    for gain, ratio in ((13.0, 8.0 / 13.0), (8.0, 1.0)):
        node = SlaveNode(paper_model.with_gain(gain), scenario, "linear")
        state = node.initial_state(1)
        state.gain_ratio = np.array([ratio])
        forces.append(np.array([node.step(state, u[:, 0:2], np.zeros((1, 2))).tool_force_N
                                for u in inputs]))
    np.testing.assert_allclose(forces[0], forces[1], rtol=1e-9, atol=1e-12)
    assert np.abs(forces[1]).max() > 1e-3  # the comparison is not of zeros


def test_on_a_ramp_the_governor_acts_before_the_margin(k13, table) -> None:
    """A one-way delay rising 2 -> 40 ms over 3 s: k is lowered while the round trip is still
    inside tau*(13), so the loop never runs beyond its margin and stays bounded."""
    ts = k13.sample_period_s
    governor = MarginGovernor(GovernorSettings(enabled=True, recover_after_s=0.0), table)
    steps = int(round(4.0 / ts))
    pulse = np.zeros((steps, 2))
    pulse[:20] = 1.0
    simulator = LockstepSimulator(k13, load_scenario("constant-rate"),
                                  parse_operator_spec("constant:fx=0,fy=0"),
                                  np.array([13.0]), "linear")
    result = simulator.run(4.0, 0, to_slave=InjectionConfig(delay_s=0.002),
                           to_master=InjectionConfig(delay_profile=parse_delay_profile(
                               "linear 0:0.002 3:0.040")),
                           excitation_N=pulse, governors=[governor])
    first = result.governed.events[0]
    round_trip_then = 0.002 + (0.002 + 0.038 * first["time_s"] / 3.0)
    assert round_trip_then < table.margin_s(13.0)  # acted before the margin
    assert round_trip_then == pytest.approx(0.7 * table.margin_s(13.0), abs=2 * ts)
    assert not growth_verdict(result, 1.0).growing[0]
    assert result.peak_handle_force_N.max() < 2.0


def _standby_run(model, table, profile: str, duration_s: float, **settings):
    """A governed run with the ``tdpa`` action in paper mode: the passivity layer waits on
    standby on both sides (master/tick.py, slave_sim/tick.py)."""
    from haptic.common.model.passivity import PassivitySettings

    ts = model.sample_period_s
    steps = int(round(duration_s / ts))
    pulse = np.zeros((steps, 2))
    pulse[:20] = 1.0
    at = int(round(STEP_AT_S / ts))
    pulse[at:at + 20] = 1.0
    simulator = LockstepSimulator(model, load_scenario("constant-rate"),
                                  parse_operator_spec("constant:fx=0,fy=0"),
                                  np.array([13.0]), "linear", passivity=PassivitySettings(),
                                  passivity_standby=True)
    governor = MarginGovernor(GovernorSettings(enabled=True, action="tdpa", **settings), table,
                              tdpa_available=True)
    result = simulator.run(duration_s, 0, to_slave=InjectionConfig(delay_s=0.002),
                           to_master=InjectionConfig(delay_profile=parse_delay_profile(profile)),
                           excitation_N=pulse, governors=[governor])
    return simulator, result


def test_governed_tdpa_switches_the_passivity_layer_on_at_both_sides(k13, table) -> None:
    """The tdpa action at run time: the step to 40 ms switches the standby layer on at the
    master, the slave follows the flag; k stays 13 (nothing is lowered) and the loop that
    grows without bound ungoverned stays bounded, the sides aligned."""
    simulator, result = _standby_run(k13, table, f"step 0:0.002 {STEP_AT_S}:0.040",
                                     DURATION_S, recover_after_s=0.0)
    assert not growth_verdict(result, STEP_AT_S + 0.5).growing[0]
    assert not result.diverged[0] and result.peak_handle_force_N.max() < 2.0
    assert np.all(result.governed.gains_k == 13.0)
    first = result.governed.events[0]
    assert first["kind"] == "governor_tdpa_request"
    assert STEP_AT_S < first["time_s"] < STEP_AT_S + 0.040
    master_tick, slave_tick = simulator.last_ticks
    assert master_tick.passivity_events[0]["kind"] == "tdpa_on"
    assert master_tick.passivity_events[0]["time_s"] == pytest.approx(first["time_s"])
    master_state, slave_state = simulator.final_states
    assert master_state.passivity.active[0] and slave_state.passivity.active[0]
    followed = [e for e in slave_tick.supervisors[0].events if e["kind"] == "tdpa_on"]
    # the slave switches on once the first flagged handle message reaches it (2 ms later)
    assert len(followed) == 1
    ts = k13.sample_period_s
    assert followed[0]["time_s"] - first["time_s"] == pytest.approx(0.002, abs=2 * ts)
    assert np.abs(result.final_position_gap_m[0]).max() < 2e-3


def test_governed_tdpa_switches_back_off_when_the_delay_returns(k13, table) -> None:
    """Out of tdpa: once the peak round trip over ``hold_s`` allows the nominal k again for
    ``recover_after_s``, both sides switch the layer off (the paper's scheme again)."""
    simulator, result = _standby_run(k13, table, "step 0:0.002 1.0:0.040 2.0:0.002", 5.0,
                                     recover_after_s=1.0, hold_s=0.5)
    kinds = [e["kind"] for e in result.governed.events]
    assert kinds == ["governor_tdpa_request", "governor_paper_request"]
    off_at = result.governed.events[1]["time_s"]
    assert 2.0 + 0.5 + 1.0 <= off_at < 2.0 + 0.5 + 1.0 + 0.1
    master_tick, slave_tick = simulator.last_ticks
    assert [e["kind"] for e in master_tick.passivity_events] == ["tdpa_on", "tdpa_off"]
    assert [e["kind"] for e in slave_tick.supervisors[0].events
            if e["kind"].startswith("tdpa")] == ["tdpa_on", "tdpa_off"]
    master_state, slave_state = simulator.final_states
    assert not master_state.passivity.active[0] and not slave_state.passivity.active[0]
    assert not result.diverged[0] and result.peak_handle_force_N.max() < 2.0


def _pushed_run(model, table, profile: str, governed: bool = True):
    """A sustained 1 N push on the linear loop at k = 13, the layer on standby, the tool's
    delay ``profile`` to the master; governed with the ``tdpa`` action (or not at all)."""
    from haptic.common.model.passivity import PassivitySettings

    simulator = LockstepSimulator(model, load_scenario("constant-rate"),
                                  parse_operator_spec("constant:fx=1.0,onset=0.05"),
                                  np.array([13.0]), "linear", passivity=PassivitySettings(),
                                  passivity_standby=True)
    governors = [MarginGovernor(GovernorSettings(enabled=True, action="tdpa",
                                                 recover_after_s=0.0), table,
                                tdpa_available=True)] if governed else None
    result = simulator.run(4.0, 0, to_slave=InjectionConfig(delay_s=0.002),
                           to_master=InjectionConfig(delay_profile=parse_delay_profile(profile)),
                           governors=governors)
    return simulator, result


@pytest.mark.parametrize("one_way_s", [0.040, 0.100])
def test_a_switch_in_motion_beyond_the_margin_keeps_the_ports_passive(k13, table,
                                                                      one_way_s) -> None:
    """The delay jumps beyond the margin while the tool moves fast (a sustained 1 N push, the
    step at 0.3 s): both layers switch on with their accounts empty and the two ports give out
    no more than they took in. Why they start empty: a slave account credited with its tool's
    kinetic energy at the switch (tried) let the loop get going before the controllers acted,
    and their capped corrections could not catch up: 41-48 mJ more out than in, 1.66 N."""
    simulator, result = _pushed_run(k13, table, f"step 0:0.002 0.3:{one_way_s}")
    assert [e["kind"] for e in result.governed.events] == ["governor_tdpa_request"]
    master_tick, slave_tick = simulator.last_ticks
    moving = [e for e in slave_tick.supervisors[0].events if e["kind"] == "tdpa_on"]
    assert len(moving) == 1 and max(abs(v) for v in moving[0]["position_gap_m"]) > 0.0
    master, slave = (state.passivity for state in simulator.final_states)
    assert master.active[0] and slave.active[0]
    out_J = master.output_energy_J[0] + slave.output_energy_J[0]
    in_J = master.input_energy_J[0] + slave.input_energy_J[0]
    assert out_J <= in_J + 0.5e-3
    assert not result.diverged[0] and result.peak_handle_force_N.max() < 1.3


def test_a_switch_at_rest_under_a_sustained_push_keeps_the_approachs_offset(k13, table
                                                                           ) -> None:
    """The two-process governed test's scenario, deterministic: a sustained 1 N push, the
    approach over in the paper's scheme (2.76 mm apart, its offset for this push), then the
    step from 2 to 40 ms one way at 1.5 s. The layer goes on at rest and the sides end no
    further apart than they were then; without the switch the loop grows without bound."""
    simulator, result = _pushed_run(k13, table, "step 0:0.002 1.5:0.040")
    switched = [e for e in simulator.last_ticks[1].supervisors[0].events
                if e["kind"] == "tdpa_on"]
    assert len(switched) == 1 and 1.5 < switched[0]["time_s"] < 1.54
    at_switch_m = np.abs(switched[0]["position_gap_m"]).max()
    assert at_switch_m == pytest.approx(2.76e-3, abs=0.05e-3)
    assert np.abs(result.final_position_gap_m[0]).max() <= at_switch_m + 0.05e-3
    assert not result.diverged[0] and result.peak_handle_force_N.max() < 1.2
    _, ungoverned = _pushed_run(k13, table, "step 0:0.002 1.5:0.040", governed=False)
    assert ungoverned.diverged[0] or ungoverned.peak_handle_force_N.max() > 5.0
