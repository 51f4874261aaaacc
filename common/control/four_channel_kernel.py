"""The Warp kernel of one side of the four-channel scheme
(:mod:`haptic.common.control.four_channel`, the numpy reference): every lane in one launch, one
thread per lane, both axes.

tests/common/control/test_four_channel.py runs both on the same inputs, non-finite ones
included.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from haptic.common.control.four_channel import SideLaw, SideState
from haptic.common.control.warp_lanes import DEVICE, LaneBuffers, warp

wp.config.log_level = wp.LOG_WARNING


@wp.struct
class SideGains:
    """A side's law as the kernel reads it (SI)."""

    period_s: wp.float64
    mass_kg: wp.float64
    stiffness_N_per_m: wp.float64
    implicit_mass_kg: wp.float64
    own_force_gain: wp.float64
    peer_mass_kg: wp.float64
    peer_damping_N_s_per_m: wp.float64
    peer_stiffness_N_per_m: wp.float64
    peer_force_gain: wp.float64
    force_limit_N: wp.float64
    speed_limit_m_per_s: wp.float64
    position_limit_m: wp.float64


@wp.func
def measured_force(force: wp.float64, limit: wp.float64) -> wp.float64:
    """The side's own force as the law uses it: 0 when non-finite, clamped."""
    if not wp.isfinite(force):
        return wp.float64(0.0)
    return wp.clamp(force, -limit, limit)


@wp.func
def peer_message_usable(lane: int, fresh: wp.array(dtype=wp.bool),
                        position: wp.array2d(dtype=wp.float64),
                        velocity: wp.array2d(dtype=wp.float64),
                        force: wp.array2d(dtype=wp.float64)) -> bool:
    """A fresh message whose every field is finite."""
    ok = fresh[lane]
    for axis in range(2):
        ok = ok and wp.isfinite(position[lane, axis]) and wp.isfinite(velocity[lane, axis])
        ok = ok and wp.isfinite(force[lane, axis])
    return ok


@wp.kernel
def four_channel_side_kernel(
    own_force: wp.array2d(dtype=wp.float64),
    peer_position_in: wp.array2d(dtype=wp.float64),
    peer_velocity_in: wp.array2d(dtype=wp.float64),
    peer_force_in: wp.array2d(dtype=wp.float64),
    fresh: wp.array(dtype=wp.bool),
    position: wp.array2d(dtype=wp.float64),
    velocity: wp.array2d(dtype=wp.float64),
    peer_position: wp.array2d(dtype=wp.float64),
    peer_velocity: wp.array2d(dtype=wp.float64),
    peer_force: wp.array2d(dtype=wp.float64),
    gains: SideGains,
):
    """One period of one lane: take the peer's message if usable, then one implicit Euler
    step of the side's virtual manipulator under the four channels."""
    lane = wp.tid()
    ts = gains.period_s
    vlim = gains.speed_limit_m_per_s
    xlim = gains.position_limit_m
    flim = gains.force_limit_N
    take = peer_message_usable(lane, fresh, peer_position_in, peer_velocity_in, peer_force_in)
    for axis in range(2):
        accel = wp.float64(0.0)
        if take:
            new_velocity = wp.clamp(peer_velocity_in[lane, axis], -vlim, vlim)
            accel = (new_velocity - peer_velocity[lane, axis]) / ts
            peer_velocity[lane, axis] = new_velocity
            peer_position[lane, axis] = wp.clamp(peer_position_in[lane, axis], -xlim, xlim)
            peer_force[lane, axis] = wp.clamp(peer_force_in[lane, axis], -flim, flim)
        own = measured_force(own_force[lane, axis], flim)
        drive = (gains.own_force_gain * own + gains.peer_mass_kg * accel
                 + gains.peer_damping_N_s_per_m * peer_velocity[lane, axis]
                 + gains.peer_stiffness_N_per_m * peer_position[lane, axis]
                 + gains.peer_force_gain * peer_force[lane, axis])
        x = position[lane, axis]
        v = (gains.mass_kg * velocity[lane, axis]
             + ts * (drive - gains.stiffness_N_per_m * x)) / gains.implicit_mass_kg
        v = wp.clamp(v, -vlim, vlim)
        velocity[lane, axis] = v
        position[lane, axis] = wp.clamp(x + ts * v, -xlim, xlim)


class FourChannelSideKernel:
    """One side over ``lanes`` lanes on the Warp kernel; :attr:`state` is a
    :class:`SideState` of numpy views of the kernel's buffers."""

    _INPUTS = ("own_force", "peer_position_in", "peer_velocity_in", "peer_force_in")

    def __init__(self, law: SideLaw, start_m: np.ndarray) -> None:
        wp = warp()
        gains = SideGains()
        gains.period_s = law.period_s
        gains.mass_kg = law.mass_kg
        gains.stiffness_N_per_m = law.stiffness_N_per_m
        gains.implicit_mass_kg = law.implicit_mass_kg
        gains.own_force_gain = law.own_force_gain
        gains.peer_mass_kg = law.peer.mass_kg
        gains.peer_damping_N_s_per_m = law.peer.damping_N_s_per_m
        gains.peer_stiffness_N_per_m = law.peer.stiffness_N_per_m
        gains.peer_force_gain = law.peer_force_gain
        gains.force_limit_N = law.force_limit_N
        gains.speed_limit_m_per_s = law.speed_limit_m_per_s
        gains.position_limit_m = law.position_limit_m
        start = SideState.create(start_m)
        self.lanes = start.position_m.shape[0]
        self.buffers = LaneBuffers()
        for name in self._INPUTS:
            self.buffers.add(name, np.zeros_like(start.position_m))
        for name in start.names:
            self.buffers.add(name, getattr(start, name))
        self.buffers.add("fresh", np.zeros(self.lanes, bool), wp.bool)
        self.state = SideState(*(self.buffers.view[name] for name in start.names))
        arrays = self.buffers.arrays
        #: the launch, recorded once over the persistent buffers (a node may replay it)
        self.command = wp.launch(four_channel_side_kernel, dim=self.lanes, device=DEVICE, inputs=[
            *(arrays[name] for name in self._INPUTS), arrays["fresh"],
            *(arrays[name] for name in start.names), gains], record_cmd=True)

    def step(self, own_force_N: np.ndarray, peer_position_m: np.ndarray,
             peer_velocity_m_per_s: np.ndarray, peer_force_N: np.ndarray, fresh: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:
        """One period (see :func:`haptic.common.control.four_channel.side_step_reference`):
        (position command m, velocity m/s), views of the kernel's buffers."""
        view = self.buffers.view
        for name, value in zip(self._INPUTS, (own_force_N, peer_position_m,
                                              peer_velocity_m_per_s, peer_force_N), strict=True):
            view[name][...] = value
        view["fresh"][...] = fresh
        self.command.launch()
        return view["position_m"], view["velocity_m_per_s"]


__all__ = ["FourChannelSideKernel", "SideGains", "four_channel_side_kernel"]
