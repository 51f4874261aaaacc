"""NVIDIA Warp kernel of the master node's step: the safety layer and the Ch1/Ct1 compensator
for every lane in one launch, compiled for the compensator's block layout (:func:`step_kernel`,
common/model/block_layout.py: every loop of constant length, unrolled).

One thread per lane. The real-time master runs one lane through a recorded launch (about
2 us on the CPU device, where the numpy version of the same law cost 55-75 us in small-array
calls); the lockstep simulator runs a whole sweep's lanes through the same kernel, so the
programs and the simulator step exactly one implementation. Arithmetic is float64 throughout.

Outputs that need Python (safety events with their reasons) are coded as integers per lane:
``trip_code`` (the trip that latched this step, ``reason * 2 + axis``, or -1) and
``event_bits`` (saturation onsets, bit ``2 * limit + axis``; :data:`ENABLE_BIT` when the
force gate opened). Any lane with an event adds one to ``event_count[0]``, and a lane that
tripped also to ``event_count[1]``, so the caller reads one integer per step, decodes only
when it is non-zero, and scans for trips only when there were any.
"""

from __future__ import annotations

import functools
from typing import Any

import warp as wp

from haptic.common.control.command_funcs import clamp_to_box, finite_or_zero, rebase_origin
from haptic.common.model.block_kernels import (
    EXCHANGE_COLUMNS,
    CompensatorArrays,
    block_step,
    governed_inputs,
)
from haptic.common.model.block_layout import CompensatorLayout

# The programs print JSON on stdout: Warp must not announce itself there (its struct
# definitions below may initialise it).
wp.config.log_level = wp.LOG_WARNING

#: Trip reasons in the order the safety layer checks them (``trip_code // 2``).
TRIP_NON_FINITE_FORCE = 0
TRIP_NON_FINITE_POSITION = 1
TRIP_NON_FINITE_TOOL_FORCE = 2
TRIP_FORCE = 3
TRIP_SPEED = 4
TRIP_WORKSPACE = 5
#: ``event_bits``: bit ``2 * limit + axis`` for the onset of limit 0..3 (handle force, tool
#: force, command rate, workspace); this bit when the force gate opened.
ENABLE_BIT = 8
#: Columns of the kernel's ``inputs`` (lanes, 6).
INPUT_COLUMNS = EXCHANGE_COLUMNS
#: Columns of ``used`` (lanes, 4): the forces the compensator received this step, N (zero
#: in a faulted lane, whose compensator is frozen).
USED_COLUMNS = ("fh_used_x", "fh_used_y", "ft_used_x", "ft_used_y")
#: The compensator's input count (fh_x, fh_y, ft_x, ft_y).
COMPENSATOR_INPUT_COUNT = 4


@wp.struct
class MasterLimits:
    """The safety settings and the period, as the kernel reads them (SI units)."""

    period_s: wp.float64
    force_limit_N: wp.float64
    force_trip_N: wp.float64
    max_command_step_m: wp.float64
    velocity_trip_m_per_s: wp.float64
    workspace_min_x_m: wp.float64
    workspace_min_y_m: wp.float64
    workspace_max_x_m: wp.float64
    workspace_max_y_m: wp.float64
    workspace_trip_margin_m: wp.float64
    ramp_small_force_N: wp.float64
    ramp_small_samples: wp.int32
    ramp_time_s: wp.float64


@wp.func
def onset_bit(active: bool, was_active: bool, healthy: bool, bit: wp.int32) -> wp.int32:
    """``1 << bit`` when a limit starts acting in a healthy lane, else 0."""
    if active and not was_active and healthy:
        return wp.int32(1) << bit
    return wp.int32(0)


@wp.func
def note_limit(limiting: wp.array3d(dtype=wp.bool), lane: int, limit: wp.int32,
               axis: wp.int32, active: bool, healthy: bool) -> wp.int32:
    """Stores whether limit ``limit`` acts on ``axis``; returns its onset bit
    (``2 * limit + axis``, see :func:`onset_bit`)."""
    bit = onset_bit(active, limiting[lane, limit, axis], healthy, limit * 2 + axis)
    limiting[lane, limit, axis] = active
    return bit


