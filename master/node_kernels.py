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

from haptic.common.model.block_kernels import block_step
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
INPUT_COLUMNS = ("fh_x", "fh_y", "yh_x", "yh_y", "ft_x", "ft_y")
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


@functools.cache
def step_kernel(layout: CompensatorLayout) -> Any:
    """The node's kernel compiled for the compensator's block layout
    (:class:`~haptic.common.model.block_layout.CompensatorLayout`), in its own Warp module
    (compiled once per layout and cached on disk)."""
    compensator_step = block_step(layout)  # common/model/block_kernels.py

    @wp.kernel(module="unique")
    def master_step_kernel(
        inputs: wp.array2d(dtype=wp.float64),
        comp_a: wp.array4d(dtype=wp.float64),
        comp_b: wp.array4d(dtype=wp.float64),
        comp_c: wp.array4d(dtype=wp.float64),
        comp_d: wp.array3d(dtype=wp.float64),
        per_lane_matrices: wp.int32,
        compensator: wp.array2d(dtype=wp.float64),
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
        zero = wp.float64(0.0)
        one = wp.float64(1.0)
        fhx = inputs[lane, 0]
        fhy = inputs[lane, 1]
        yhx = inputs[lane, 2]
        yhy = inputs[lane, 3]
        ftx = inputs[lane, 4]
        fty = inputs[lane, 5]
        fault = faulted[lane]
        code = wp.int32(-1)

        # 1. Non-finite inputs trip the lane; it holds its last finite position.
        fhx_ok = wp.isfinite(fhx)
        fhy_ok = wp.isfinite(fhy)
        yhx_ok = wp.isfinite(yhx)
        yhy_ok = wp.isfinite(yhy)
        ftx_ok = wp.isfinite(ftx)
        fty_ok = wp.isfinite(fty)
        if not fault:
            if not fhx_ok:
                code = TRIP_NON_FINITE_FORCE * 2
            elif not fhy_ok:
                code = TRIP_NON_FINITE_FORCE * 2 + 1
            elif not yhx_ok:
                code = TRIP_NON_FINITE_POSITION * 2
            elif not yhy_ok:
                code = TRIP_NON_FINITE_POSITION * 2 + 1
            elif not ftx_ok:
                code = TRIP_NON_FINITE_TOOL_FORCE * 2
            elif not fty_ok:
                code = TRIP_NON_FINITE_TOOL_FORCE * 2 + 1
            if code >= 0:
                fault = True
                hold[lane, 0] = last_position[lane, 0]
                hold[lane, 1] = last_position[lane, 1]
        px = last_position[lane, 0]
        py = last_position[lane, 1]
        if yhx_ok:
            px = yhx
        if yhy_ok:
            py = yhy
        vx = (px - last_position[lane, 0]) / limits.period_s
        vy = (py - last_position[lane, 1]) / limits.period_s
        last_position[lane, 0] = px
        last_position[lane, 1] = py
        if not fhx_ok:
            fhx = zero
        if not fhy_ok:
            fhy = zero
        if not ftx_ok:
            ftx = zero
        if not fty_ok:
            fty = zero

        # 2. Trips on the measured force, speed and position.
        if not fault:
            margin = limits.workspace_trip_margin_m
            if wp.abs(fhx) > limits.force_trip_N:
                code = TRIP_FORCE * 2
            elif wp.abs(fhy) > limits.force_trip_N:
                code = TRIP_FORCE * 2 + 1
            elif wp.abs(vx) > limits.velocity_trip_m_per_s:
                code = TRIP_SPEED * 2
            elif wp.abs(vy) > limits.velocity_trip_m_per_s:
                code = TRIP_SPEED * 2 + 1
            elif px < limits.workspace_min_x_m - margin or px > limits.workspace_max_x_m + margin:
                code = TRIP_WORKSPACE * 2
            elif py < limits.workspace_min_y_m - margin or py > limits.workspace_max_y_m + margin:
                code = TRIP_WORKSPACE * 2 + 1
            if code >= 0:
                fault = True
                hold[lane, 0] = px
                hold[lane, 1] = py
        faulted[lane] = fault
        healthy = not fault

        # 3. Force saturation (limits 0: handle force, 1: tool force).
        limit = limits.force_limit_N
        bits = wp.int32(0)
        sat_fhx = wp.abs(fhx) > limit
        sat_fhy = wp.abs(fhy) > limit
        sat_ftx = wp.abs(ftx) > limit
        sat_fty = wp.abs(fty) > limit
        bits = bits | onset_bit(sat_fhx, limiting[lane, 0, 0], healthy, 0)
        bits = bits | onset_bit(sat_fhy, limiting[lane, 0, 1], healthy, 1)
        bits = bits | onset_bit(sat_ftx, limiting[lane, 1, 0], healthy, 2)
        bits = bits | onset_bit(sat_fty, limiting[lane, 1, 1], healthy, 3)
        limiting[lane, 0, 0] = sat_fhx
        limiting[lane, 0, 1] = sat_fhy
        limiting[lane, 1, 0] = sat_ftx
        limiting[lane, 1, 1] = sat_fty
        fhx = wp.clamp(fhx, -limit, limit)
        fhy = wp.clamp(fhy, -limit, limit)
        ftx = wp.clamp(ftx, -limit, limit)
        fty = wp.clamp(fty, -limit, limit)

        # 4. The force gate and ramp after activation.
        small = wp.abs(fhx) < limits.ramp_small_force_N and wp.abs(fhy) < limits.ramp_small_force_N
        count = wp.int32(0)
        if small:
            count = wp.min(small_count[lane] + 1, wp.int32(1 << 30))
        small_count[lane] = count
        enabled = forces_enabled[lane]
        if not enabled and healthy and count >= limits.ramp_small_samples:
            enabled = True
            forces_enabled[lane] = True
            bits = bits | (wp.int32(1) << ENABLE_BIT)
        scale = one
        if limits.ramp_time_s > zero:
            scale = wp.clamp(ramp_elapsed[lane] / limits.ramp_time_s, zero, one)
        if enabled:
            ramp_elapsed[lane] = ramp_elapsed[lane] + limits.period_s
        else:
            scale = zero
        force_scale[lane] = scale

        # The compensator: y = C x + D u, x' = A x + B u (frozen in faulted lanes). Its inputs
        # are scaled by the gain ratio k/k0 of the margin governor (the design is linear in k:
        # common/analysis/margin_table.py); ``used`` reports the forces before that scale.
        u0 = scale * fhx
        u1 = scale * fhy
        u2 = scale * ftx
        u3 = scale * fty
        g = gain_ratio[lane]
        c0 = g * u0
        c1 = g * u1
        c2 = g * u2
        c3 = g * u3
        out = compensator_step(lane, wp.vec4d(c0, c1, c2, c3), comp_a, comp_b, comp_c,
                               comp_d, lane * per_lane_matrices, compensator, healthy)
        out_x = out[0]
        out_y = out[1]
        raw_x = origin[lane, 0] + out_x
        raw_y = origin[lane, 1] + out_y

        # 5. Command rate and workspace limits (2, 3), re-basing the offset when they act.
        max_step = limits.max_command_step_m
        step_x = raw_x - last_command[lane, 0]
        step_y = raw_y - last_command[lane, 1]
        rate_x = wp.abs(step_x) > max_step
        rate_y = wp.abs(step_y) > max_step
        bits = bits | onset_bit(rate_x, limiting[lane, 2, 0], healthy, 4)
        bits = bits | onset_bit(rate_y, limiting[lane, 2, 1], healthy, 5)
        limiting[lane, 2, 0] = rate_x
        limiting[lane, 2, 1] = rate_y
        cmd_x = last_command[lane, 0] + wp.clamp(step_x, -max_step, max_step)
        cmd_y = last_command[lane, 1] + wp.clamp(step_y, -max_step, max_step)
        box_x = cmd_x < limits.workspace_min_x_m or cmd_x > limits.workspace_max_x_m
        box_y = cmd_y < limits.workspace_min_y_m or cmd_y > limits.workspace_max_y_m
        bits = bits | onset_bit(box_x, limiting[lane, 3, 0], healthy, 6)
        bits = bits | onset_bit(box_y, limiting[lane, 3, 1], healthy, 7)
        limiting[lane, 3, 0] = box_x
        limiting[lane, 3, 1] = box_y
        cmd_x = wp.clamp(cmd_x, limits.workspace_min_x_m, limits.workspace_max_x_m)
        cmd_y = wp.clamp(cmd_y, limits.workspace_min_y_m, limits.workspace_max_y_m)
        origin[lane, 0] = origin[lane, 0] + (cmd_x - raw_x)
        origin[lane, 1] = origin[lane, 1] + (cmd_y - raw_y)
        if fault:
            cmd_x = hold[lane, 0]
            cmd_y = hold[lane, 1]
        last_command[lane, 0] = cmd_x
        last_command[lane, 1] = cmd_y
        command[lane, 0] = cmd_x
        command[lane, 1] = cmd_y
        if fault:  # a frozen compensator uses no force; the peer must integrate none either
            u0 = zero
            u1 = zero
            u2 = zero
            u3 = zero
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

    return master_step_kernel
