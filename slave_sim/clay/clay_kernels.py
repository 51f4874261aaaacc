"""NVIDIA Warp kernels of the clay step (kept in a plain module so Warp can compile them).

One thread per row of each lane's footprint window: ``wp.tid()`` gives (lane, row) inside a
window of ``window_y x window_x`` cells placed around that lane's tool position, so one launch
covers every lane and never touches the rest of the grid; a thread walks its row and adds its
row's sums to the lane's accumulators once (few atomics, little per-thread overhead on CPU).
The arithmetic matches :mod:`haptic.slave_sim.clay.clay_numpy` operation for operation (float64).

Each kernel's per-lane (or per-row) work is a Warp function of its own (:func:`proxy_lane`,
:func:`cut_row`, :func:`yield_lane`), so a kernel that steps the node and the clay together
for several samples (slave_sim/catch_up_kernels.py) runs the very same arithmetic.
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


@wp.func
def cut_row(
    lane: int,
    j: int,
    heights: wp.array3d(dtype=wp.float64),
    block_id: wp.array2d(dtype=wp.int32),
    damping: wp.array2d(dtype=wp.float64),
    tool_xy: wp.array2d(dtype=wp.float64),
    geo: ClayGeometry,
    accumulators: wp.array2d(dtype=wp.float64),
):
    """Lower every cell of one window row under the tool to the tool's surface (capped per
    step) and add the removed volume (m^3) and the damping-weighted volume (N s/m m^3) to the
    lane's sums. One thread per (lane, window row): the row's sums are added once.

    The square root is taken only in the chamfer's ring: a cell whose squared distance is
    below the inner radius's square (less a 1e-9 margin) lies on the flat bottom, one above
    the outer radius's square (plus the margin) is outside: the same verdicts the distance
    gives, so the cut is the one computed from the distance everywhere (numpy's, to rounding:
    tests/slave_sim/test_clay.py). A cell already down to the flat bottom (the groove behind
    the tool) is passed over before its distance: no level is below the bottom's. A row
    visits only its chord of the outer circle, widened by two cells each side (a tool off
    the grid, whose window is clamped away from it, costs almost nothing:
    bench/clay_bench.py measures the step)."""
    px = tool_xy[lane, 0]
    py = tool_xy[lane, 1]
    ix0 = window_start(px, geo.x0, geo.dx, geo.outer_radius, geo.cells_x, geo.window_x)
    iy = window_start(py, geo.y0, geo.dy, geo.outer_radius, geo.cells_y, geo.window_y) + j
    half = wp.float64(0.5)
    zero = wp.float64(0.0)
    ddy = geo.y0 + (wp.float64(iy) + half) * geo.dy - py
    ddy2 = ddy * ddy
    outside2 = geo.outer_radius * geo.outer_radius * wp.float64(1.000000001)
    bottom2 = wp.where(geo.inner_radius > zero,
                       geo.inner_radius * geo.inner_radius * wp.float64(0.999999999),
                       wp.float64(-1.0))  # no flat bottom: every cell is in the chamfer
    if ddy2 >= outside2:
        return  # the whole row is outside the tool
    # the level inside the inner radius, computed as the chamfer computes it there
    bottom = geo.bottom_height + geo.edge_height * edge_profile(wp.float64(-1.0))
    volume_sum = zero
    weighted_sum = zero
    # only the row's chord of the outer circle, widened by more than a cell on each side:
    # every cell left out fails the distance test below by far more than rounding
    half_chord = wp.sqrt(outside2 - ddy2)
    first = wp.int32(wp.floor((px - half_chord - geo.x0) / geo.dx - half)) - 2
    last = wp.int32(wp.floor((px + half_chord - geo.x0) / geo.dx - half)) + 3
    for i in range(wp.max(first - ix0, 0), wp.min(last - ix0, geo.window_x)):
        ix = ix0 + i
        ddx = geo.x0 + (wp.float64(ix) + half) * geo.dx - px
        distance2 = ddx * ddx + ddy2
        if distance2 < outside2:
            height = heights[lane, iy, ix]
            # every level is at or above the flat bottom's (the chamfer only rises): a cell
            # already down to it (the groove behind the tool) is passed without the distance
            if height > bottom:
                block = block_id[iy, ix]
                if block >= 0:
                    level = bottom
                    under = True
                    if distance2 >= bottom2:
                        distance = wp.sqrt(distance2)
                        under = distance < geo.outer_radius
                        level = geo.bottom_height + geo.edge_height * edge_profile(
                            (distance - geo.inner_radius) * geo.inv_edge_width)
                    if under and height > level:
                        cut = wp.min(height - level, geo.cut_cap)
                        heights[lane, iy, ix] = height - cut
                        volume = cut * geo.cell_area
                        volume_sum += volume
                        weighted_sum += volume * damping[lane, block]
    if volume_sum > zero:
        wp.atomic_add(accumulators, lane, 0, volume_sum)
        wp.atomic_add(accumulators, lane, 1, weighted_sum)


@wp.kernel
def cut_kernel(
    heights: wp.array3d(dtype=wp.float64),
    block_id: wp.array2d(dtype=wp.int32),
    damping: wp.array2d(dtype=wp.float64),
    tool_xy: wp.array2d(dtype=wp.float64),
    geo: ClayGeometry,
    accumulators: wp.array2d(dtype=wp.float64),
):
    """:func:`cut_row` for every (lane, window row)."""
    lane, j = wp.tid()
    cut_row(lane, j, heights, block_id, damping, tool_xy, geo, accumulators)


#: Columns of the yield kernel's ``result`` (lanes, 4).
RESULT_COLUMNS = ("removed_volume_m3", "cutting", "engagement", "damping_N_s_per_m")


@wp.struct
class ContactConstants:
    """The proxy contact's constants: coupling stiffness (N/m) and damping (N s/m), sample
    period (s), reference cut cross-section (m^2), still-proxy step (m)."""

    stiffness: wp.float64
    damping: wp.float64
    period: wp.float64
    reference_area: wp.float64
    min_step: wp.float64


@wp.func
def proxy_lane(
    lane: int,
    tool_xy: wp.array2d(dtype=wp.float64),
    tool_v: wp.array2d(dtype=wp.float64),
    proxy: wp.array2d(dtype=wp.float64),
    proxy_prev: wp.array2d(dtype=wp.float64),
    resistance: wp.array1d(dtype=wp.float64),
    direction: wp.array2d(dtype=wp.float64),
    force: wp.array2d(dtype=wp.float64),
    accumulators: wp.array2d(dtype=wp.float64),
    cc: ContactConstants,
):
    """One implicit step of each lane's proxy (one thread per lane): the coupling
    f = K (x - p) + b (v - dp/dt) against the clay's yield law f = c dp/dt, solved at the
    step's end; no clay or a tool pulling back: the proxy is the tool, no force. Also zeroes
    the lane's accumulators for the cut that follows."""
    zero = wp.float64(0.0)
    px = proxy[lane, 0]
    py = proxy[lane, 1]
    proxy_prev[lane, 0] = px
    proxy_prev[lane, 1] = py
    accumulators[lane, 0] = zero
    accumulators[lane, 1] = zero
    ux = cc.stiffness * (tool_xy[lane, 0] - px) + cc.damping * tool_v[lane, 0]
    uy = cc.stiffness * (tool_xy[lane, 1] - py) + cc.damping * tool_v[lane, 1]
    push = ux * direction[lane, 0] + uy * direction[lane, 1]
    c = resistance[lane]
    if c > zero and push > zero:
        gain = wp.float64(1.0) / (c + cc.stiffness * cc.period + cc.damping)
        force[lane, 0] = c * ux * gain
        force[lane, 1] = c * uy * gain
        proxy[lane, 0] = px + cc.period * ux * gain
        proxy[lane, 1] = py + cc.period * uy * gain
    else:
        force[lane, 0] = zero
        force[lane, 1] = zero
        proxy[lane, 0] = tool_xy[lane, 0]
        proxy[lane, 1] = tool_xy[lane, 1]


