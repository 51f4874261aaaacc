"""The master node: Ch1/Ct1 compensator and the safety layer, vectorised over lanes."""

from __future__ import annotations

import dataclasses

import control
import numpy as np
import pytest

from haptic.common.config import load_config
from haptic.common.model.synthesis import synthesize
from haptic.common.model.teleop import model_from_config
from haptic.master.node import MasterNode, master_compensator
from haptic.master.settings import SafetySettings, master_settings


@pytest.fixture(scope="module")
def model():
    return model_from_config(load_config())


def _safety(**changes) -> SafetySettings:
    base = SafetySettings(
        force_limit_N=20.0, force_trip_N=60.0, velocity_limit_m_per_s=10.0,
        velocity_trip_m_per_s=20.0, workspace_min_m=(-0.5, -0.5), workspace_max_m=(0.5, 0.5),
        workspace_trip_margin_m=0.01, ramp_small_force_N=0.5, ramp_small_samples=5,
        ramp_time_s=0.0,
    )
    return dataclasses.replace(base, **changes)


def _enable(node: MasterNode, state, position: np.ndarray) -> None:
    """Feed small forces until the force gate opens."""
    lanes = position.shape[0]
    for _ in range(node.safety.ramp_small_samples):
        node.step(state, np.zeros((lanes, 2)), position, np.zeros((lanes, 2)))


def test_compensator_is_ch1_minus_ct1_from_the_synthesis(model) -> None:
    block = master_compensator(model)
    assert block.input_names == ("fh_x", "fh_y", "ft_x", "ft_y")
    assert block.output_names == ("vh_x", "vh_y")
    ts = model.sample_period_s
    omega = np.array([0.5, 5.0, 50.0])
    axes = synthesize(model)
    for w in omega:
        z = np.exp(1j * w * ts)
        response = block.C @ np.linalg.solve(z * np.eye(block.n_states) - block.A, block.B) + (
            block.D)
        for index, axis in enumerate(axes):
            # Tustin warps frequency by (w Ts)^2/12: negligible here.
            ch1 = complex(control.evalfr(axis.ch1, 1j * w))
            ct1 = complex(control.evalfr(axis.ct1, 1j * w))
            assert response[index, index] == pytest.approx(ch1, rel=1e-3)
            assert response[index, 2 + index] == pytest.approx(-ct1, rel=1e-3)
            assert response[index, 1 - index] == 0.0


def test_activation_holds_the_position_and_forces_wait_for_small_samples(model) -> None:
    node = MasterNode.from_model(model, _safety(ramp_small_samples=5))
    start = np.array([[0.01, -0.02]])
    state = node.initial_state(start)
    big = np.array([[3.0, 0.0]])
    for _ in range(50):  # the operator already pushes: nothing moves
        command = node.step(state, big, start, np.zeros((1, 2)))
        np.testing.assert_array_equal(command, start)
    assert not state.forces_enabled[0]
    for _ in range(5):
        command = node.step(state, np.array([[0.1, 0.0]]), start, np.zeros((1, 2)))
    assert state.forces_enabled[0]
    assert [e.kind for e in state.events] == ["enable"]
    command = node.step(state, big, start, np.zeros((1, 2)))
    assert command[0, 0] > start[0, 0]


def test_forces_ramp_in_over_the_configured_time(model) -> None:
    ts = model.sample_period_s
    node = MasterNode.from_model(model, _safety(ramp_time_s=100 * ts))
    state = node.initial_state(np.zeros((1, 2)))
    _enable(node, state, np.zeros((1, 2)))
    scales = []
    for _ in range(150):
        node.step(state, np.array([[1.0, 0.0]]), np.zeros((1, 2)), np.zeros((1, 2)))
        scales.append(state.force_scale[0])
    assert scales[0] < 0.02
    assert scales[50] == pytest.approx(0.5, abs=0.02)
    assert scales[-1] == 1.0
    assert np.all(np.diff(scales) >= 0.0)


def test_open_loop_output_is_the_compensator_response(model) -> None:
    """With no limit active the command is origin + (Ch1 fh - Ct1 ft), exactly."""
    node = MasterNode.from_model(model, _safety())
    block = node.compensator
    origin = np.array([[0.02, 0.03]])
    state = node.initial_state(origin)
    _enable(node, state, origin)
    reference = block.initial_state(1)
    rng = np.random.default_rng(3)
    for _ in range(200):
        fh, ft = rng.uniform(-2, 2, (1, 2)), rng.uniform(-2, 2, (1, 2))
        command = node.step(state, fh, origin, ft)
        expected = origin + block.step(reference, np.concatenate([fh, ft], axis=1))
        np.testing.assert_allclose(command, expected, rtol=1e-12, atol=1e-15)


