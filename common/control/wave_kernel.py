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
    reserve_floor_J: wp.float64
    loss_floor_fraction: wp.float64
    stale_weight: wp.float64
    credit_per_period_J: wp.float64
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
def credited(gained: wp.float64, counted: bool, periods: wp.float64,
             per_period_J: wp.float64) -> wp.float64:
    """The credit of a message's energy counter: what it gained, within what the sender could
    have sent in ``periods`` (0 for a stale message or a non-finite counter)."""
    if not counted:
        return wp.float64(0.0)
    return wp.clamp(gained, wp.float64(0.0), periods * per_period_J)


@wp.func
def spend_bound(filtered: wp.float64, reserve_J: wp.float64, stale_share: wp.float64,
                limits: WaveLimits) -> wp.float64:
    """The largest used wave: the filtered wave within the whole reserve, the correction
    within what lies above the loss floor."""
    floor = limits.reserve_floor_J * wp.min(wp.float64(1.0),
                                            stale_share / limits.loss_floor_fraction)
    whole = wp.sqrt(wp.float64(2.0) * reserve_J / limits.period_s)
    kept = wp.clamp(filtered, -whole, whole)
    spare = wp.sqrt(kept * kept + wp.float64(2.0) * wp.max(reserve_J - floor, wp.float64(0.0))
                    / limits.period_s)
    return wp.min(spare, whole)


@wp.kernel
def wave_port_kernel(
    force: wp.array2d(dtype=wp.float64),
    received_wave: wp.array2d(dtype=wp.float64),
    received_integral_in: wp.array2d(dtype=wp.float64),
    received_energy_in: wp.array2d(dtype=wp.float64),
    fresh: wp.array(dtype=wp.bool),
    filtered: wp.array2d(dtype=wp.float64),
    reserve: wp.array2d(dtype=wp.float64),
    used_integral: wp.array2d(dtype=wp.float64),
    received_integral: wp.array2d(dtype=wp.float64),
    sent_integral: wp.array2d(dtype=wp.float64),
    held_wave: wp.array2d(dtype=wp.float64),
    credited_energy: wp.array2d(dtype=wp.float64),
    sent_energy: wp.array2d(dtype=wp.float64),
    periods_uncredited: wp.array2d(dtype=wp.float64),
    stale_share: wp.array2d(dtype=wp.float64),
    velocity: wp.array2d(dtype=wp.float64),
    sent: wp.array2d(dtype=wp.float64),
    limits: WaveLimits,
):
    """One period of one lane: the held wave, the energy credit, the filter, the drift
    correction within the reserve, then the side's velocity command and the wave it sends."""
    lane = wp.tid()
    ts = limits.period_s
    b = limits.impedance_N_s_per_m
    root = wp.sqrt(wp.float64(2.0) * b)
    half_ts = ts / wp.float64(2.0)
    is_fresh = fresh[lane]
    for axis in range(2):
        f = port_force(force[lane, axis], limits.force_limit_N)
        wave = received_wave[lane, axis]
        stale = wp.float64(1.0)
        if is_fresh and wp.isfinite(wave):
            held_wave[lane, axis] = wp.clamp(wave, -limits.wave_limit, limits.wave_limit)
            stale = wp.float64(0.0)
        share = stale_share[lane, axis]
        share = share + limits.stale_weight * (stale - share)
        stale_share[lane, axis] = share
        integral = received_integral_in[lane, axis]
        if is_fresh and wp.isfinite(integral):
            received_integral[lane, axis] = integral
        periods = periods_uncredited[lane, axis] + wp.float64(1.0)
        energy = received_energy_in[lane, axis]
        counted = is_fresh and wp.isfinite(energy)
        credit = credited(energy - credited_energy[lane, axis], counted, periods,
                          limits.credit_per_period_J)
        credited_energy[lane, axis] = credited_energy[lane, axis] + credit
        if counted:
            periods = wp.float64(0.0)
        periods_uncredited[lane, axis] = periods
        account = wp.min(reserve[lane, axis] + credit, limits.reserve_max_J)
        y = filtered[lane, axis]
        y = y + limits.filter_weight * (held_wave[lane, axis] - y)
        filtered[lane, axis] = y
        desired = y + limits.drift_gain_per_s * (
            received_integral[lane, axis] - used_integral[lane, axis])
        bound = spend_bound(y, account, share, limits)
        used = wp.clamp(desired, -bound, bound)
        reserve[lane, axis] = wp.max(account - used * used * half_ts, wp.float64(0.0))
        used_integral[lane, axis] = used_integral[lane, axis] + used * ts
        velocity[lane, axis] = (root * used + limits.sign * f) / b
        out = used + limits.sign * (wp.float64(2.0) * f / root)
        sent[lane, axis] = out
        sent_integral[lane, axis] = sent_integral[lane, axis] + out * ts
        sent_energy[lane, axis] = sent_energy[lane, axis] + out * out * half_ts


class WavePortKernel:
    """One side's wave port over ``lanes`` lanes on the Warp kernel; :attr:`state` is a
    :class:`WavePortState` of numpy views of the kernel's buffers."""

    #: the :class:`WavePortState` fields, in the kernel's argument order
    STATE_FIELDS = ("filtered", "reserve_J", "used_integral", "received_integral",
                    "sent_integral", "held_wave", "credited_energy_J", "sent_energy_J",
                    "periods_uncredited", "stale_share")

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
        limits.reserve_floor_J = settings.reserve_floor_J
        limits.loss_floor_fraction = settings.loss_floor_fraction
        limits.stale_weight = settings.stale_weight
        limits.credit_per_period_J = settings.credit_per_period_J
        limits.force_limit_N = settings.force_limit_N
        limits.wave_limit = settings.wave_limit
        limits.sign = float(sign)
        zeros = np.zeros((lanes, 2))
        self.buffers = LaneBuffers()
        for name in ("force", "received_wave", "received_integral_in", "received_energy_in",
                     *self.STATE_FIELDS,
                     "velocity", "sent"):
            self.buffers.add(name, zeros)
        self.buffers.add("fresh", np.zeros(lanes, bool), wp.bool)
        self.state = WavePortState(*(self.buffers.view[name] for name in self.STATE_FIELDS))
        arrays = self.buffers.arrays
        #: the launch, recorded once over the persistent buffers (a node may replay it)
        self.command = wp.launch(wave_port_kernel, dim=lanes, device=DEVICE, inputs=[
            arrays["force"], arrays["received_wave"], arrays["received_integral_in"],
            arrays["received_energy_in"], arrays["fresh"],
            *(arrays[name] for name in self.STATE_FIELDS), arrays["velocity"], arrays["sent"],
            limits], record_cmd=True)

    def step(self, force_N: np.ndarray, received_wave: np.ndarray,
             received_integral: np.ndarray, received_energy_J: np.ndarray, fresh: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """One period (see :func:`haptic.common.control.wave.wave_port_step_reference`):
        (velocity command m/s, wave to send, its integral, its energy J), views of the
        kernel's buffers."""
        view = self.buffers.view
        view["force"][...] = force_N
        view["received_wave"][...] = received_wave
        view["received_integral_in"][...] = received_integral
        view["received_energy_in"][...] = received_energy_J
        view["fresh"][...] = fresh
        self.command.launch()
        return view["velocity"], view["sent"], view["sent_integral"], view["sent_energy_J"]


__all__ = ["WaveLimits", "WavePortKernel", "wave_port_kernel"]