@wp.func
def first_non_finite(fhx: wp.float64, fhy: wp.float64, yhx: wp.float64, yhy: wp.float64,
                     ftx: wp.float64, fty: wp.float64) -> wp.int32:
    """The trip code of the first non-finite input in the safety layer's order, or -1."""
    if not wp.isfinite(fhx):
        return wp.int32(TRIP_NON_FINITE_FORCE * 2)
    if not wp.isfinite(fhy):
        return wp.int32(TRIP_NON_FINITE_FORCE * 2 + 1)
    if not wp.isfinite(yhx):
        return wp.int32(TRIP_NON_FINITE_POSITION * 2)
    if not wp.isfinite(yhy):
        return wp.int32(TRIP_NON_FINITE_POSITION * 2 + 1)
    if not wp.isfinite(ftx):
        return wp.int32(TRIP_NON_FINITE_TOOL_FORCE * 2)
    if not wp.isfinite(fty):
        return wp.int32(TRIP_NON_FINITE_TOOL_FORCE * 2 + 1)
    return wp.int32(-1)


@wp.func
def first_measured_trip(fhx: wp.float64, fhy: wp.float64, vx: wp.float64, vy: wp.float64,
                        px: wp.float64, py: wp.float64, limits: MasterLimits) -> wp.int32:
    """The trip code of the first limit the (finite) handle force (N), speed (m/s) or
    position (m) is beyond, in the safety layer's order, or -1."""
    margin = limits.workspace_trip_margin_m
    if wp.abs(fhx) > limits.force_trip_N:
        return wp.int32(TRIP_FORCE * 2)
    if wp.abs(fhy) > limits.force_trip_N:
        return wp.int32(TRIP_FORCE * 2 + 1)
    if wp.abs(vx) > limits.velocity_trip_m_per_s:
        return wp.int32(TRIP_SPEED * 2)
    if wp.abs(vy) > limits.velocity_trip_m_per_s:
        return wp.int32(TRIP_SPEED * 2 + 1)
    if px < limits.workspace_min_x_m - margin or px > limits.workspace_max_x_m + margin:
        return wp.int32(TRIP_WORKSPACE * 2)
    if py < limits.workspace_min_y_m - margin or py > limits.workspace_max_y_m + margin:
        return wp.int32(TRIP_WORKSPACE * 2 + 1)
    return wp.int32(-1)


@wp.func
def trip_stage(lane: int, inputs: wp.array2d(dtype=wp.float64),
               faulted: wp.array(dtype=wp.bool), last_position: wp.array2d(dtype=wp.float64),
               hold: wp.array2d(dtype=wp.float64), limits: MasterLimits):
    """Safety steps 1-2: non-finite inputs trip the lane (it holds its last finite position),
    then the measured force, speed and position. Returns the trip code (or -1), whether the
    lane is faulted, and the forces (fh_x, fh_y, ft_x, ft_y; N, non-finite ones as 0)."""
    fhx = inputs[lane, 0]
    fhy = inputs[lane, 1]
    yhx = inputs[lane, 2]
    yhy = inputs[lane, 3]
    ftx = inputs[lane, 4]
    fty = inputs[lane, 5]
    fault = faulted[lane]
    code = wp.int32(-1)
    if not fault:
        code = first_non_finite(fhx, fhy, yhx, yhy, ftx, fty)
        if code >= 0:
            fault = True
            hold[lane, 0] = last_position[lane, 0]
            hold[lane, 1] = last_position[lane, 1]
    px = last_position[lane, 0]
    py = last_position[lane, 1]
    if wp.isfinite(yhx):
        px = yhx
    if wp.isfinite(yhy):
        py = yhy
    vx = (px - last_position[lane, 0]) / limits.period_s
    vy = (py - last_position[lane, 1]) / limits.period_s
    last_position[lane, 0] = px
    last_position[lane, 1] = py
    forces = wp.vec4d(finite_or_zero(fhx), finite_or_zero(fhy), finite_or_zero(ftx),
                      finite_or_zero(fty))
    if not fault:
        code = first_measured_trip(forces[0], forces[1], vx, vy, px, py, limits)
        if code >= 0:
            fault = True
            hold[lane, 0] = px
            hold[lane, 1] = py
    faulted[lane] = fault
    return code, fault, forces