def test_force_limit_saturates_with_one_event_per_onset(model) -> None:
    node = MasterNode.from_model(model, _safety(force_limit_N=2.0))
    clipped = node.initial_state(np.zeros((1, 2)))
    reference = node.initial_state(np.zeros((1, 2)))
    _enable(node, clipped, np.zeros((1, 2)))
    _enable(node, reference, np.zeros((1, 2)))
    for _ in range(20):
        a = node.step(clipped, np.array([[5.0, -1.0]]), np.zeros((1, 2)), np.zeros((1, 2)))
        b = node.step(reference, np.array([[2.0, -1.0]]), np.zeros((1, 2)), np.zeros((1, 2)))
        np.testing.assert_array_equal(a, b)
    saturations = [e for e in clipped.events if e.kind == "saturate"]
    assert len(saturations) == 1 and saturations[0].axis == "x"
    assert "handle force" in saturations[0].reason
    # A reflected tool force saturates too.
    node.step(clipped, np.zeros((1, 2)), np.zeros((1, 2)), np.array([[0.0, -9.0]]))
    assert clipped.events[-1].reason.startswith("tool force") and clipped.events[-1].axis == "y"


def test_force_beyond_the_trip_level_puts_the_lane_in_its_safe_state(model) -> None:
    node = MasterNode.from_model(model, _safety(force_trip_N=30.0))
    state = node.initial_state(np.zeros((2, 2)))
    _enable(node, state, np.zeros((2, 2)))
    position = np.array([[0.001, 0.002], [0.003, 0.004]])
    force = np.array([[1.0, 0.0], [0.0, -31.0]])
    command = node.step(state, force, position, np.zeros((2, 2)))
    assert state.faulted.tolist() == [False, True]
    np.testing.assert_array_equal(command[1], position[1])  # holds where it was
    trips = [e for e in state.events if e.kind == "trip"]
    assert len(trips) == 1 and trips[0].lane == 1 and trips[0].axis == "y"
    for _ in range(100):  # latched: no force moves it any more
        command = node.step(state, np.array([[1.0, 0.0], [5.0, 5.0]]), position,
                            np.array([[0.0, 0.0], [3.0, 3.0]]))
    np.testing.assert_array_equal(command[1], position[1])
    assert command[0, 0] > position[0, 0]  # the other lane carries on


@pytest.mark.parametrize("where", ["handle force", "handle position", "tool force"])
def test_non_finite_input_never_reaches_the_command(model, where: str) -> None:
    node = MasterNode.from_model(model, _safety())
    start = np.array([[0.01, 0.01]])
    state = node.initial_state(start)
    _enable(node, state, start)
    for _ in range(20):
        node.step(state, np.array([[2.0, 0.0]]), start, np.zeros((1, 2)))
    inputs = {"handle force": np.array([[2.0, 0.0]]), "handle position": start.copy(),
              "tool force": np.zeros((1, 2))}
    inputs[where] = inputs[where].copy()
    inputs[where][0, 1] = np.nan
    command = node.step(state, inputs["handle force"], inputs["handle position"],
                        inputs["tool force"])
    assert np.all(np.isfinite(command))
    assert state.faulted[0]
    np.testing.assert_array_equal(command, start)
    assert state.events[-1].kind == "trip" and state.events[-1].reason == f"non-finite {where}"
    for value in (np.inf, -np.inf, np.nan):
        command = node.step(state, np.full((1, 2), value), np.full((1, 2), value),
                            np.full((1, 2), value))
        np.testing.assert_array_equal(command, start)


def test_command_rate_is_limited_without_wind_up(model) -> None:
    ts = model.sample_period_s
    node = MasterNode.from_model(model, _safety(velocity_limit_m_per_s=0.01))
    state = node.initial_state(np.zeros((1, 2)))
    _enable(node, state, np.zeros((1, 2)))
    commands = [node.step(state, np.array([[20.0, 0.0]]), np.zeros((1, 2)),
                          np.zeros((1, 2)))[0] for _ in range(400)]
    steps = np.diff(np.array(commands)[:, 0])
    assert np.max(np.abs(steps)) <= 0.01 * ts * (1 + 1e-9)
    assert any(e.kind == "saturate" and "rate" in e.reason for e in state.events)
    # Reverse the force: the command turns round once Ch1's own velocity state (time
    # constant 0.1 s) has reversed, not after unwinding the 2 m/s x 0.2 s it was held back.
    before = commands[-1][0]
    for _ in range(400):
        command = node.step(state, np.array([[-20.0, 0.0]]), np.zeros((1, 2)), np.zeros((1, 2)))
    assert command[0, 0] < before


