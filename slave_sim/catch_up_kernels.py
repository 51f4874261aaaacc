"""The NVIDIA Warp kernel that steps one slave lane, node and clay together, over several
master samples in one launch (a catch-up tick: slave_sim/catch_up.py).

Per sample, in order, it runs exactly what one node step runs in its launches
(slave_sim/node_kernels.py's step kernel, then slave_sim/clay/clay_kernels.py's proxy, cut
and yield kernels), calling the same Warp functions on the same buffers, so the state it
leaves is the one of the samples stepped one launch sequence each, bit for bit
(tests/slave_sim/test_catch_up.py): the sample's handle force, position and force ramp into
the node's inputs; the compensators and the tool's motion; the tool's position and velocity
into the clay's inputs; the proxy, the cut row by row, the yield; the clay's force (zero on a
halted lane, as the node zeroes it) into the next sample's ft. Between samples nothing
returns to Python: a tick of k samples costs one launch and one pass of Python, not k.

Only the one-lane, no-TDPA, CPU-clay step is fused (the real-time slave's); every other case
keeps the separate launches.
"""

from __future__ import annotations

import functools
from typing import Any

import warp as wp

from haptic.common.model.block_kernels import CompensatorArrays
from haptic.common.model.block_layout import CompensatorLayout
from haptic.slave_sim.clay.clay_kernels import (
    ClayGeometry,
    ContactConstants,
    cut_row,
    proxy_lane,
    yield_lane,
)
from haptic.slave_sim.node_kernels import SlaveConstants, compensate_stage, motion_lane

wp.config.log_level = wp.LOG_WARNING

#: Columns of the kernel's ``samples`` (max samples, 5): each sample's handle force (N),
#: position (m) and force ramp (0..1).
SAMPLE_COLUMNS = ("fh_x", "fh_y", "yh_x", "yh_y", "ft_scale")


@functools.cache
def catch_up_kernel(layout: CompensatorLayout) -> Any:
    """The kernel for compensators of ``layout`` (one Warp module per layout, cached on
    disk): ``count[0]`` samples of ``samples`` stepped in order; ``removed[s]`` the clay
    volume sample ``s`` removed, m^3 (the caller adds them up in order)."""
    compensate = compensate_stage(layout)

    @wp.kernel(module=f"{__name__}.layout_{layout.blocks}x{layout.block_states}")
    def slave_catch_up_kernel(
        samples: wp.array2d(dtype=wp.float64),
        count: wp.array(dtype=wp.int32),
        removed: wp.array(dtype=wp.float64),
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
        clay_tool: wp.array2d(dtype=wp.float64),
        clay_velocity: wp.array2d(dtype=wp.float64),
        proxy: wp.array2d(dtype=wp.float64),
        proxy_prev: wp.array2d(dtype=wp.float64),
        resistance: wp.array1d(dtype=wp.float64),
        direction: wp.array2d(dtype=wp.float64),
        force: wp.array2d(dtype=wp.float64),
        sums: wp.array2d(dtype=wp.float64),
        contact: ContactConstants,
        heights: wp.array3d(dtype=wp.float64),
        block_id: wp.array2d(dtype=wp.int32),
        damping: wp.array2d(dtype=wp.float64),
        geometry: ClayGeometry,
        result: wp.array2d(dtype=wp.float64),
    ):
        """The samples of one lane, node then clay each."""
        lane = wp.tid()
        zero = wp.float64(0.0)
        for s in range(count[0]):
            inputs[lane, 0] = samples[s, 0]
            inputs[lane, 1] = samples[s, 1]
            inputs[lane, 2] = samples[s, 2]
            inputs[lane, 3] = samples[s, 3]
            inputs[lane, 6] = samples[s, 4]
            if s > 0:  # ft: the previous sample's clay force, none on a halted lane
                if halted[lane]:
                    inputs[lane, 4] = zero
                    inputs[lane, 5] = zero
                else:
                    inputs[lane, 4] = force[lane, 0]
                    inputs[lane, 5] = force[lane, 1]
            halted_count[0] = 0
            compensate(lane, inputs, compensator, tool, drift, actuator, constants)
            motion_lane(lane, plant_a, plant_b, tool, halted, halted_count, actuator, motion,
                        constants)
            clay_tool[lane, 0] = tool[lane, 0]
            clay_tool[lane, 1] = tool[lane, 2]
            clay_velocity[lane, 0] = tool[lane, 1]
            clay_velocity[lane, 1] = tool[lane, 3]
            proxy_lane(lane, clay_tool, clay_velocity, proxy, proxy_prev, resistance,
                       direction, force, sums, contact)
            for j in range(geometry.window_y):
                cut_row(lane, j, heights, block_id, damping, proxy, geometry, sums)
            yield_lane(lane, proxy, proxy_prev, sums, resistance, direction, contact, result)
            removed[s] = result[lane, 0]

    return slave_catch_up_kernel
