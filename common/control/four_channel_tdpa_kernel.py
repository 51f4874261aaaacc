"""One side of ``four-channel-tdpa`` on Warp: the four-channel law's kernel
(:mod:`haptic.common.control.four_channel_kernel`) and then the master's TDPA kernel
(:mod:`haptic.common.control.passivity_kernel`) over the same position buffer, every lane in
one launch each.

Both sides of the four-channel law command a position from a measured force, the contract of
the master's passivity kernel (receive the peer's energy, yield along the port's force by what
the account lacks, observe the step's work), so both sides run that kernel unchanged: the
master with the operator's force as the port force, the slave with the environment's force on
the tool (``-fe``). No drift stage (its rate is 0: the law's position channels pull the sides
together), no fault, the workspace the law's position limit. The numpy reference is
:func:`haptic.common.control.four_channel_passivity.passive_side_step_reference`;
tests/common/control/test_four_channel_tdpa_kernel.py runs both on the same inputs. Both programs
(the four-channel mode with its passivity layer) and the comparison's lanes run it.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import warp as wp

from haptic.common.control import passivity_kernel
from haptic.common.control.four_channel import SideLaw
from haptic.common.control.four_channel_kernel import FourChannelSideKernel
from haptic.common.control.passivity_kernel import PassivityLimits
from haptic.common.control.warp_lanes import DEVICE, warp
from haptic.common.model.passivity import PassivityPort, PassivitySettings

wp.config.log_level = wp.LOG_WARNING

_TYPES = {np.float64: "float64", np.int64: "int64", np.bool_: "bool"}


def _limits(law: SideLaw, settings: PassivitySettings, keep_J: float) -> PassivityLimits:
    """The TDPA kernel's limits for one four-channel side (no drift stage)."""
    limits = PassivityLimits()
    limits.period_s = law.period_s
    limits.force_limit_N = law.force_limit_N
    limits.force_floor_N = settings.force_floor_N
    limits.conductance_max_m_per_N_s = settings.conductance_max_m_per_N_s
    limits.correction_speed_max_m_per_s = settings.correction_speed_max_m_per_s
    limits.correction_accel_max_m_per_s2 = settings.correction_accel_max_m_per_s2
    limits.credit_max_J = settings.credit_max_J
    limits.keep_J = keep_J
    limits.workspace_min_x_m = limits.workspace_min_y_m = -law.position_limit_m
    limits.workspace_max_x_m = limits.workspace_max_y_m = law.position_limit_m
    limits.drift_rate_per_s = 0.0
    limits.drift_speed_max_m_per_s = 0.0
    return limits


class PassiveFourChannelSideKernel:
    """One four-channel side with the TDPA over ``lanes`` lanes: :attr:`state` (the law's
    :class:`SideState`, views of its kernel's buffers) and :attr:`port` (a
    :class:`PassivityPort` of views of the TDPA kernel's buffers: ``port.sent_J`` is what the
    side's messages carry)."""

    def __init__(self, law: SideLaw, settings: PassivitySettings, keep_J: float,
                 port_sign: float, start_m: np.ndarray) -> None:
        warp()
        self.law = FourChannelSideKernel(law, start_m)
        self.state = self.law.state
        self.port_sign = float(port_sign)
        lanes = self.law.lanes
        port: list[Any] = []

        def zeros(shape: tuple, dtype: Any) -> np.ndarray:
            array = wp.zeros(shape, dtype=getattr(wp, _TYPES[dtype]), device=DEVICE)
            port.append(array)
            return array.numpy()

        self.port = PassivityPort.create(settings, law.period_s, lanes, keep_J, zeros)
        self.port.previous_position_m[...] = self.state.position_m
        vectors = {name: wp.zeros(shape, dtype=wp.float64, device=DEVICE) for name, shape in (
            ("force", (lanes, 2)), ("peer_energy", lanes), ("target", (lanes, 2)),
            ("last_command", (lanes, 2)), ("origin", (lanes, 2)))}
        vectors["target"].fill_(np.nan)  # no drift target
        vectors["last_command"].assign(np.ascontiguousarray(self.state.position_m))
        flags = [wp.zeros(lanes, dtype=wp.bool, device=DEVICE) for _ in range(2)]
        self._view = {name: array.numpy() for name, array in vectors.items()}
        self._buffers = (port, vectors, flags)  # kept alive with the recorded launch
        # PassivityPort's field order: tank, sent, peer_sent, input, output, forgotten,
        # dissipated, correction, damper force, active steps, previous position, active;
        # the flags: enabled (no drift), faulted (never)
        self._launch = wp.launch(
            passivity_kernel.master_passivity_kernel, dim=lanes, device=DEVICE,
            inputs=[vectors["force"], vectors["peer_energy"], vectors["target"], *flags,
                    self.law.buffers.arrays["position_m"], vectors["last_command"],
                    vectors["origin"], port[10], *port[0:8], port[9], port[11],
                    _limits(law, settings, keep_J)],
            record_cmd=True)

    def step(self, own_force_N: np.ndarray, peer_position_m: np.ndarray,
             peer_velocity_m_per_s: np.ndarray, peer_force_N: np.ndarray,
             peer_energy_J: np.ndarray, fresh: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One period (see :func:`haptic.common.control.four_channel_passivity.
        passive_side_step_reference`): (position command m, velocity m/s), views of the
        kernels' buffers."""
        position, velocity = self.law.step(own_force_N, peer_position_m, peer_velocity_m_per_s,
                                           peer_force_N, fresh)
        self._view["force"][...] = self.port_sign * np.asarray(own_force_N, float)
        self._view["peer_energy"][...] = np.where(np.asarray(fresh, bool), peer_energy_J,
                                                  np.nan)
        self._launch.launch()
        return position, velocity


__all__ = ["PassiveFourChannelSideKernel"]