def test_command_is_clamped_into_the_workspace(model) -> None:
    node = MasterNode.from_model(model, _safety(workspace_min_m=(-0.01, -0.01),
                                                workspace_max_m=(0.002, 0.01)))
    state = node.initial_state(np.zeros((1, 2)))
    _enable(node, state, np.zeros((1, 2)))
    for _ in range(3000):
        command = node.step(state, np.array([[20.0, 0.0]]), np.zeros((1, 2)), np.zeros((1, 2)))
    assert command[0, 0] == 0.002
    assert [e.reason for e in state.events if e.kind == "saturate"] == [
        "command clamped to the workspace"]
    # Leaving the wall needs no unwinding of the ~3 m the compensator pushed into it:
    # Ch1's velocity state reverses within about 0.16 s (time constant 0.1 s).
    for _ in range(400):
        command = node.step(state, np.array([[-20.0, 0.0]]), np.zeros((1, 2)), np.zeros((1, 2)))
    assert command[0, 0] < 0.002


def test_measured_speed_and_position_trips(model) -> None:
    ts = model.sample_period_s
    node = MasterNode.from_model(model, _safety(velocity_trip_m_per_s=0.5,
                                                velocity_limit_m_per_s=0.2))
    state = node.initial_state(np.zeros((2, 2)))
    jump = np.array([[0.6 * ts, 0.0], [0.0, 0.4 * ts]])  # lane 0 at 0.6 m/s, lane 1 at 0.4
    node.step(state, np.zeros((2, 2)), jump, np.zeros((2, 2)))
    assert state.faulted.tolist() == [True, False]
    assert "speed" in state.events[-1].reason
    node = MasterNode.from_model(model, _safety(workspace_max_m=(0.1, 0.1),
                                                workspace_trip_margin_m=0.005))
    state = node.initial_state(np.array([[0.104, 0.0]]))
    node.step(state, np.zeros((1, 2)), np.array([[0.104, 0.0]]), np.zeros((1, 2)))
    assert not state.faulted[0]
    node.step(state, np.zeros((1, 2)), np.array([[0.1055, 0.0]]), np.zeros((1, 2)))
    assert state.faulted[0] and state.events[-1].reason == "handle outside the workspace"


def test_outside_trip_records_a_reason_and_holds(model) -> None:
    node = MasterNode.from_model(model, _safety())
    state = node.initial_state(np.array([[0.0, 0.0], [0.01, 0.0]]))
    node.trip(state, np.array([False, True]), "hardware: missing TPDO1")
    command = node.step(state, np.full((2, 2), 0.1), np.array([[0.0, 0.0], [0.01, 0.0]]),
                        np.zeros((2, 2)))
    np.testing.assert_array_equal(command[1], [0.01, 0.0])
    assert state.events[0].reason == "hardware: missing TPDO1" and state.events[0].lane == 1


def test_shipped_safety_settings_load_and_cross_checks_name_the_key() -> None:
    config = load_config()
    settings = master_settings(config)
    assert settings.safety.force_trip_N >= settings.safety.force_limit_N
    from haptic.common.config import ConfigError, override

    bad = override(config, "master.safety.force_trip_N", 1.0)
    with pytest.raises(ConfigError) as caught:
        master_settings(bad)
    assert caught.value.key == "master.safety.force_trip_N"
    bad = override(config, "master.safety.workspace_max_m", [-1.0, 1.0])
    with pytest.raises(ConfigError) as caught:
        master_settings(bad)
    assert caught.value.key == "master.safety.workspace_max_m"


def test_resume_ramps_forces_in_without_the_small_force_gate(paper_model) -> None:
    safety = master_settings(load_config()).safety
    node = MasterNode.from_model(paper_model, safety)
    start = np.array([[0.02, -0.01]])
    state = node.initial_state(start)
    node.resume(state, start)
    assert state.forces_enabled[0] and state.events[0].kind == "enable"
    push = np.array([[3.0, 0.0]])  # the operator pushes through the outage
    first = node.step(state, push, start, np.zeros((1, 2)))
    assert np.allclose(first, start, atol=1e-9)  # no jump: the ramp starts at zero
    scales = []
    for _ in range(round(0.3 / node.period_s)):
        node.step(state, push, start, np.zeros((1, 2)))
        scales.append(state.force_scale[0])
    assert 0.0 < scales[10] < 0.2 and scales[-1] == 1.0


