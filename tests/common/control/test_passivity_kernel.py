"""The master's passivity kernel (common/control/passivity_kernel.py) against its numpy reference
(common/model/passivity.py): the same node, the same inputs, the same energy flows and commands."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from haptic.common.config import load_config
from haptic.common.model.passivity import PassivityPort, PassivitySettings, master_step_reference
from haptic.common.model.teleop import model_from_config
from haptic.master.node import MasterNode
from haptic.master.settings import master_settings


def _random_input_setup() -> tuple:
    """k = 13, the shipped limits with the start-up gate open at once (random forces are
    never small), and a small account (the credit cap and keep_J act often)."""
    config = load_config(None)
    model = model_from_config(config).with_gain(13.0)
    safety = replace(master_settings(config).safety, ramp_small_force_N=1e9,
                     ramp_small_samples=1, ramp_time_s=0.05)
    return model, safety, PassivitySettings(credit_max_J=0.002, master_keep_J=0.0005)


def test_kernel_matches_the_numpy_reference() -> None:
    model, safety, settings = _random_input_setup()
    lanes = 6
    start = np.zeros((lanes, 2))
    tdpa = MasterNode.from_model(model, safety, settings)
    paper = MasterNode.from_model(model, safety)
    kernel_state = tdpa.initial_state(start)
    reference_state = paper.initial_state(start)
    port = PassivityPort.create(settings, model.sample_period_s, lanes, settings.master_keep_J)
    rng = np.random.default_rng(3)
    position = np.zeros((lanes, 2))
    peer = np.zeros(lanes)
    target = np.full((lanes, 2), np.nan)  # the tool in handle coordinates: none yet
    acted = 0
    for step in range(3000):
        if step == 200:  # the tool's first message: a few mm off on every lane but the last
            target = rng.normal(0.0, 0.004, (lanes, 2))
            target[-1] = np.nan
        if step >= 200 and step % 50 == 0:
            target[:-1] += rng.normal(0.0, 0.002, (lanes - 1, 2))
        kernel_state.peer_target_m[...] = target
        force = rng.normal(0.0, 1.5, (lanes, 2))
        force[0] = 0.0  # a lane below the force floor
        if step == 1500:
            force[1, 0] = np.nan  # a non-finite force: the lane trips, no correction
        tool = rng.normal(0.0, 3.0, (lanes, 2))  # a reflected force that makes the port active
        if step % 7 == 0:
            peer += rng.random(lanes) * 1e-4  # the slave's handed-over energy, now and then
            kernel_state.peer_energy_J[...] = peer
            port.receive(peer)
        command = tdpa.step(kernel_state, force, position, tool)
        reference = paper.step(reference_state, force, position, tool)
        master_step_reference(port, reference_state.inputs, reference_state.command_m,
                              reference_state.last_command_m, reference_state.origin_m,
                              reference_state.faulted, safety.force_limit_N,
                              np.asarray(safety.workspace_min_m),
                              np.asarray(safety.workspace_max_m), target,
                              reference_state.forces_enabled)
        reference = reference_state.command_m.copy()
        np.testing.assert_allclose(command, reference, rtol=0, atol=1e-12)
        position = position + 0.2 * (command - position)  # a handle servo following
        acted += int(np.count_nonzero(kernel_state.passivity.correction_m))
    kernel = kernel_state.passivity
    for name in ("tank_J", "sent_J", "peer_sent_J", "input_energy_J", "output_energy_J",
                 "forgotten_energy_J", "dissipated_energy_J", "active_steps"):
        np.testing.assert_allclose(getattr(kernel, name), getattr(port, name), rtol=1e-9,
                                   atol=1e-12, err_msg=name)
    assert acted > 100  # the controller did act
    assert kernel.active_steps[0] == 0  # never below the force floor
    assert kernel_state.faulted[1]


def test_the_handle_command_drifts_to_the_tool_while_the_operator_lets_go() -> None:
    """Issue 16's drift compensation on the master: with no operator force the handle's
    command closes its gap to the tool (Ah1^-1 yt_recv, 3 mm off) at the configured rate and
    speed, for free (the port's work fh . dcmd is 0); a lane whose tool is unknown (NaN) and
    a lane pushed against the correction with an empty account stay where they are."""
    config = load_config(None)
    model = model_from_config(config).with_gain(13.0)
    safety = replace(master_settings(config).safety, ramp_small_force_N=1e9,
                     ramp_small_samples=1, ramp_time_s=0.0)
    settings = PassivitySettings(master_drift_rate_per_s=1.0, master_keep_J=0.0,
                                 master_drift_speed_max_m_per_s=0.005, force_floor_N=1e9)
    node = MasterNode.from_model(model, safety, settings)
    ts = model.sample_period_s
    start = np.zeros((3, 2))
    state = node.initial_state(start)
    target = np.array([[0.003, 0.0], [np.nan, np.nan], [0.003, 0.0]])
    force = np.zeros((3, 2))
    node.step(state, force, start, np.zeros((3, 2)))  # the start-up gate opens
    state.peer_target_m[...] = target
    force[2, 0] = -1e-9  # a touch against the correction, below any compensator response
    moved = []
    for _ in range(int(round(5.0 / ts))):
        command = node.step(state, force, start, np.zeros((3, 2)))
        moved.append(command[0, 0])
    moved = np.array(moved)
    assert moved[0] == pytest.approx(0.003 * 1.0 * ts, rel=1e-6)  # rate x gap x Ts
    assert np.all(np.diff(moved) <= 0.005 * ts * (1 + 1e-9))  # never faster than the cap
    assert 0.003 - moved[-1] == pytest.approx(0.003 * np.exp(-5.0), rel=0.01)  # 1/s
    assert command[1].tolist() == [0.0, 0.0]
    assert abs(command[2, 0]) < 1e-12  # nothing in the account to pay for it
    assert state.passivity.tank_J[0] == pytest.approx(0.0, abs=1e-15)


def test_a_standby_layer_switched_per_lane_matches_the_reference_and_off_is_the_paper() -> None:
    """The governor's run-time switch (paper mode, ``action = "tdpa"``): lanes switched on and
    off at different steps step exactly as the numpy reference with the same switches; a lane
    never switched on steps exactly as the paper's node; the energy counters stay monotone
    across a switch and a switched-on lane starts with an empty account."""
    model, safety, settings = _random_input_setup()
    lanes = 5
    start = np.zeros((lanes, 2))
    standby = MasterNode.from_model(model, safety, settings, passivity_standby=True)
    paper = MasterNode.from_model(model, safety)
    kernel_state = standby.initial_state(start)
    assert standby.passivity_standby and not kernel_state.passivity.active.any()
    reference_state = paper.initial_state(start)
    plain_state = paper.initial_state(start)
    port = PassivityPort.create(settings, model.sample_period_s, lanes, settings.master_keep_J,
                                active=False)
    switches = {300: ([1, 3, 4], True), 1200: ([3], False), 2000: ([0, 3], True)}
    rng = np.random.default_rng(5)
    position = np.zeros((lanes, 2))
    peer = np.zeros(lanes)
    sent_before = None
    for step in range(2600):
        if step in switches:
            which, on = switches[step]
            mask = np.zeros(lanes, bool)
            mask[which] = True
            if step == 1200:
                sent_before = kernel_state.passivity.sent_J.copy()
            changed = kernel_state.passivity.switch(mask, on)
            assert port.switch(mask, on).tolist() == changed.tolist()
            if on:
                assert np.all(kernel_state.passivity.tank_J[changed] == 0.0)
        force = rng.normal(0.0, 1.5, (lanes, 2))
        tool = rng.normal(0.0, 3.0, (lanes, 2))
        if step % 7 == 0:
            peer += rng.random(lanes) * 1e-4
            kernel_state.peer_energy_J[...] = peer
            port.receive(peer)
        command = standby.step(kernel_state, force, position, tool)
        paper.step(reference_state, force, position, tool)
        master_step_reference(port, reference_state.inputs, reference_state.command_m,
                              reference_state.last_command_m, reference_state.origin_m,
                              reference_state.faulted, safety.force_limit_N,
                              np.asarray(safety.workspace_min_m),
                              np.asarray(safety.workspace_max_m))
        np.testing.assert_allclose(command, reference_state.command_m, rtol=0, atol=1e-12)
        plain = paper.step(plain_state, force, position, tool)
        # lane 2 is never switched on: the paper's node, bit for bit
        assert command[2].tolist() == plain[2].tolist()
        position = position + 0.2 * (command - position)
    kernel = kernel_state.passivity
    for name in ("tank_J", "sent_J", "peer_sent_J", "input_energy_J", "output_energy_J",
                 "dissipated_energy_J", "active_steps"):
        np.testing.assert_allclose(getattr(kernel, name), getattr(port, name), rtol=1e-9,
                                   atol=1e-12, err_msg=name)
    assert kernel.active.tolist() == [True, True, False, True, True]
    assert kernel.active_steps[2] == 0 and kernel.input_energy_J[2] == 0.0
    assert kernel.peer_sent_J[2] == peer[2]  # noted while off: counted once, never twice
    assert np.all(kernel.sent_J >= sent_before) and kernel.sent_J[3] > sent_before[3]
    assert kernel.active_steps[[1, 4]].min() > 50  # the switched-on lanes acted
