"""Operator models for the simulated rig: the intent force ``uh`` (N) the operator's arm
produces, per axis (x, y), vectorised over lanes.

The force the handle's sensor measures is ``fh = uh - Th yh`` (the arm impedance Th acts on
the handle's motion, see :mod:`haptic.master.simulated_rig.rig_block`); these models give ``uh``
only.
Three scripted intents, chosen by a spec string ``kind:key=value,...``:

- ``constant:fx=3,fy=0,onset=0.05,rise=0.02`` - a constant force (N) per axis, applied from
  ``onset`` (s) and ramped in linearly over ``rise`` (s).
- ``regulate:fx=3.6,fy=0,kp=0.5,ki=4,lag=0.1,max=20,onset=0,rise=0`` - the paper's
  operator who corrects the applied force to hold a cutting force: the felt tool force
  ``ft`` passes a first-order perception lag (time constant ``lag`` s), and a PI regulator
  adds ``kp e + ki integral(e)`` to the expected force, ``e = target - ft_felt``;
  ``uh = target + kp e + ki int e`` is limited to +-``max`` N with conditional integration
  (no wind-up while limited).
- ``track:shape=ramp,vx=0.038,vy=0,kp=200,kd=20,max=20,onset=0`` or
  ``track:shape=sine,ax=0.02,ay=0,freq=0.5,...`` - a position-trajectory follower: the arm
  pulls the handle towards a scripted trajectory r(t) (relative to where it grasped the
  handle) with a spring ``kp`` (N/m) and damper ``kd`` (N s/m), ``uh = kp (r - y) +
  kd (r' - y')``, limited to +-``max`` N.

A malformed spec raises :class:`~haptic.common.config.ConfigError` naming the key it came
from. Models hold no mutable state: :class:`OperatorState` is owned by the caller.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from haptic.common.config.operator_spec import parse_operator_params


@dataclass(eq=False)
class OperatorState:
    """Per-lane operator state (numpy views of the kernel's buffers: change them in place):
    elapsed time (s), regulator integral (N s), felt force (N)."""

    time_s: np.ndarray
    integral_N_s: np.ndarray
    felt_tool_force_N: np.ndarray
    buffers: tuple = field(default=(), repr=False)  # the Warp arrays behind the views

    @property
    def lanes(self) -> int:
        """Number of lanes."""
        return self.time_s.shape[0]


_KINDS = {"constant": 0, "regulate": 1, "track": 2}


def _warp() -> Any:
    import warp as wp

    wp.config.log_level = wp.LOG_WARNING
    wp.init()
    return wp


@dataclass(frozen=True)
class OperatorModel:
    """One scripted operator (see the module docstring for the kinds and parameters). Its
    law runs in a Warp kernel (:func:`haptic.master.simulated_rig.rig_kernels.operator_intent`),
    alone
    through :meth:`intent_force` or inside the rig's step."""

    kind: str
    params: dict[str, float | str] = field(default_factory=dict)

    def _p(self, name: str) -> float:
        return float(self.params.get(name, 0.0))

    def kernel_params(self, period_s: float) -> Any:
        """The parameters as the kernel's struct, for the sample period ``period_s`` (s)."""
        from haptic.master.simulated_rig import rig_kernels

        params = rig_kernels.OperatorParams()
        params.kind = _KINDS[self.kind]
        params.shape = rig_kernels.SHAPE_SINE if self.params.get("shape") == "sine" else (
            rig_kernels.SHAPE_RAMP)
        params.fx, params.fy = self._p("fx"), self._p("fy")
        params.onset_s, params.rise_s = self._p("onset"), self._p("rise")
        params.kp, params.ki, params.kd = self._p("kp"), self._p("ki"), self._p("kd")
        lag_s = self._p("lag")
        params.lag_alpha = 1.0 if lag_s == 0.0 else 1.0 - math.exp(-period_s / lag_s)
        params.max_N = self._p("max")
        params.vx, params.vy = self._p("vx"), self._p("vy")
        params.ax, params.ay = self._p("ax"), self._p("ay")
        params.omega_rad_s = 2.0 * math.pi * self._p("freq")
        return params

    def initial_state(self, lanes: int = 1) -> OperatorState:
        """Zero time, zero integral, nothing felt yet."""
        wp = _warp()
        time_s = wp.zeros(lanes, dtype=wp.float64, device="cpu")
        integral = wp.zeros((lanes, 2), dtype=wp.float64, device="cpu")
        felt = wp.zeros((lanes, 2), dtype=wp.float64, device="cpu")
        return OperatorState(time_s.numpy(), integral.numpy(), felt.numpy(),
                             (time_s, integral, felt))

    def intent_force(
        self,
        state: OperatorState,
        handle_offset_m: np.ndarray,
        handle_velocity_m_per_s: np.ndarray,
        tool_force_N: np.ndarray,
        period_s: float,
    ) -> np.ndarray:
        """The intent force uh (N), shape (lanes, 2), at the state's time; then advances the
        state by ``period_s``. ``handle_offset_m`` is the handle position relative to where
        the operator grasped it; ``tool_force_N`` is the tool force the operator feels."""
        from haptic.master.simulated_rig import rig_kernels

        wp = _warp()
        lanes = state.lanes
        inputs = np.empty((lanes, 6))
        inputs[:, 0:2] = handle_offset_m
        inputs[:, 2:4] = handle_velocity_m_per_s
        inputs[:, 4:6] = tool_force_N
        force = wp.zeros((lanes, 2), dtype=wp.float64, device="cpu")
        time_s, integral, felt = state.buffers
        wp.launch(rig_kernels.operator_kernel, dim=lanes, device="cpu",
                  inputs=[self.kernel_params(period_s), float(period_s),
                          wp.array(inputs, dtype=wp.float64, device="cpu"), time_s, integral,
                          felt, force])
        return force.numpy().copy()


def parse_operator_spec(spec: str, key: str = "operator") -> OperatorModel:
    """Parse ``kind:key=value,...`` into an :class:`OperatorModel` (the spec's grammar and
    checks: :func:`haptic.common.config.operator_spec.parse_operator_params`).

    Raises :class:`ConfigError` (naming ``key``) for an unknown kind or parameter, a value
    that is not a finite number, or a negative time, gain or limit.
    """
    kind, params = parse_operator_params(spec, key)
    return OperatorModel(kind, params)
