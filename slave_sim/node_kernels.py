"""NVIDIA Warp kernels of the slave node's step: the Ch2/Ct2 compensators with the paper
mode's drift coupling, and the tool's motion (the ZOH plant, the safe state, the work area's
wall), for every lane in one launch.

One thread per lane; float64 throughout. The real-time slave runs one lane through a recorded
CPU launch (a few us, where the numpy version of the same law cost about 35 us in
small-array calls); the lockstep simulator runs a whole sweep's lanes through the same
kernels, so the programs and the simulator step one implementation (slave_sim/node.py).

The step is two stages, because the TDPA layer (``tdpa`` mode, in numpy:
common/model/passivity.py) acts between them, on the actuator force and the tool's position:

1. the compensators (compiled for their block layout, :func:`step_kernels`): ``vt = -Ch2 fh
   + Ct2 ft_prev`` (inputs scaled by the master's force ramp on ft and the governed gain
   ratio), plus the drift coupling ``kp Cp (Ah1 yh - yt)``;
2. :func:`motion_lane`: halted lanes get no force and keep their tool; the others step the
   tool plant ``x' = A x + B vt``; every lane is held inside the work area; the tool's
   acceleration at the end of the step (the linear environment's input).

Without an active TDPA layer the node launches both stages as one kernel. Stage 1 is compiled
for the compensators' layout (:class:`CompensatorLayout`, :func:`step_kernels`).
"""

from __future__ import annotations

import functools
from typing import Any

import warp as wp

from haptic.common.model.block_kernels import (
    EXCHANGE_COLUMNS,
    CompensatorArrays,
    block_step,
    governed_inputs,
)
from haptic.common.model.block_layout import CompensatorLayout

# The programs print JSON on stdout: Warp must not announce itself there.
wp.config.log_level = wp.LOG_WARNING

#: Columns of the kernel's ``inputs`` (lanes, 8): the bounded handle force (N) and position
#: (m) the tool follows, the environment force of the previous step (N), the master's force
#: ramp on ft (0..1) and the governed gain ratio k/k0.
INPUT_COLUMNS = (*EXCHANGE_COLUMNS, "ft_scale", "gain_ratio")
#: Columns of ``motion`` (lanes, 4): the tool's position before the step (m) and its
#: acceleration at the end of it (m/s^2).
MOTION_COLUMNS = ("previous_x", "previous_y", "acceleration_x", "acceleration_y")
#: The largest finite float64 (numpy's ``nan_to_num`` maps +-inf there).
_FLOAT64_MAX = 1.7976931348623157e308


@wp.struct
class SlaveConstants:
    """The tool and the coupling, as the kernels read them (SI units)."""

    position_ratio_x: wp.float64  # Ah1 of x, dimensionless
    position_ratio_y: wp.float64
    drift_on: wp.int32  # 1: the paper mode's drift coupling is on
    drift_a: wp.float64  # Tustin low-pass: y = a y' + b (x + x')
    drift_b: wp.float64
    drift_stiffness_N_per_m: wp.float64
    bounds_on: wp.int32  # 1: the tool stays inside the work area
    low_x_m: wp.float64
    low_y_m: wp.float64
    high_x_m: wp.float64
    high_y_m: wp.float64
    inv_mass_x_per_kg: wp.float64
    inv_mass_y_per_kg: wp.float64
    damping_x_N_s_per_m: wp.float64
    damping_y_N_s_per_m: wp.float64
    stiffness_x_N_per_m: wp.float64
    stiffness_y_N_per_m: wp.float64


@wp.func
def finite_or_clamped(value: wp.float64) -> wp.float64:
    """numpy's ``nan_to_num``: NaN -> 0, +-inf -> the largest finite float64."""
    if wp.isnan(value):
        return wp.float64(0.0)
    if wp.isinf(value):
        if value > wp.float64(0.0):
            return wp.float64(_FLOAT64_MAX)
        return wp.float64(-_FLOAT64_MAX)
    return value


@wp.func
def drift_force(lane: int, inputs: wp.array2d(dtype=wp.float64),
                tool: wp.array2d(dtype=wp.float64), drift: wp.array2d(dtype=wp.float64),
                constants: SlaveConstants) -> wp.vec2d:
    """The paper mode's slow spring on ``Ah1 yh - yt`` (common/model/drift.py), N; advances
    the lane's filter."""
    gap_x = finite_or_clamped(constants.position_ratio_x * inputs[lane, 2] - tool[lane, 0])
    gap_y = finite_or_clamped(constants.position_ratio_y * inputs[lane, 3] - tool[lane, 2])
    a = constants.drift_a
    b = constants.drift_b
    filtered_x = a * drift[lane, 0] + b * (gap_x + drift[lane, 2])
    filtered_y = a * drift[lane, 1] + b * (gap_y + drift[lane, 3])
    drift[lane, 0] = filtered_x
    drift[lane, 1] = filtered_y
    drift[lane, 2] = gap_x
    drift[lane, 3] = gap_y
    return wp.vec2d(constants.drift_stiffness_N_per_m * filtered_x,
                    constants.drift_stiffness_N_per_m * filtered_y)