@wp.kernel
def proxy_kernel(
    tool_xy: wp.array2d(dtype=wp.float64),
    tool_v: wp.array2d(dtype=wp.float64),
    proxy: wp.array2d(dtype=wp.float64),
    proxy_prev: wp.array2d(dtype=wp.float64),
    resistance: wp.array1d(dtype=wp.float64),
    direction: wp.array2d(dtype=wp.float64),
    force: wp.array2d(dtype=wp.float64),
    accumulators: wp.array2d(dtype=wp.float64),
    cc: ContactConstants,
):
    """:func:`proxy_lane` for every lane."""
    proxy_lane(wp.tid(), tool_xy, tool_v, proxy, proxy_prev, resistance, direction, force,
               accumulators, cc)


@wp.func
def yield_lane(
    lane: int,
    proxy: wp.array2d(dtype=wp.float64),
    proxy_prev: wp.array2d(dtype=wp.float64),
    accumulators: wp.array2d(dtype=wp.float64),
    resistance: wp.array1d(dtype=wp.float64),
    direction: wp.array2d(dtype=wp.float64),
    cc: ContactConstants,
    result: wp.array2d(dtype=wp.float64),
):
    """Each lane's clay resistance for the next step from this step's cut: c = B_eff e with
    e = min(1, dV / (A |dp|)); the move's direction is where the clay lies. No removal: no
    resistance; a proxy that did not move keeps both. Also the step's result per lane
    (:data:`RESULT_COLUMNS`: removed volume m^3, cutting 1/0, engagement 0..1, the
    removal-weighted damping N s/m), as ``_ClayBase._result`` computes it in numpy."""
    zero = wp.float64(0.0)
    dx = proxy[lane, 0] - proxy_prev[lane, 0]
    dy = proxy[lane, 1] - proxy_prev[lane, 1]
    step = wp.sqrt(dx * dx + dy * dy)
    removed_volume = accumulators[lane, 0]
    cutting = removed_volume > zero
    result[lane, 0] = removed_volume
    result[lane, 1] = wp.where(cutting, wp.float64(1.0), zero)
    if step > cc.min_step:
        result[lane, 2] = wp.min(removed_volume / (cc.reference_area * step), wp.float64(1.0))
    else:
        result[lane, 2] = wp.where(cutting, wp.float64(1.0), zero)
    result[lane, 3] = wp.where(cutting, accumulators[lane, 1] / removed_volume, zero)
    if step > cc.min_step:
        removed = accumulators[lane, 0]
        if removed > wp.float64(0.0):
            engagement = wp.min(removed / (cc.reference_area * step), wp.float64(1.0))
            resistance[lane] = accumulators[lane, 1] / removed * engagement
            direction[lane, 0] = dx / step
            direction[lane, 1] = dy / step
        else:
            resistance[lane] = wp.float64(0.0)


@wp.kernel
def yield_kernel(
    proxy: wp.array2d(dtype=wp.float64),
    proxy_prev: wp.array2d(dtype=wp.float64),
    accumulators: wp.array2d(dtype=wp.float64),
    resistance: wp.array1d(dtype=wp.float64),
    direction: wp.array2d(dtype=wp.float64),
    cc: ContactConstants,
    result: wp.array2d(dtype=wp.float64),
):
    """:func:`yield_lane` for every lane."""
    yield_lane(wp.tid(), proxy, proxy_prev, accumulators, resistance, direction, cc, result)
