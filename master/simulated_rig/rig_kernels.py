"""NVIDIA Warp kernels of the simulated rig: the handle axes and the scripted operator, one
thread per lane (kept in a plain module so Warp can compile them).

:func:`operator_intent` is the operator models' law (:mod:`haptic.master.simulated_rig.operator`
documents the kinds and parameters); :data:`operator_kernel` runs it alone,
:func:`rig_step_kernel` (compiled for the number of plant states) inside one SYNC of the rig
(:mod:`haptic.master.simulated_rig.rig_block`). The model rig of the real-time master steps one lane
per tick through a recorded launch; the lockstep simulator steps a whole sweep's lanes with
the same kernel. Arithmetic is float64 throughout.
"""

from __future__ import annotations

import functools
from typing import Any

import warp as wp

wp.config.log_level = wp.LOG_WARNING  # the programs print JSON on stdout

#: Operator kinds as the kernel knows them.
KIND_CONSTANT = 0
KIND_REGULATE = 1
KIND_TRACK = 2
#: Track shapes.
SHAPE_RAMP = 0
SHAPE_SINE = 1
#: Columns of the rig's ``sample`` buffer (lanes, 12), each an (x, y) pair.
SAMPLE_PAIRS = ("handle_position_m", "handle_velocity_m_per_s",
                "handle_acceleration_m_per_s2", "operator_intent_force_N", "handle_force_N",
                "handle_force_measured_N")
#: The largest finite float64 (what numpy's nan_to_num makes of +inf).
FLOAT64_MAX = 1.7976931348623157e308


@wp.struct
class OperatorParams:
    """One operator model's parameters (SI units; see haptic.master.simulated_rig.operator)."""

    kind: wp.int32
    shape: wp.int32
    fx: wp.float64
    fy: wp.float64
    onset_s: wp.float64
    rise_s: wp.float64
    kp: wp.float64
    ki: wp.float64
    kd: wp.float64
    lag_alpha: wp.float64
    max_N: wp.float64
    vx: wp.float64
    vy: wp.float64
    ax: wp.float64
    ay: wp.float64
    omega_rad_s: wp.float64


@wp.func
def envelope(time_s: wp.float64, onset_s: wp.float64, rise_s: wp.float64) -> wp.float64:
    """0 before onset, a linear ramp over ``rise_s``, then 1."""
    zero = wp.float64(0.0)
    one = wp.float64(1.0)
    if rise_s > zero:
        return wp.clamp((time_s - onset_s) / rise_s, zero, one)
    if time_s >= onset_s:
        return one
    return zero


@wp.func
def finite_or_zero(value: wp.float64) -> wp.float64:
    """numpy's nan_to_num: NaN -> 0, +-inf -> the largest finite float64."""
    if wp.isnan(value):
        return wp.float64(0.0)
    return wp.clamp(value, wp.float64(-FLOAT64_MAX), wp.float64(FLOAT64_MAX))


@wp.func
def sign_of(value: wp.float64) -> wp.float64:
    """-1, 0 or 1 (numpy's sign)."""
    zero = wp.float64(0.0)
    if value > zero:
        return wp.float64(1.0)
    if value < zero:
        return wp.float64(-1.0)
    return zero


@wp.func
def regulate_axis(p: OperatorParams, target: wp.float64, tool_force_N: wp.float64,
                  period_s: wp.float64, active: bool, lane: wp.int32, axis: wp.int32,
                  integral: wp.array2d(dtype=wp.float64),
                  felt: wp.array2d(dtype=wp.float64)) -> wp.float64:
    """The force regulator of one axis: perception lag, PI with conditional integration."""
    sensed = felt[lane, axis] + p.lag_alpha * (finite_or_zero(tool_force_N) - felt[lane, axis])
    felt[lane, axis] = sensed
    error = target - sensed
    raw = target + p.kp * error + p.ki * integral[lane, axis]
    limited = wp.clamp(raw, -p.max_N, p.max_N)
    pushing_limit = raw != limited and sign_of(error) == sign_of(raw)
    if active and not pushing_limit:
        integral[lane, axis] = integral[lane, axis] + error * period_s
    return limited


@wp.func
def operator_intent(p: OperatorParams, lane: wp.int32, period_s: wp.float64,
                    offset_x: wp.float64, offset_y: wp.float64, velocity_x: wp.float64,
                    velocity_y: wp.float64, tool_force_x: wp.float64,
                    tool_force_y: wp.float64, time_s: wp.array(dtype=wp.float64),
                    integral: wp.array2d(dtype=wp.float64),
                    felt: wp.array2d(dtype=wp.float64)) -> wp.vec2d:
    """The intent force uh (N) of one lane at its time; then advances its time."""
    zero = wp.float64(0.0)
    t = time_s[lane]
    force = wp.vec2d(zero, zero)
    if p.kind == KIND_CONSTANT:
        e = envelope(t, p.onset_s, p.rise_s)
        force = wp.vec2d(e * p.fx, e * p.fy)
    elif p.kind == KIND_REGULATE:
        e = envelope(t, p.onset_s, p.rise_s)
        active = e > zero
        force = wp.vec2d(
            e * regulate_axis(p, p.fx, tool_force_x, period_s, active, lane, 0, integral, felt),
            e * regulate_axis(p, p.fy, tool_force_y, period_s, active, lane, 1, integral, felt))
    else:
        elapsed = wp.max(t - p.onset_s, zero)
        started = t >= p.onset_s
        ref_x = zero
        ref_y = zero
        rate_x = zero
        rate_y = zero
        if p.shape == SHAPE_RAMP:
            ref_x = p.vx * elapsed
            ref_y = p.vy * elapsed
            if started:
                rate_x = p.vx
                rate_y = p.vy
        else:
            phase = p.omega_rad_s * elapsed
            ref_x = p.ax * wp.sin(phase)
            ref_y = p.ay * wp.sin(phase)
            if started:
                rate_x = p.ax * p.omega_rad_s * wp.cos(phase)
                rate_y = p.ay * p.omega_rad_s * wp.cos(phase)
        fx = p.kp * (ref_x - offset_x) + p.kd * (rate_x - velocity_x)
        fy = p.kp * (ref_y - offset_y) + p.kd * (rate_y - velocity_y)
        force = wp.vec2d(wp.clamp(fx, -p.max_N, p.max_N), wp.clamp(fy, -p.max_N, p.max_N))
    time_s[lane] = t + period_s
    return force