@wp.func
def compensator_inputs(lane: int, inputs: wp.array2d(dtype=wp.float64)) -> wp.vec4d:
    """The compensators' inputs (fh, ft; N): ft scaled by the master's force ramp, both
    governed (the gain ratio k/k0)."""
    scale = inputs[lane, 6]
    return governed_inputs(wp.vec4d(inputs[lane, 0], inputs[lane, 1], inputs[lane, 4] * scale,
                                    inputs[lane, 5] * scale), inputs[lane, 7])


@wp.func
def store_actuator(lane: int, out: wp.vec2d, inputs: wp.array2d(dtype=wp.float64),
                   tool: wp.array2d(dtype=wp.float64), drift: wp.array2d(dtype=wp.float64),
                   actuator: wp.array2d(dtype=wp.float64), constants: SlaveConstants):
    """The actuator force (N): the compensators' output ``out`` plus, where it is on, the
    drift coupling."""
    out_x = out[0]
    out_y = out[1]
    if constants.drift_on != 0:
        coupling = drift_force(lane, inputs, tool, drift, constants)
        out_x += coupling[0]
        out_y += coupling[1]
    actuator[lane, 0] = out_x
    actuator[lane, 1] = out_y


@wp.func
def motion_lane(
    lane: int,
    plant_a: wp.array2d(dtype=wp.float64),
    plant_b: wp.array2d(dtype=wp.float64),
    tool: wp.array2d(dtype=wp.float64),
    halted: wp.array(dtype=wp.bool),
    halted_count: wp.array(dtype=wp.int32),
    actuator: wp.array2d(dtype=wp.float64),
    motion: wp.array2d(dtype=wp.float64),
    constants: SlaveConstants,
):
    """Stage 2 of one lane: the tool's step under ``actuator`` (zeroed where halted; each
    halted lane adds one to ``halted_count[0]``)."""
    zero = wp.float64(0.0)
    fx = actuator[lane, 0]
    fy = actuator[lane, 1]
    stopped = halted[lane]
    if stopped:
        wp.atomic_add(halted_count, 0, 1)
        fx = zero
        fy = zero
        actuator[lane, 0] = zero
        actuator[lane, 1] = zero
    s0 = tool[lane, 0]
    s1 = tool[lane, 1]
    s2 = tool[lane, 2]
    s3 = tool[lane, 3]
    motion[lane, 0] = s0
    motion[lane, 1] = s2
    if not stopped:
        n0 = plant_a[0, 0] * s0 + plant_a[0, 1] * s1 + plant_a[0, 2] * s2 + plant_a[0, 3] * s3
        n1 = plant_a[1, 0] * s0 + plant_a[1, 1] * s1 + plant_a[1, 2] * s2 + plant_a[1, 3] * s3
        n2 = plant_a[2, 0] * s0 + plant_a[2, 1] * s1 + plant_a[2, 2] * s2 + plant_a[2, 3] * s3
        n3 = plant_a[3, 0] * s0 + plant_a[3, 1] * s1 + plant_a[3, 2] * s2 + plant_a[3, 3] * s3
        s0 = n0 + plant_b[0, 0] * fx + plant_b[0, 1] * fy
        s1 = n1 + plant_b[1, 0] * fx + plant_b[1, 1] * fy
        s2 = n2 + plant_b[2, 0] * fx + plant_b[2, 1] * fy
        s3 = n3 + plant_b[3, 0] * fx + plant_b[3, 1] * fy
    if constants.bounds_on != 0:  # the wall: back onto it, no velocity into it
        if (s0 < constants.low_x_m and s1 < zero) or (s0 > constants.high_x_m and s1 > zero):
            s1 = zero
        if (s2 < constants.low_y_m and s3 < zero) or (s2 > constants.high_y_m and s3 > zero):
            s3 = zero
        s0 = wp.clamp(s0, constants.low_x_m, constants.high_x_m)
        s2 = wp.clamp(s2, constants.low_y_m, constants.high_y_m)
    tool[lane, 0] = s0
    tool[lane, 1] = s1
    tool[lane, 2] = s2
    tool[lane, 3] = s3
    motion[lane, 2] = (fx - constants.damping_x_N_s_per_m * s1
                       - constants.stiffness_x_N_per_m * s0) * constants.inv_mass_x_per_kg
    motion[lane, 3] = (fy - constants.damping_y_N_s_per_m * s3
                       - constants.stiffness_y_N_per_m * s2) * constants.inv_mass_y_per_kg