@wp.func
def saturation_stage(lane: int, forces: wp.vec4d, healthy: bool,
                     limiting: wp.array3d(dtype=wp.bool), limit_N: wp.float64):
    """Safety step 3: the forces (fh_x, fh_y, ft_x, ft_y; N) clamped to ``limit_N`` (limits
    0: handle force, 1: tool force). Returns the clamped forces and the onset bits."""
    bits = note_limit(limiting, lane, 0, 0, wp.abs(forces[0]) > limit_N, healthy)
    bits = bits | note_limit(limiting, lane, 0, 1, wp.abs(forces[1]) > limit_N, healthy)
    bits = bits | note_limit(limiting, lane, 1, 0, wp.abs(forces[2]) > limit_N, healthy)
    bits = bits | note_limit(limiting, lane, 1, 1, wp.abs(forces[3]) > limit_N, healthy)
    clamped = wp.vec4d(wp.clamp(forces[0], -limit_N, limit_N),
                       wp.clamp(forces[1], -limit_N, limit_N),
                       wp.clamp(forces[2], -limit_N, limit_N),
                       wp.clamp(forces[3], -limit_N, limit_N))
    return clamped, bits


@wp.func
def force_gate_stage(lane: int, fhx: wp.float64, fhy: wp.float64, healthy: bool,
                     small_count: wp.array(dtype=wp.int32),
                     forces_enabled: wp.array(dtype=wp.bool),
                     ramp_elapsed: wp.array(dtype=wp.float64),
                     force_scale: wp.array(dtype=wp.float64), limits: MasterLimits):
    """Safety step 4: the force gate opens after ``ramp_small_samples`` small handle forces
    (N) in a healthy lane, then the forces ramp up over ``ramp_time_s``. Returns the force
    scale (0..1) and :data:`ENABLE_BIT`'s bit where the gate opened this step (else 0)."""
    zero = wp.float64(0.0)
    one = wp.float64(1.0)
    small = wp.abs(fhx) < limits.ramp_small_force_N and wp.abs(fhy) < limits.ramp_small_force_N
    count = wp.int32(0)
    if small:
        count = wp.min(small_count[lane] + 1, wp.int32(1 << 30))
    small_count[lane] = count
    enabled = forces_enabled[lane]
    bits = wp.int32(0)
    if not enabled and healthy and count >= limits.ramp_small_samples:
        enabled = True
        forces_enabled[lane] = True
        bits = wp.int32(1) << ENABLE_BIT
    scale = one
    if limits.ramp_time_s > zero:
        scale = wp.clamp(ramp_elapsed[lane] / limits.ramp_time_s, zero, one)
    if enabled:
        ramp_elapsed[lane] = ramp_elapsed[lane] + limits.period_s
    else:
        scale = zero
    force_scale[lane] = scale
    return scale, bits


@wp.func
def command_limit_stage(lane: int, raw: wp.vec2d, healthy: bool,
                        last_command: wp.array2d(dtype=wp.float64),
                        limiting: wp.array3d(dtype=wp.bool), limits: MasterLimits):
    """Safety step 5: the command (m) limited in rate (limit 2) and to the workspace (limit
    3). Returns the limited command and the onset bits."""
    max_step = limits.max_command_step_m
    step_x = raw[0] - last_command[lane, 0]
    step_y = raw[1] - last_command[lane, 1]
    bits = note_limit(limiting, lane, 2, 0, wp.abs(step_x) > max_step, healthy)
    bits = bits | note_limit(limiting, lane, 2, 1, wp.abs(step_y) > max_step, healthy)
    cmd_x = last_command[lane, 0] + wp.clamp(step_x, -max_step, max_step)
    cmd_y = last_command[lane, 1] + wp.clamp(step_y, -max_step, max_step)
    box_x = cmd_x < limits.workspace_min_x_m or cmd_x > limits.workspace_max_x_m
    box_y = cmd_y < limits.workspace_min_y_m or cmd_y > limits.workspace_max_y_m
    bits = bits | note_limit(limiting, lane, 3, 0, box_x, healthy)
    bits = bits | note_limit(limiting, lane, 3, 1, box_y, healthy)
    inside = clamp_to_box(wp.vec2d(cmd_x, cmd_y), limits.workspace_min_x_m,
                          limits.workspace_min_y_m, limits.workspace_max_x_m,
                          limits.workspace_max_y_m)
    return inside, bits