def test_tdpa_node_matches_the_numpy_reference_port() -> None:
    """The node's passivity port (``tdpa``) wired to the right buffers and limits: the same
    commands and energy flows as the numpy reference, the peer's energy given to ``step``."""
    from haptic.common.model.passivity import (
        PassivityPort,
        PassivitySettings,
        master_step_reference,
    )

    config = load_config(None)
    model = model_from_config(config).with_gain(13.0)
    safety = dataclasses.replace(master_settings(config).safety, ramp_small_force_N=1e9,
                                 ramp_small_samples=1, ramp_time_s=0.05)
    settings = PassivitySettings(credit_max_J=0.002, master_keep_J=0.0005)
    lanes = 4
    start = np.zeros((lanes, 2))
    tdpa = MasterNode.from_model(model, safety, settings)
    paper = MasterNode.from_model(model, safety)
    state = tdpa.initial_state(start)
    assert np.isnan(state.peer_energy_J).all()  # no energy received yet
    assert state.peer_target_m.shape == (lanes, 2)  # the tool in handle coordinates (x, y)
    assert np.isnan(state.peer_target_m).all()  # no tool position received yet
    reference_state = paper.initial_state(start)
    port = PassivityPort.create(settings, model.sample_period_s, lanes, settings.master_keep_J)
    rng = np.random.default_rng(5)
    position = np.zeros((lanes, 2))
    peer = np.zeros(lanes)
    acted = 0
    for step in range(800):
        force = rng.normal(0.0, 1.5, (lanes, 2))
        force[0] = 0.0  # below the force floor
        tool = rng.normal(0.0, 3.0, (lanes, 2))
        given = None
        if step % 7 == 0:
            peer = peer + rng.random(lanes) * 1e-4
            given = peer
            port.receive(peer)
        if step == 100:  # the tool's first message: its position, a few mm off
            state.peer_target_m[...] = rng.normal(0.0, 0.003, (lanes, 2))
        command = tdpa.step(state, force, position, tool, peer_energy_J=given)
        paper.step(reference_state, force, position, tool)
        master_step_reference(port, reference_state.inputs, reference_state.command_m,
                              reference_state.last_command_m, reference_state.origin_m,
                              reference_state.faulted, safety.force_limit_N,
                              np.asarray(safety.workspace_min_m),
                              np.asarray(safety.workspace_max_m), state.peer_target_m,
                              reference_state.forces_enabled)
        np.testing.assert_allclose(command, reference_state.command_m, rtol=0, atol=1e-12)
        position = position + 0.2 * (command - position)
        acted += int(np.count_nonzero(state.passivity.correction_m))
    np.testing.assert_array_equal(state.peer_energy_J, peer)
    for name in ("tank_J", "sent_J", "peer_sent_J", "input_energy_J", "output_energy_J",
                 "forgotten_energy_J", "dissipated_energy_J", "active_steps"):
        np.testing.assert_allclose(getattr(state.passivity, name), getattr(port, name),
                                   rtol=1e-9, atol=1e-12, err_msg=name)
    assert acted > 20
    assert state.passivity.active_steps[0] == 0


def test_gain_ratio_scales_the_compensator_inputs_not_the_used_forces() -> None:
    """``gain_ratio`` (k/k0, 1 at activation) scales what Ch1 integrates: a lane at ratio
    0.5 commands what a lane at ratio 1 commands for half the forces, and differs from a lane
    at ratio 1 with the same forces; the forces reported as used are the unscaled ones."""
    config = load_config(None)
    model = model_from_config(config).with_gain(13.0)
    safety = dataclasses.replace(master_settings(config).safety, ramp_small_force_N=1e9,
                                 ramp_small_samples=1, ramp_time_s=0.01)
    node = MasterNode.from_model(model, safety)
    state = node.initial_state(np.zeros((3, 2)))
    np.testing.assert_array_equal(state.gain_ratio, np.ones(3))
    state.gain_ratio[0] = 0.5
    rng = np.random.default_rng(9)
    for _ in range(200):
        force = rng.normal(0.0, 0.5, 2)
        tool = rng.normal(0.0, 0.8, 2)
        handle = np.array([force, force / 2, force])
        tools = np.array([tool, tool / 2, tool])
        command = node.step(state, handle, np.zeros((3, 2)), tools)
        np.testing.assert_allclose(command[0], command[1], rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose(state.handle_force_used_N[0],
                                   state.force_scale[0] * force, rtol=1e-12)
        np.testing.assert_allclose(state.tool_force_used_N[0],
                                   state.force_scale[0] * tool, rtol=1e-12)
    assert not state.faulted.any()
    assert np.abs(command[0] - command[2]).max() > 1e-6