def _layout_module(layout: CompensatorLayout) -> str:
    """The Warp module of the kernels compiled for ``layout`` (one compile per layout)."""
    return f"{__name__}.layout_{layout.blocks}x{layout.block_states}"


@functools.cache
def compensate_stage(layout: CompensatorLayout) -> Any:
    """Stage 1 of one lane compiled for ``layout``, in the layout's Warp module: the
    compensators' vt (and the drift coupling) into ``actuator`` (common/model/block_kernels.py:
    y = C x + D u, x' = A x + B u)."""
    compensator_step = block_step(layout)

    @wp.func(module=_layout_module(layout))
    def compensate(
        lane: int,
        inputs: wp.array2d(dtype=wp.float64),
        compensator: CompensatorArrays,
        tool: wp.array2d(dtype=wp.float64),
        drift: wp.array2d(dtype=wp.float64),
        actuator: wp.array2d(dtype=wp.float64),
        constants: SlaveConstants,
    ):
        """Stage 1 of one lane."""
        out = compensator_step(lane, compensator_inputs(lane, inputs), compensator, True)
        store_actuator(lane, out, inputs, tool, drift, actuator, constants)

    return compensate


@functools.cache
def motion_kernel(layout: CompensatorLayout) -> Any:
    """Stage 2 for every lane (after the TDPA layer acted on ``actuator`` and ``tool``), in
    the layout's Warp module so that loading that module loads every stage."""

    @wp.kernel(module=_layout_module(layout))
    def slave_motion_kernel(
        plant_a: wp.array2d(dtype=wp.float64),
        plant_b: wp.array2d(dtype=wp.float64),
        tool: wp.array2d(dtype=wp.float64),
        halted: wp.array(dtype=wp.bool),
        halted_count: wp.array(dtype=wp.int32),
        actuator: wp.array2d(dtype=wp.float64),
        motion: wp.array2d(dtype=wp.float64),
        constants: SlaveConstants,
    ):
        """Stage 2 of one lane."""
        motion_lane(wp.tid(), plant_a, plant_b, tool, halted, halted_count, actuator, motion,
                    constants)

    return slave_motion_kernel


@functools.cache
def step_kernels(layout: CompensatorLayout) -> tuple[Any, Any, Any]:
    """The kernels compiled for ``layout``: (both stages, stage 1 alone, stage 2 alone), in
    one Warp module of their own (one compile per layout, cached on disk)."""
    compensate = compensate_stage(layout)
    module = _layout_module(layout)

    @wp.kernel(module=module)
    def slave_step_kernel(
        inputs: wp.array2d(dtype=wp.float64),
        compensator: CompensatorArrays,
        tool: wp.array2d(dtype=wp.float64),
        drift: wp.array2d(dtype=wp.float64),
        actuator: wp.array2d(dtype=wp.float64),
        plant_a: wp.array2d(dtype=wp.float64),
        plant_b: wp.array2d(dtype=wp.float64),
        halted: wp.array(dtype=wp.bool),
        halted_count: wp.array(dtype=wp.int32),
        motion: wp.array2d(dtype=wp.float64),
        constants: SlaveConstants,
    ):
        """Both stages for every lane (no active TDPA layer between them)."""
        lane = wp.tid()
        compensate(lane, inputs, compensator, tool, drift, actuator, constants)
        motion_lane(lane, plant_a, plant_b, tool, halted, halted_count, actuator, motion,
                    constants)

    @wp.kernel(module=module)
    def slave_actuator_kernel(
        inputs: wp.array2d(dtype=wp.float64),
        compensator: CompensatorArrays,
        tool: wp.array2d(dtype=wp.float64),
        drift: wp.array2d(dtype=wp.float64),
        actuator: wp.array2d(dtype=wp.float64),
        constants: SlaveConstants,
    ):
        """Stage 1 for every lane (the TDPA layer then acts on ``actuator`` and ``tool``)."""
        compensate(wp.tid(), inputs, compensator, tool, drift, actuator, constants)

    return slave_step_kernel, slave_actuator_kernel, motion_kernel(layout)
