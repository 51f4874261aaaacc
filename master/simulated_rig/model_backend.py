"""The ``model`` backend: the rig block stepped directly behind the hardware interface.

Where ``sim`` (:mod:`haptic.master.simulated_rig.can_devices`) runs the rig model behind
emulated CiA 402 drives and the force sensor on python-can's virtual bus (the real driver's
code path, a thread and the frame traffic of every cycle), ``model`` steps the same
:class:`~haptic.master.simulated_rig.rig_block.RigModel` kernel inside ``read()``: no bus, no
thread, only the model's step.
It keeps the timing contract (a command written in cycle k is applied at SYNC k+1) and the
sensor's quantisation (encoder counts and force counts from ``[master.can]``), so the loop
sees the same signals; it cannot inject bus faults. Use it where the loop, not the drives, is
under test: the loop benchmark, long sessions on a small machine.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from haptic.common.model.teleop import model_from_config
from haptic.master.hardware.interface import (
    HandleHardware,
    HandleReading,
    HardwareError,
    LifecycleState,
)
from haptic.master.settings import CanSettings, master_settings
from haptic.master.simulated_rig.rig_block import RigModel


class ModelRigHardware(HandleHardware):
    """The rig block as handle hardware (one lane). ``initial_position_m`` (x, y) in m;
    ``rng`` drives the sensor noise. ``write()`` and ``present_tool_force()`` fill the rig
    kernel's input buffers; ``read()`` steps it and quantises the sample as the encoders and
    the force sensor do."""

    def __init__(self, model: RigModel, can: CanSettings,
                 initial_position_m: tuple[float, float], rng: np.random.Generator) -> None:
        self.model = model
        self.can = can
        self._initial = np.asarray([initial_position_m], float)
        self._rng = rng
        self._state = None
        self._operator_grasped = False
        self._lifecycle = LifecycleState.UNCONFIGURED
        self._metres_per_count = can.metres_per_count
        self._force_step = tuple(float(v) for v in can.force_scale_N_per_count)
        self._force_offset = tuple(float(v) for v in can.force_offset_count)
        self.cycle = 0

    @property
    def lifecycle_state(self) -> LifecycleState:
        return self._lifecycle

    def configure(self) -> None:
        if self._lifecycle is not LifecycleState.UNCONFIGURED:
            raise HardwareError(f"configure from {self._lifecycle.value}")
        self._state = self.model.initial_state(self._initial, self._rng)
        self._operator_grasped = False
        self._lifecycle = LifecycleState.INACTIVE

    def activate(self) -> None:
        if self._lifecycle is not LifecycleState.INACTIVE:
            raise HardwareError(f"activate from {self._lifecycle.value}")
        self._state.target_m[...] = np.nan  # hold: the applied command stays
        self._lifecycle = LifecycleState.ACTIVE

    def deactivate(self) -> None:
        if self._lifecycle is LifecycleState.ACTIVE:
            self._state.target_m[...] = np.nan
            self._lifecycle = LifecycleState.INACTIVE

    def cleanup(self) -> None:
        self._lifecycle = LifecycleState.UNCONFIGURED
        self._state = None

    def read(self) -> HandleReading:
        state = self._state
        if state is None:
            raise HardwareError("read before configure")
        if not self._operator_grasped:
            # the operator waits for the ready lamp: the script's clock has not started
            # (one period before its start: no intent yet, even with onset 0)
            state.operator.time_s[0] = -self.model.period_s
            state.operator.integral_N_s[0] = 0.0
        sample = self.model.step_inputs(state)
        target = state.target_m
        target[0, 0] = target[0, 1] = np.nan  # a command is applied at one SYNC only
        self.cycle += 1
        x, y, _, _, _, _, _, _, _, _, fx, fy = sample[0].tolist()
        step, offset = self._force_step, self._force_offset
        per_count = self._metres_per_count
        position = np.array((_quantise(x, per_count, 0.0), _quantise(y, per_count, 0.0)))
        force = np.array((_quantise(fx, step[0], offset[0]), _quantise(fy, step[1], offset[1])))
        return HandleReading(force, position, self.cycle)

    def write(self, position_command_m: np.ndarray) -> None:
        if self._lifecycle is not LifecycleState.ACTIVE:
            return
        # as the CAN driver: a non-finite command is never applied (the previous one stays;
        # the kernel ignores a NaN target per axis)
        x, y = np.asarray(position_command_m, float).reshape(2).tolist()
        target = self._state.target_m
        target[0, 0] = x if math.isfinite(x) else math.nan
        target[0, 1] = y if math.isfinite(y) else math.nan

    def present_tool_force(self, tool_force_N: np.ndarray) -> None:
        if self._state is not None:
            self._state.tool_force_N[0] = np.asarray(tool_force_N, float).reshape(2)

    def present_forces_enabled(self, enabled: bool) -> None:
        if enabled:
            self._operator_grasped = True


def _quantise(value: float, step: float, offset_counts: float) -> float:
    """``value`` through a converter of ``step`` units per count with an offset (counts),
    rounded half to even as the drives' and sensor's conversions; NaN if not finite."""
    if not math.isfinite(value):
        return math.nan
    return (round(value / step + offset_counts) - offset_counts) * step


def model_rig_hardware(config: dict[str, Any]) -> ModelRigHardware:
    """The ``model`` backend of a validated configuration (``[model]``, ``[master.can]`` for
    the quantisation, ``[master.sim]`` for the operator, noise, seed and start)."""
    settings = master_settings(config)
    sim = settings.sim
    rig = RigModel.from_model(model_from_config(config), sim.operator, sim.force_noise_std_N)
    return ModelRigHardware(rig, settings.can, sim.initial_position_m,
                            np.random.default_rng(sim.seed))
