"""The ``model`` backend: the rig block behind the hardware interface, without a bus."""

from __future__ import annotations

import uuid

import numpy as np
import pytest

from haptic.common.config import load_config, override
from haptic.common.model.teleop import model_from_config
from haptic.master.hardware.interface import HardwareError, LifecycleState, create_hardware
from haptic.master.node import MasterNode
from haptic.master.settings import master_settings
from haptic.master.standalone import run_master


def _config() -> dict:
    config = override(load_config(), "master.sim.operator", "constant:fx=1,fy=-0.5,onset=0.02")
    return override(config, "master.sim.channel", f"model-{uuid.uuid4().hex}")


def test_model_backend_moves_the_handle_like_the_simulated_can_rig() -> None:
    """Same model, same node, same quantisation: the trajectories of ``model`` and ``sim``
    agree within 1 % of the travel. (Not exactly: the CAN set-up and enable sequence send a
    few SYNCs, each a rig step, so the sim rig's operator clock runs a few cycles ahead.)"""
    config = _config()
    model = model_from_config(config)
    safety = master_settings(config).safety
    runs = {}
    for name in ("model", "sim"):
        node = MasterNode.from_model(model, safety)
        with create_hardware(name, config) as hardware:
            runs[name] = run_master(hardware, node, 400, pace=False, record=True)
    a, b = runs["model"].trace, runs["sim"].trace
    travel = np.abs(b.handle_position_m[-1])
    assert np.all(np.abs(a.handle_position_m[-1] - b.handle_position_m[-1]) < 0.01 * travel)
    assert np.max(np.abs(a.handle_force_N - b.handle_force_N)[50:]) < 0.05
    assert a.handle_position_m[-1, 0] > 0.0 > a.handle_position_m[-1, 1]


def test_model_backend_lifecycle_and_bad_commands() -> None:
    hardware = create_hardware("model", _config())
    assert hardware.lifecycle_state is LifecycleState.UNCONFIGURED
    with pytest.raises(HardwareError):
        hardware.read()
    hardware.configure()
    hardware.write(np.array([0.05, 0.05]))  # inactive: ignored
    hardware.activate()
    start = hardware.read().position_m
    hardware.write(np.array([np.nan, 0.0]))  # the x axis keeps its command
    for _ in range(50):
        reading = hardware.read()
    assert np.isfinite(reading.position_m).all() and not reading.faults
    assert abs(reading.position_m[0] - start[0]) < 1e-5
    hardware.deactivate()
    hardware.cleanup()
    assert hardware.lifecycle_state is LifecycleState.UNCONFIGURED


def test_the_simulated_operator_waits_for_the_ready_lamp() -> None:
    """Before the master's forces come on, the operator's script does not run (a pushing
    operator would keep the node's small-force gate shut); its clock starts at the lamp."""
    config = _config()
    config["master"]["sim"]["operator"] = "constant:fx=3,onset=0.01"  # and onset 0 below
    config["master"]["sim"]["force_noise_std_N"] = 0.0
    hardware = create_hardware("model", config)
    hardware.configure()
    hardware.activate()
    idle = [hardware.read().force_N[0] for _ in range(200)]  # 108 ms: ten onsets
    assert max(abs(f) for f in idle) < 0.05
    hardware.present_forces_enabled(True)
    pushed = [hardware.read().force_N[0] for _ in range(200)]
    onset_cycles = int(0.01 / 0.00054)
    assert max(abs(f) for f in pushed[:onset_cycles - 1]) < 0.05
    assert pushed[-1] > 2.0
    hardware.deactivate()
    hardware.cleanup()
    config["master"]["sim"]["operator"] = "regulate:fx=3.6"  # pushes from t = 0
    hardware = create_hardware("model", config)
    hardware.configure()
    hardware.activate()
    assert max(abs(hardware.read().force_N[0]) for _ in range(50)) < 0.05
    hardware.present_forces_enabled(True)
    assert max(abs(hardware.read().force_N[0]) for _ in range(50)) > 3.0
    hardware.cleanup()
