"""The Warp function both nodes' kernels step their compensator with, compiled for its block
layout (common/model/block_layout.py): y = C x + D u, and x' = A x + B u where the caller
says the state advances, block by block with every loop of constant length (unrolled).

The master's kernel (master/node_kernels.py: Ch1/Ct1, frozen in a faulted lane) and the
slave's (slave_sim/node_kernels.py: Ch2/Ct2) call it with their own four inputs, both scaled
by the margin governor's gain ratio through :func:`governed_inputs`. Both take the
compensator's matrices and state as one :class:`CompensatorArrays` argument (built by
:func:`compensator_arrays`), so a kernel names them in one parameter.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Any

import warp as wp

from haptic.common.model.block_layout import CompensatorLayout

# The programs print JSON on stdout: Warp must not announce itself there.
wp.config.log_level = wp.LOG_WARNING


@wp.struct
class CompensatorArrays:
    """One node's compensator as its kernels read it: the packed matrices ``a`` (L, P, Q, Q),
    ``b`` (L, P, Q, 4), ``c`` (L, P, 2, Q), ``d`` (L, 2, 4) of its block layout (P blocks of
    Q states), whether lane ``l`` steps matrix set ``l`` (``per_lane_matrices`` 1; 0: every
    lane set 0, L = 1) and the lanes' ``state`` (lanes, P * Q). The struct holds references
    to the arrays: the kernels write ``state`` in place."""

    a: wp.array4d(dtype=wp.float64)
    b: wp.array4d(dtype=wp.float64)
    c: wp.array4d(dtype=wp.float64)
    d: wp.array3d(dtype=wp.float64)
    per_lane_matrices: wp.int32
    state: wp.array2d(dtype=wp.float64)


def compensator_arrays(matrices: Sequence[Any], per_lane: int, state: Any) -> Any:
    """The :class:`CompensatorArrays` of the packed Warp ``matrices`` (a, b, c, d),
    ``per_lane`` (1: one matrix set per lane) and the state array ``state``."""
    arrays = CompensatorArrays()
    arrays.a, arrays.b, arrays.c, arrays.d = matrices
    arrays.per_lane_matrices = int(per_lane)
    arrays.state = state
    return arrays


#: The input columns both nodes' kernels start with: the handle's force fh (N) and position
#: yh (m), the tool's force ft (N), (x, y) each (master/node_kernels.py, slave_sim/node_kernels.py).
EXCHANGE_COLUMNS = ("fh_x", "fh_y", "yh_x", "yh_y", "ft_x", "ft_y")
#: The shape of one lane's (x, y) pair.
_ONE_LANE_PAIR = (1, 2)


def write_exchange_inputs(inputs: Any, handle_force_N: Any, handle_position_m: Any,
                          tool_force_N: Any) -> bool:
    """fh, yh and ft ((lanes, 2) each or broadcastable, N, m, N) into :data:`EXCHANGE_COLUMNS`
    of a node's input buffer ``inputs`` (lanes, 6+). One lane's (1, 2) arrays are written
    element by element (about half the time of the slice writes, the same values), anything
    else by columns; returns whether the one-lane way was taken."""
    if (inputs.shape[0] == 1 and getattr(handle_force_N, "shape", None) == _ONE_LANE_PAIR
            and getattr(handle_position_m, "shape", None) == _ONE_LANE_PAIR
            and getattr(tool_force_N, "shape", None) == _ONE_LANE_PAIR):
        row = inputs[0]
        row[0] = handle_force_N[0, 0]
        row[1] = handle_force_N[0, 1]
        row[2] = handle_position_m[0, 0]
        row[3] = handle_position_m[0, 1]
        row[4] = tool_force_N[0, 0]
        row[5] = tool_force_N[0, 1]
        return True
    inputs[:, 0:2] = handle_force_N
    inputs[:, 2:4] = handle_position_m
    inputs[:, 4:6] = tool_force_N
    return False


@wp.func
def governed_inputs(u: wp.vec4d, gain_ratio: wp.float64) -> wp.vec4d:
    """The compensator's inputs ``u`` (N) scaled by the margin governor's gain ratio k/k0:
    the design is linear in k (common/analysis/margin_table.py)."""
    return gain_ratio * u


@functools.cache
def block_step(layout: CompensatorLayout) -> Any:
    """``compensator_step(lane, u, compensator, advance) -> vec2d``: the two outputs for the
    inputs ``u`` (vec4d), from lane ``lane``'s state and matrix set in ``compensator``
    (:class:`CompensatorArrays`); the state advances when ``advance``. One Warp module per
    layout."""
    blocks, q = layout.blocks, layout.block_states
    block_vector = wp.types.vector(length=q, dtype=wp.float64)

    @wp.func(module=f"{__name__}.layout_{blocks}x{q}")
    def compensator_step(
        lane: int,
        u: wp.vec4d,
        compensator: CompensatorArrays,
        advance: bool,
    ) -> wp.vec2d:
        m = lane * compensator.per_lane_matrices
        comp_a = compensator.a
        comp_b = compensator.b
        comp_c = compensator.c
        comp_d = compensator.d
        state = compensator.state
        out_x = comp_d[m, 0, 0] * u[0] + comp_d[m, 0, 1] * u[1] + comp_d[m, 0, 2] * u[2] + (
            comp_d[m, 0, 3] * u[3])
        out_y = comp_d[m, 1, 0] * u[0] + comp_d[m, 1, 1] * u[1] + comp_d[m, 1, 2] * u[2] + (
            comp_d[m, 1, 3] * u[3])
        for block in range(blocks):
            x = block_vector()
            for j in range(q):
                x[j] = state[lane, block * q + j]
            for j in range(q):
                out_x += comp_c[m, block, 0, j] * x[j]
                out_y += comp_c[m, block, 1, j] * x[j]
            if advance:
                for i in range(q):
                    acc = comp_b[m, block, i, 0] * u[0] + comp_b[m, block, i, 1] * u[1] + (
                        comp_b[m, block, i, 2] * u[2]) + comp_b[m, block, i, 3] * u[3]
                    for j in range(q):
                        acc += comp_a[m, block, i, j] * x[j]
                    state[lane, block * q + i] = acc
        return wp.vec2d(out_x, out_y)

    return compensator_step


__all__ = ["EXCHANGE_COLUMNS", "CompensatorArrays", "block_step", "compensator_arrays",
           "governed_inputs", "write_exchange_inputs"]