@wp.kernel
def operator_kernel(
    params: OperatorParams,
    period_s: wp.float64,
    inputs: wp.array2d(dtype=wp.float64),
    time_s: wp.array(dtype=wp.float64),
    integral: wp.array2d(dtype=wp.float64),
    felt: wp.array2d(dtype=wp.float64),
    force: wp.array2d(dtype=wp.float64),
):
    """The operator alone; ``inputs`` (lanes, 6): offset x y (m), velocity x y (m/s), tool
    force x y (N); ``force`` (lanes, 2): uh, N."""
    lane = wp.tid()
    uh = operator_intent(params, lane, period_s, inputs[lane, 0], inputs[lane, 1],
                         inputs[lane, 2], inputs[lane, 3], inputs[lane, 4], inputs[lane, 5],
                         time_s, integral, felt)
    force[lane, 0] = uh[0]
    force[lane, 1] = uh[1]


@functools.cache
def rig_step_kernel(n_states: int) -> Any:
    """The rig's kernel compiled for ``n_states`` plant states (both axes' Gh realisations
    stacked), in its own Warp module: every loop over the state has a constant length and is
    unrolled, the lane's state read once (a third of the cost of the loops over the arrays'
    runtime shape at a sweep's 210 lanes, the same arithmetic in the same order)."""
    state_vector = wp.types.vector(length=n_states, dtype=wp.float64)

    @wp.kernel(module="unique")
    def rig_step(
        plant_a: wp.array2d(dtype=wp.float64),
        plant_b: wp.array2d(dtype=wp.float64),
        outputs_c: wp.array3d(dtype=wp.float64),
        outputs_d: wp.array2d(dtype=wp.float64),
        impedance: wp.array2d(dtype=wp.float64),
        params: OperatorParams,
        period_s: wp.float64,
        target: wp.array2d(dtype=wp.float64),
        tool_force: wp.array2d(dtype=wp.float64),
        noise: wp.array2d(dtype=wp.float64),
        plant: wp.array2d(dtype=wp.float64),
        applied: wp.array2d(dtype=wp.float64),
        grasp: wp.array2d(dtype=wp.float64),
        time_s: wp.array(dtype=wp.float64),
        integral: wp.array2d(dtype=wp.float64),
        felt: wp.array2d(dtype=wp.float64),
        sample: wp.array2d(dtype=wp.float64),
    ):
        """One SYNC of one lane: advance the axes over the last period with the command
        applied there, apply the new target (a non-finite one is ignored per axis), sample
        position, velocity and acceleration (``outputs_c`` (3, 2, n), ``outputs_d`` (3, 2):
        position, velocity, acceleration), the operator's intent and the sensor force
        ``fh = uh - (m a + b v + k (y - y_grasp))`` plus ``noise``."""
        lane = wp.tid()
        held_x = applied[lane, 0]
        held_y = applied[lane, 1]
        x = state_vector()
        for j in range(n_states):
            x[j] = plant[lane, j]
        advanced = state_vector()
        for i in range(n_states):
            acc = plant_b[i, 0] * held_x + plant_b[i, 1] * held_y
            for j in range(n_states):
                acc += plant_a[i, j] * x[j]
            advanced[i] = acc
            plant[lane, i] = acc
        if wp.isfinite(target[lane, 0]):
            held_x = target[lane, 0]
            applied[lane, 0] = held_x
        if wp.isfinite(target[lane, 1]):
            held_y = target[lane, 1]
            applied[lane, 1] = held_y
        held = wp.vec2d(held_x, held_y)
        for output in range(3):
            for axis in range(2):
                value = outputs_d[output, axis] * held[axis]
                for j in range(n_states):
                    value += outputs_c[output, axis, j] * advanced[j]
                sample[lane, 2 * output + axis] = value
        offset_x = sample[lane, 0] - grasp[lane, 0]
        offset_y = sample[lane, 1] - grasp[lane, 1]
        uh = operator_intent(params, lane, period_s, offset_x, offset_y, sample[lane, 2],
                             sample[lane, 3], tool_force[lane, 0], tool_force[lane, 1],
                             time_s, integral, felt)
        offsets = wp.vec2d(offset_x, offset_y)
        for axis in range(2):
            arm = impedance[axis, 0] * sample[lane, 4 + axis] + (
                impedance[axis, 1] * sample[lane, 2 + axis]) + impedance[axis, 2] * offsets[axis]
            force = uh[axis] - arm
            sample[lane, 6 + axis] = uh[axis]
            sample[lane, 8 + axis] = force
            sample[lane, 10 + axis] = force + noise[lane, axis]

    return rig_step
