"""The clay step in vectorised numpy: the reference that the Warp kernels are tested against.

Same footprint windows, same arithmetic, same order of operations as
:func:`haptic.slave_sim.clay.clay_kernels.cut_kernel`; every lane at once through fancy indexing
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


@dataclass(frozen=True)
class ContactConstants:
    """The proxy contact's constants (mirrors ``clay_kernels.ContactConstants``):
    coupling stiffness (N/m) and damping (N s/m) between tool and proxy, the sample period
    (s), the reference cut's cross-section (m^2) and the step (m) under which the proxy
    counts as still."""

    stiffness: float
    damping: float
    period: float
    reference_area: float
    min_step: float


def proxy_numpy(tool_xy: np.ndarray, tool_v: np.ndarray, proxy: np.ndarray,
                proxy_prev: np.ndarray, resistance: np.ndarray, direction: np.ndarray,
                force: np.ndarray, cc: ContactConstants) -> None:
    """Advance every lane's proxy by one implicit (backward Euler) step, in place.

    The coupling force ``f = K (x - p) + b (v - dp/dt)`` and the clay's viscous yield law
    ``f = c dp/dt`` (``c`` the lane's resistance, N s/m, from the last cut) solved for the
    step's end: ``f = c u / (c + K T + b)`` with ``u = K (x - p_prev) + b v``. The clay only
    resists the proxy moving on into it (``u . direction > 0``); otherwise, or with no clay
    (``c = 0``), the proxy is the tool's position and the force is zero."""
    proxy_prev[...] = proxy
    ux = cc.stiffness * (tool_xy[:, 0] - proxy[:, 0]) + cc.damping * tool_v[:, 0]
    uy = cc.stiffness * (tool_xy[:, 1] - proxy[:, 1]) + cc.damping * tool_v[:, 1]
    push = ux * direction[:, 0] + uy * direction[:, 1]
    engaged = (resistance > 0.0) & (push > 0.0)
    gain = np.where(engaged, 1.0 / (resistance + cc.stiffness * cc.period + cc.damping), 0.0)
    force[:, 0] = resistance * ux * gain
    force[:, 1] = resistance * uy * gain
    proxy[:, 0] = np.where(engaged, proxy[:, 0] + cc.period * ux * gain, tool_xy[:, 0])
    proxy[:, 1] = np.where(engaged, proxy[:, 1] + cc.period * uy * gain, tool_xy[:, 1])


def yield_numpy(proxy: np.ndarray, proxy_prev: np.ndarray, sums: np.ndarray,
                resistance: np.ndarray, direction: np.ndarray, cc: ContactConstants) -> None:
    """The clay's resistance for the next step from this step's cut, in place.

    ``c = B_eff e`` with the engagement ``e = min(1, dV / (A |dp|))`` of the proxy's move dp
    and ``B_eff`` the removal-weighted damping; the direction of the move is where the clay
    now lies. A move that removed nothing leaves no resistance; a proxy that did not move
    keeps both."""
    dx = proxy[:, 0] - proxy_prev[:, 0]
    dy = proxy[:, 1] - proxy_prev[:, 1]
    step = np.sqrt(dx * dx + dy * dy)
    moved = step > cc.min_step
    removed = sums[:, 0]
    cut = moved & (removed > 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        engagement = np.minimum(removed / (cc.reference_area * step), 1.0)
        value = sums[:, 1] / removed * engagement
        resistance[...] = np.where(cut, value, np.where(moved, 0.0, resistance))
        direction[:, 0] = np.where(cut, dx / step, direction[:, 0])
        direction[:, 1] = np.where(cut, dy / step, direction[:, 1])
