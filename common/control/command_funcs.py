"""Warp functions of a position-commanding port that the master node's kernel
(master/node_kernels.py) and the passivity kernel (common/control/passivity_kernel.py) share:
the rule for a non-finite force, the command offset's rebase and the workspace clamp (m)."""

from __future__ import annotations

import warp as wp

wp.config.log_level = wp.LOG_WARNING


@wp.func
def finite_or_zero(value: wp.float64) -> wp.float64:
    """The safety layer's rule for a non-finite force (N): it counts as 0. The passivity
    kernel reads the operator's force through the same rule."""
    if wp.isfinite(value):
        return value
    return wp.float64(0.0)


@wp.func
def rebase_origin(origin: wp.array2d(dtype=wp.float64), lane: int, sent: wp.vec2d,
                  produced: wp.vec2d):
    """Moves the lane's command offset (m) by what a limit or correction changed, ``sent -
    produced``, so that the compensator's next output is measured from the command sent."""
    origin[lane, 0] = origin[lane, 0] + (sent[0] - produced[0])
    origin[lane, 1] = origin[lane, 1] + (sent[1] - produced[1])


@wp.func
def clamp_to_box(point: wp.vec2d, low_x: wp.float64, low_y: wp.float64, high_x: wp.float64,
                 high_y: wp.float64) -> wp.vec2d:
    """The point (m) clamped into [low_x, high_x] x [low_y, high_y] (m): the workspace rule
    the node's and the passivity kernel's commands obey."""
    return wp.vec2d(wp.clamp(point[0], low_x, high_x), wp.clamp(point[1], low_y, high_y))


__all__ = ["clamp_to_box", "finite_or_zero", "rebase_origin"]
