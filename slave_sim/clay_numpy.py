"""The clay step in vectorised numpy: the reference that the Warp kernels are tested against.

Same footprint windows, same arithmetic, same order of operations as
:func:`haptic.slave_sim.clay_kernels.cut_kernel`; every lane at once through fancy indexing
(each lane's window lies inside the grid, so no index repeats within a lane).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class GeometryConstants:
    """The numbers the cut needs (m, float64); mirrors ``clay_kernels.ClayGeometry``."""

    x0: float
    y0: float
    dx: float
    dy: float
    cells_x: int
    cells_y: int
    window_x: int
    window_y: int
    inner_radius: float
    outer_radius: float
    edge_height: float
    inv_edge_width: float
    bottom_height: float
    cut_cap: float
    cell_area: float


def edge_profile(t: np.ndarray) -> np.ndarray:
    """Rise of the chamfer across its width, 0..1: smoothstep of t clamped to [0, 1]."""
    u = np.clip(t, 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


def window_starts(tool_xy: np.ndarray, geo: GeometryConstants) -> tuple[np.ndarray, np.ndarray]:
    """First column and row of every lane's footprint window, shape (lanes,) each."""
    ix0 = np.floor((tool_xy[:, 0] - geo.outer_radius - geo.x0) / geo.dx).astype(np.int64)
    iy0 = np.floor((tool_xy[:, 1] - geo.outer_radius - geo.y0) / geo.dy).astype(np.int64)
    return (np.clip(ix0, 0, geo.cells_x - geo.window_x),
            np.clip(iy0, 0, geo.cells_y - geo.window_y))


def cut_numpy(
    heights: np.ndarray,
    block_id: np.ndarray,
    damping: np.ndarray,
    tool_xy: np.ndarray,
    geo: GeometryConstants,
) -> np.ndarray:
    """Cut every lane's clay in place; returns accumulators (lanes, 2): removed volume m^3
    and damping-weighted removed volume (N s/m m^3)."""
    lanes = heights.shape[0]
    ix0, iy0 = window_starts(tool_xy, geo)
    ix = ix0[:, None, None] + np.arange(geo.window_x)[None, None, :]  # (lanes, 1, wx)
    iy = iy0[:, None, None] + np.arange(geo.window_y)[None, :, None]  # (lanes, wy, 1)
    lane = np.arange(lanes)[:, None, None]
    ddx = geo.x0 + (ix + 0.5) * geo.dx - tool_xy[:, 0, None, None]
    ddy = geo.y0 + (iy + 0.5) * geo.dy - tool_xy[:, 1, None, None]
    distance = np.sqrt(ddx * ddx + ddy * ddy)
    level = geo.bottom_height + geo.edge_height * edge_profile(
        (distance - geo.inner_radius) * geo.inv_edge_width)
    blocks = block_id[iy, ix]
    height = heights[lane, iy, ix]
    cutting = (blocks >= 0) & (distance < geo.outer_radius) & (height > level)
    cut = np.where(cutting, np.minimum(height - level, geo.cut_cap), 0.0)
    heights[lane, iy, ix] = height - cut
    volume = cut * geo.cell_area
    weights = np.take_along_axis(damping, np.maximum(blocks, 0).reshape(lanes, -1), axis=1)
    result = np.empty((lanes, 2))
    result[:, 0] = volume.reshape(lanes, -1).sum(axis=1)
    result[:, 1] = (volume.reshape(lanes, -1) * weights).sum(axis=1)
    return result
