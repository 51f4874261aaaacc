"""The master's passivity kernel (master/passivity_kernel.py) against its numpy reference
(common/model/passivity.py): the same node, the same inputs, the same energy flows and commands."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from haptic.common.config import load_config
from haptic.common.model.passivity import PassivityPort, PassivitySettings, master_step_reference
from haptic.common.model.teleop import model_from_config
from haptic.master.node import MasterNode
from haptic.master.settings import master_settings


def test_kernel_matches_the_numpy_reference() -> None:
    config = load_config(None)
    model = model_from_config(config).with_gain(13.0)
    # the shipped limits, with the start-up gate open at once (random forces are never small)
    safety = replace(master_settings(config).safety, ramp_small_force_N=1e9,
                     ramp_small_samples=1, ramp_time_s=0.05)
    settings = PassivitySettings(credit_max_J=0.002, master_keep_J=0.0005)
    lanes = 6
    start = np.zeros((lanes, 2))
    tdpa = MasterNode.from_model(model, safety, settings)
    paper = MasterNode.from_model(model, safety)
    kernel_state = tdpa.activate(start)
    reference_state = paper.activate(start)
    port = PassivityPort.create(settings, model.sample_period_s, lanes, settings.master_keep_J)
    rng = np.random.default_rng(3)
    position = np.zeros((lanes, 2))
    peer = np.zeros(lanes)
    acted = 0
    for step in range(3000):
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
                              np.asarray(safety.workspace_max_m))
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
