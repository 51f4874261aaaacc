"""The Warp function both nodes' kernels step their compensator with, compiled for its block
layout (common/model/block_layout.py): y = C x + D u, and x' = A x + B u where the caller
says the state advances, block by block with every loop of constant length (unrolled).

The master's kernel (master/node_kernels.py: Ch1/Ct1, frozen in a faulted lane) and the
slave's (slave_sim/node_kernels.py: Ch2/Ct2) call it with their own four inputs, both scaled
by the margin governor's gain ratio through :func:`governed_inputs`.
"""

from __future__ import annotations

import functools
from typing import Any

import warp as wp

from haptic.common.model.block_layout import CompensatorLayout

# The programs print JSON on stdout: Warp must not announce itself there.
wp.config.log_level = wp.LOG_WARNING


@wp.func
def governed_inputs(u: wp.vec4d, gain_ratio: wp.float64) -> wp.vec4d:
    """The compensator's inputs ``u`` (N) scaled by the margin governor's gain ratio k/k0:
    the design is linear in k (common/analysis/margin_table.py)."""
    return gain_ratio * u


@functools.cache
def block_step(layout: CompensatorLayout) -> Any:
    """``compensator_step(lane, u, comp_a, comp_b, comp_c, comp_d, m, compensator, advance)
    -> vec2d``: the two outputs for the inputs ``u`` (vec4d), from lane ``lane``'s state
    (``compensator`` (lanes, blocks * block_states)) and matrix set ``m`` (the packed
    ``a`` (L, P, Q, Q), ``b`` (L, P, Q, 4), ``c`` (L, P, 2, Q), ``d`` (L, 2, 4)); the state
    advances when ``advance``. One Warp module per layout."""
    blocks, q = layout.blocks, layout.block_states
    block_vector = wp.types.vector(length=q, dtype=wp.float64)

    @wp.func(module=f"{__name__}.layout_{blocks}x{q}")
    def compensator_step(
        lane: int,
        u: wp.vec4d,
        comp_a: wp.array4d(dtype=wp.float64),
        comp_b: wp.array4d(dtype=wp.float64),
        comp_c: wp.array4d(dtype=wp.float64),
        comp_d: wp.array3d(dtype=wp.float64),
        m: int,
        compensator: wp.array2d(dtype=wp.float64),
        advance: bool,
    ) -> wp.vec2d:
        out_x = comp_d[m, 0, 0] * u[0] + comp_d[m, 0, 1] * u[1] + comp_d[m, 0, 2] * u[2] + (
            comp_d[m, 0, 3] * u[3])
        out_y = comp_d[m, 1, 0] * u[0] + comp_d[m, 1, 1] * u[1] + comp_d[m, 1, 2] * u[2] + (
            comp_d[m, 1, 3] * u[3])
        for block in range(blocks):
            x = block_vector()
            for j in range(q):
                x[j] = compensator[lane, block * q + j]
            for j in range(q):
                out_x += comp_c[m, block, 0, j] * x[j]
                out_y += comp_c[m, block, 1, j] * x[j]
            if advance:
                for i in range(q):
                    acc = comp_b[m, block, i, 0] * u[0] + comp_b[m, block, i, 1] * u[1] + (
                        comp_b[m, block, i, 2] * u[2]) + comp_b[m, block, i, 3] * u[3]
                    for j in range(q):
                        acc += comp_a[m, block, i, j] * x[j]
                    compensator[lane, block * q + i] = acc
        return wp.vec2d(out_x, out_y)

    return compensator_step


__all__ = ["block_step", "governed_inputs"]
