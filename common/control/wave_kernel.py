"""The Warp kernel of one side's wave-variable port (:mod:`haptic.common.control.wave`, the
numpy reference): every lane in one launch, one thread per lane, both axes.

tests/common/control/test_wave.py runs both on the same inputs, non-finite ones included.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from haptic.common.control.warp_lanes import DEVICE, LaneBuffers, warp
from haptic.common.control.wave import WavePortState, WaveSettings

wp.config.log_level = wp.LOG_WARNING


@wp.struct
class WaveLimits:
    """The side's settings as the kernel reads them (SI; ``sign`` +1 master, -1 slave)."""

    period_s: wp.float64
    impedance_N_s_per_m: wp.float64
    filter_weight: wp.float64
    drift_gain_per_s: wp.float64
    reserve_max_J: wp.float64
    force_limit_N: wp.float64
    wave_limit: wp.float64
    sign: wp.float64


@wp.func
def port_force(force: wp.float64, limit: wp.float64) -> wp.float64:
    """The measured force as the law uses it: 0 when non-finite, clamped to the limit."""
    if not wp.isfinite(force):
        return wp.float64(0.0)
    return wp.clamp(force, -limit, limit)


@wp.func
def incoming_wave(wave: wp.float64, fresh: bool, limit: wp.float64) -> wp.float64:
    """The received wave as the law counts it: 0 when stale or non-finite, clamped."""
    if not fresh or not wp.isfinite(wave):
        return wp.float64(0.0)
    return wp.clamp(wave, -limit, limit)


@wp.func
def energy_guarded(desired: wp.float64, received: wp.float64, reserve_J: wp.float64,
                   period_s: wp.float64) -> wp.float64:
    """The used wave: ``desired`` clamped so its energy stays within what was received plus
    the reserve."""
    bound = wp.sqrt(received * received + wp.float64(2.0) * reserve_J / period_s)
    return wp.clamp(desired, -bound, bound)


@wp.kernel
def wave_port_kernel(
    force: wp.array2d(dtype=wp.float64),
    received_wave: wp.array2d(dtype=wp.float64),
    received_integral_in: wp.array2d(dtype=wp.float64),
    fresh: wp.array(dtype=wp.bool),
    filtered: wp.array2d(dtype=wp.float64),
    reserve: wp.array2d(dtype=wp.float64),
    used_integral: wp.array2d(dtype=wp.float64),
    received_integral: wp.array2d(dtype=wp.float64),
    sent_integral: wp.array2d(dtype=wp.float64),
    velocity: wp.array2d(dtype=wp.float64),
    sent: wp.array2d(dtype=wp.float64),
    limits: WaveLimits,
):
    """One period of one lane: filter, drift correction and energy guard on the received
    wave, then the side's velocity command and the wave it sends."""
    lane = wp.tid()
    ts = limits.period_s
    b = limits.impedance_N_s_per_m
    root = wp.sqrt(wp.float64(2.0) * b)
    is_fresh = fresh[lane]
    for axis in range(2):
        f = port_force(force[lane, axis], limits.force_limit_N)
        r = incoming_wave(received_wave[lane, axis], is_fresh, limits.wave_limit)
        integral = received_integral_in[lane, axis]
        if is_fresh and wp.isfinite(integral):
            received_integral[lane, axis] = integral
        y = filtered[lane, axis]
        y = y + limits.filter_weight * (r - y)
        filtered[lane, axis] = y
        desired = y + limits.drift_gain_per_s * (
            received_integral[lane, axis] - used_integral[lane, axis])
        used = energy_guarded(desired, r, reserve[lane, axis], ts)
        account = wp.max(reserve[lane, axis] + (r * r - used * used) * (ts / wp.float64(2.0)),
                         wp.float64(0.0))
        reserve[lane, axis] = wp.min(account, limits.reserve_max_J)
        used_integral[lane, axis] = used_integral[lane, axis] + used * ts
        velocity[lane, axis] = (root * used + limits.sign * f) / b
        out = used + limits.sign * (wp.float64(2.0) * f / root)
        sent[lane, axis] = out
        sent_integral[lane, axis] = sent_integral[lane, axis] + out * ts


class WavePortKernel:
    """One side's wave port over ``lanes`` lanes on the Warp kernel; :attr:`state` is a
    :class:`WavePortState` of numpy views of the kernel's buffers."""

    #: the :class:`WavePortState` fields, in the kernel's argument order
    STATE_FIELDS = ("filtered", "reserve_J", "used_integral", "received_integral", "sent_integral")

    def __init__(self, settings: WaveSettings, lanes: int, sign: float) -> None:
        wp = warp()
        self.settings = settings
        self.lanes = lanes
        limits = WaveLimits()
        limits.period_s = settings.period_s
        limits.impedance_N_s_per_m = settings.impedance_N_s_per_m
        limits.filter_weight = settings.filter_weight
        limits.drift_gain_per_s = settings.drift_gain_per_s
        limits.reserve_max_J = settings.reserve_max_J
        limits.force_limit_N = settings.force_limit_N
        limits.wave_limit = settings.wave_limit
        limits.sign = float(sign)
        zeros = np.zeros((lanes, 2))
        self.buffers = LaneBuffers()
        for name in ("force", "received_wave", "received_integral_in", *self.STATE_FIELDS,
                     "velocity", "sent"):
            self.buffers.add(name, zeros)
        self.buffers.add("fresh", np.zeros(lanes, bool), wp.bool)
        self.state = WavePortState(*(self.buffers.view[name] for name in self.STATE_FIELDS))
        arrays = self.buffers.arrays
        #: the launch, recorded once over the persistent buffers (a node may replay it)
        self.command = wp.launch(wave_port_kernel, dim=lanes, device=DEVICE, inputs=[
            arrays["force"], arrays["received_wave"], arrays["received_integral_in"],
            arrays["fresh"], *(arrays[name] for name in self.STATE_FIELDS), arrays["velocity"],
            arrays["sent"], limits], record_cmd=True)

    def step(self, force_N: np.ndarray, received_wave: np.ndarray,
             received_integral: np.ndarray, fresh: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One period (see :func:`haptic.common.control.wave.wave_port_step_reference`):
        (velocity command m/s, wave to send, its integral), views of the kernel's buffers."""
        view = self.buffers.view
        view["force"][...] = force_N
        view["received_wave"][...] = received_wave
        view["received_integral_in"][...] = received_integral
        view["fresh"][...] = fresh
        self.command.launch()
        return view["velocity"], view["sent"], view["sent_integral"]


__all__ = ["WaveLimits", "WavePortKernel", "wave_port_kernel"]
