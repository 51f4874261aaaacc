"""NVIDIA Warp kernels of the clay step (kept in a plain module so Warp can compile them).

One thread per row of each lane's footprint window: ``wp.tid()`` gives (lane, row) inside a
window of ``window_y x window_x`` cells placed around that lane's tool position, so one launch
covers every lane and never touches the rest of the grid; a thread walks its row and adds its
row's sums to the lane's accumulators once (few atomics, little per-thread overhead on CPU).
The arithmetic matches :mod:`haptic.slave_sim.clay_numpy` operation for operation (float64).
"""

from __future__ import annotations

import warp as wp


@wp.struct
class ClayGeometry:
    """Grid and tool constants of one clay model (m, m/m, float64)."""

    x0: wp.float64
    y0: wp.float64
    dx: wp.float64
    dy: wp.float64
    cells_x: wp.int32
    cells_y: wp.int32
    window_x: wp.int32
    window_y: wp.int32
    inner_radius: wp.float64
    outer_radius: wp.float64
    edge_height: wp.float64
    inv_edge_width: wp.float64
    bottom_height: wp.float64
    cut_cap: wp.float64
    cell_area: wp.float64


@wp.func
def window_start(position: wp.float64, origin: wp.float64, cell: wp.float64,
                 outer_radius: wp.float64, cells: wp.int32, window: wp.int32) -> wp.int32:
    """First cell index of the footprint window, kept inside the grid."""
    start = wp.int32(wp.floor((position - outer_radius - origin) / cell))
    return wp.clamp(start, 0, cells - window)


@wp.func
def edge_profile(t: wp.float64) -> wp.float64:
    """Rise of the chamfer across its width, 0..1: smoothstep of t clamped to [0, 1]."""
    u = wp.clamp(t, wp.float64(0.0), wp.float64(1.0))
    return u * u * (wp.float64(3.0) - wp.float64(2.0) * u)


@wp.kernel
def cut_kernel(
    heights: wp.array3d(dtype=wp.float64),
    block_id: wp.array2d(dtype=wp.int32),
    damping: wp.array2d(dtype=wp.float64),
    tool_xy: wp.array2d(dtype=wp.float64),
    geo: ClayGeometry,
    accumulators: wp.array2d(dtype=wp.float64),
):
    """Lower every cell of one window row under the tool to the tool's surface (capped per
    step) and add the removed volume (m^3) and the damping-weighted volume (N s/m m^3) to the
    lane's sums. One thread per (lane, window row): the row's sums are added once."""
    lane, j = wp.tid()
    px = tool_xy[lane, 0]
    py = tool_xy[lane, 1]
    ix0 = window_start(px, geo.x0, geo.dx, geo.outer_radius, geo.cells_x, geo.window_x)
    iy = window_start(py, geo.y0, geo.dy, geo.outer_radius, geo.cells_y, geo.window_y) + j
    half = wp.float64(0.5)
    zero = wp.float64(0.0)
    ddy = geo.y0 + (wp.float64(iy) + half) * geo.dy - py
    ddy2 = ddy * ddy
    volume_sum = zero
    weighted_sum = zero
    for i in range(geo.window_x):
        ix = ix0 + i
        block = block_id[iy, ix]
        if block >= 0:
            ddx = geo.x0 + (wp.float64(ix) + half) * geo.dx - px
            distance = wp.sqrt(ddx * ddx + ddy2)
            if distance < geo.outer_radius:
                level = geo.bottom_height + geo.edge_height * edge_profile(
                    (distance - geo.inner_radius) * geo.inv_edge_width)
                height = heights[lane, iy, ix]
                if height > level:
                    cut = wp.min(height - level, geo.cut_cap)
                    heights[lane, iy, ix] = height - cut
                    volume = cut * geo.cell_area
                    volume_sum += volume
                    weighted_sum += volume * damping[lane, block]
    if volume_sum > zero:
        wp.atomic_add(accumulators, lane, 0, volume_sum)
        wp.atomic_add(accumulators, lane, 1, weighted_sum)
