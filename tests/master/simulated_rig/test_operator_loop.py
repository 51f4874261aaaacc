"""The regulating operator in the loop: rig block + master node + a damping tool force."""

from __future__ import annotations

import numpy as np

from haptic.common.config import load_config
from haptic.common.model.teleop import model_from_config
from haptic.master.node import MasterNode
from haptic.master.settings import master_settings
from haptic.master.simulated_rig.operator import parse_operator_spec
from haptic.master.simulated_rig.rig_block import RigModel


def test_regulating_operator_holds_the_cutting_force_against_a_damper() -> None:
    """The paper's constant-cutting-rate experiment seen from the master: the tool follows
    the handle and the clay is a damper, ft = B yh' with B = 100 N s/m. The operator who
    regulates the felt force to 3.6 N makes the force hover around 3.6 N and the handle move
    at about F/B = 0.036 m/s (the paper measured 3.6 N and 0.038 m/s)."""
    config = load_config()
    model = model_from_config(config)
    node = MasterNode.from_model(model, master_settings(config).safety)
    rig = RigModel.from_model(model, parse_operator_spec("regulate:fx=3.6,fy=0,onset=0.25"))
    rig_state = rig.initial_state(np.zeros((1, 2)), np.random.default_rng(0))
    node_state = node.initial_state(np.zeros((1, 2)))
    ts = model.sample_period_s
    command = np.zeros((1, 2))
    tool_force = np.zeros((1, 2))
    forces, speeds = [], []
    for _ in range(round(3.0 / ts)):
        sample = rig.step(rig_state, command, tool_force)
        tool_force = 100.0 * sample.handle_velocity_m_per_s
        command = node.step(node_state, sample.handle_force_measured_N,
                            sample.handle_position_m, tool_force)
        forces.append(tool_force[0])
        speeds.append(sample.handle_velocity_m_per_s[0])
    settled = slice(round(1.0 / ts), None)
    mean_force = np.mean(np.array(forces)[settled], axis=0)
    mean_speed = np.mean(np.array(speeds)[settled], axis=0)
    assert abs(mean_force[0] - 3.6) < 0.36
    assert abs(mean_speed[0] - 0.036) < 0.0036
    assert abs(mean_force[1]) < 0.05  # nothing asked along y
    assert not node_state.faulted[0]