@wp.func
def output_stage(lane: int, cmd: wp.vec2d, u: wp.vec4d, fault: bool, code: wp.int32,
                 bits: wp.int32, hold: wp.array2d(dtype=wp.float64),
                 last_command: wp.array2d(dtype=wp.float64),
                 command: wp.array2d(dtype=wp.float64), used: wp.array2d(dtype=wp.float64),
                 trip_code: wp.array(dtype=wp.int32), event_bits: wp.array(dtype=wp.int32),
                 event_count: wp.array(dtype=wp.int32)):
    """The step's outputs: a faulted lane commands its hold position (m) and used no force
    (the peer must integrate none either); the events, counted for the caller."""
    cmd_x = cmd[0]
    cmd_y = cmd[1]
    zero = wp.float64(0.0)
    u0 = u[0]
    u1 = u[1]
    u2 = u[2]
    u3 = u[3]
    if fault:
        cmd_x = hold[lane, 0]
        cmd_y = hold[lane, 1]
        u0 = zero
        u1 = zero
        u2 = zero
        u3 = zero
    last_command[lane, 0] = cmd_x
    last_command[lane, 1] = cmd_y
    command[lane, 0] = cmd_x
    command[lane, 1] = cmd_y
    used[lane, 0] = u0
    used[lane, 1] = u1
    used[lane, 2] = u2
    used[lane, 3] = u3
    trip_code[lane] = code
    event_bits[lane] = bits
    if code >= 0 or bits != 0:
        wp.atomic_add(event_count, 0, 1)
    if code >= 0:
        wp.atomic_add(event_count, 1, 1)


@functools.cache
def step_kernel(layout: CompensatorLayout) -> Any:
    """The node's kernel compiled for the compensator's block layout
    (:class:`~haptic.common.model.block_layout.CompensatorLayout`), in its own Warp module
    (compiled once per layout and cached on disk)."""
    compensator_step = block_step(layout)  # common/model/block_kernels.py

    @wp.kernel(module="unique")
    def master_step_kernel(
        inputs: wp.array2d(dtype=wp.float64),
        compensator: CompensatorArrays,
        origin: wp.array2d(dtype=wp.float64),
        last_command: wp.array2d(dtype=wp.float64),
        last_position: wp.array2d(dtype=wp.float64),
        hold: wp.array2d(dtype=wp.float64),
        small_count: wp.array(dtype=wp.int32),
        forces_enabled: wp.array(dtype=wp.bool),
        ramp_elapsed: wp.array(dtype=wp.float64),
        force_scale: wp.array(dtype=wp.float64),
        gain_ratio: wp.array(dtype=wp.float64),
        faulted: wp.array(dtype=wp.bool),
        limiting: wp.array3d(dtype=wp.bool),
        command: wp.array2d(dtype=wp.float64),
        used: wp.array2d(dtype=wp.float64),
        trip_code: wp.array(dtype=wp.int32),
        event_bits: wp.array(dtype=wp.int32),
        event_count: wp.array(dtype=wp.int32),
        limits: MasterLimits,
    ):
        """One period of one lane; see :mod:`haptic.master.node` for the law, step by step."""
        lane = wp.tid()
        code, fault, measured = trip_stage(lane, inputs, faulted, last_position, hold, limits)
        healthy = not fault
        forces, bits = saturation_stage(lane, measured, healthy, limiting, limits.force_limit_N)
        scale, gate_bit = force_gate_stage(lane, forces[0], forces[1], healthy, small_count,
                                           forces_enabled, ramp_elapsed, force_scale, limits)
        # The compensator: y = C x + D u, x' = A x + B u (frozen in faulted lanes), its inputs
        # governed; ``used`` reports the forces before the governor's scale.
        u = scale * forces
        out = compensator_step(lane, governed_inputs(u, gain_ratio[lane]), compensator, healthy)
        raw = wp.vec2d(origin[lane, 0] + out[0], origin[lane, 1] + out[1])
        cmd, limit_bits = command_limit_stage(lane, raw, healthy, last_command, limiting,
                                              limits)
        rebase_origin(origin, lane, cmd, raw)
        output_stage(lane, cmd, u, fault, code, bits | gate_bit | limit_bits, hold,
                     last_command, command, used, trip_code, event_bits, event_count)

    return master_step_kernel
