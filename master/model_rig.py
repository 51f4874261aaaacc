"""The ``model`` backend: the rig block stepped directly behind the hardware interface.

Where ``sim`` (:mod:`haptic.master.sim_rig`) runs the rig model behind emulated CiA 402 drives
and the force sensor on python-can's virtual bus (the real driver's code path, a thread and
about 170 us of frame traffic per cycle), ``model`` steps the same
:class:`~haptic.master.rig_model.RigModel` inside ``read()``: no bus, no thread, about 25 us.
It keeps the timing contract (a command written in cycle k is applied at SYNC k+1) and the
sensor's quantisation (encoder counts and force counts from ``[master.can]``), so the loop
sees the same signals; it cannot inject bus faults. Use it where the loop, not the drives, is
under test: the loop benchmark, long sessions on a small machine.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from haptic.common.model import model_from_config
from haptic.master.hardware import (
    HandleHardware,
    HandleReading,
    HardwareError,
    LifecycleState,
    register_hardware,
)
from haptic.master.rig_model import RigModel
from haptic.master.settings import CanSettings, master_settings


class ModelRigHardware(HandleHardware):
    """The rig block as handle hardware (one lane). ``initial_position_m`` (x, y) in m;
    ``rng`` drives the sensor noise."""

    def __init__(self, model: RigModel, can: CanSettings,
                 initial_position_m: tuple[float, float], rng: np.random.Generator) -> None:
        self.model = model
        self.can = can
        self._initial = np.asarray([initial_position_m], float)
        self._rng = rng
        self._state = None
        self._lifecycle = LifecycleState.UNCONFIGURED
        self._target = np.full((1, 2), np.nan)
        self._tool_force = np.zeros((1, 2))
        self._force_step = np.asarray(can.force_scale_N_per_count, float)
        self._force_offset = np.asarray(can.force_offset_count, float)
        self.cycle = 0

    @property
    def lifecycle_state(self) -> LifecycleState:
        return self._lifecycle

    def configure(self) -> None:
        if self._lifecycle is not LifecycleState.UNCONFIGURED:
            raise HardwareError(f"configure from {self._lifecycle.value}")
        self._state = self.model.initial_state(self._initial, self._rng)
        self._lifecycle = LifecycleState.INACTIVE

    def activate(self) -> None:
        if self._lifecycle is not LifecycleState.INACTIVE:
            raise HardwareError(f"activate from {self._lifecycle.value}")
        self._target = np.full((1, 2), np.nan)  # hold: the applied command stays
        self._lifecycle = LifecycleState.ACTIVE

    def deactivate(self) -> None:
        if self._lifecycle is LifecycleState.ACTIVE:
            self._target = np.full((1, 2), np.nan)
            self._lifecycle = LifecycleState.INACTIVE

    def cleanup(self) -> None:
        self._lifecycle = LifecycleState.UNCONFIGURED
        self._state = None

    def read(self) -> HandleReading:
        if self._state is None:
            raise HardwareError("read before configure")
        sample = self.model.step(self._state, self._target, self._tool_force)
        self._target = np.full((1, 2), np.nan)
        self.cycle += 1
        counts = self.can.counts_from_metres(sample.handle_position_m[0])
        position = self.can.metres_from_counts(counts)
        raw = np.rint(sample.handle_force_measured_N[0] / self._force_step + self._force_offset)
        force = (raw - self._force_offset) * self._force_step
        return HandleReading(force, position, self.cycle)

    def write(self, position_command_m: np.ndarray) -> None:
        if self._lifecycle is not LifecycleState.ACTIVE:
            return
        command = np.asarray(position_command_m, float).reshape(1, 2)
        # as the CAN driver: a non-finite command is never applied (the previous one stays)
        self._target = np.where(np.isfinite(command), command, np.nan)

    def present_tool_force(self, tool_force_N: np.ndarray) -> None:
        self._tool_force = np.asarray(tool_force_N, float).reshape(1, 2).copy()


@register_hardware("model")
def model_rig_hardware(config: dict[str, Any]) -> ModelRigHardware:
    """The ``model`` backend of a validated configuration (``[model]``, ``[master.can]`` for
    the quantisation, ``[master.sim]`` for the operator, noise, seed and start)."""
    settings = master_settings(config)
    sim = settings.sim
    rig = RigModel.from_model(model_from_config(config), sim.operator, sim.force_noise_std_N)
    return ModelRigHardware(rig, settings.can, sim.initial_position_m,
                            np.random.default_rng(sim.seed))
