"""The clay as the operator and the engineer see it: a downsampled height map and the block
layout, as plain data for the recording (JSON) and the live view (compact bytes).

The slave's grid (e.g. 1024 x 256 cells) is reduced by an integer factor per axis (block
mean of the heights, the block of the top-left cell for the layout) to at most
``max_cells_x`` x ``max_cells_y``; the reduction is pure numpy (it releases the GIL on large
arrays) and is run off the control loop.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from haptic.common.records.heightmap_codec import downsample_heights
from haptic.slave_sim.clay.workpiece import Workpiece


def workpiece_layout(workpiece: Workpiece, factors: tuple[int, int]) -> dict[str, Any]:
    """The block layout of the reduced map: ranges (m), reduced size, block names and
    dampings (N s/m), block index per reduced cell (-1: no clay), initial heights (mm)."""
    fx, fy = factors
    grid = workpiece.grid
    ids = workpiece.block_id[: (grid.cells_y // fy) * fy : fy, : (grid.cells_x // fx) * fx : fx]
    initial = downsample_heights(workpiece.heights_m, factors)
    return {
        "x_range_m": list(grid.x_range_m),
        "y_range_m": list(grid.y_range_m),
        "cells_x": int(ids.shape[1]),
        "cells_y": int(ids.shape[0]),
        "block_names": list(workpiece.block_names),
        "block_damping_N_s_per_m": [float(v) for v in workpiece.block_damping_N_s_per_m],
        "block_id": np.where(ids < 0, -1, ids).astype(int).tolist(),
        "initial_heights_mm": np.round(initial * 1e3, 4).tolist(),
    }


def heights_message(heights_m: np.ndarray, factors: tuple[int, int]) -> dict[str, Any]:
    """The recording's ``/slave/clay`` message: the reduced map in mm (rows of y)."""
    reduced = downsample_heights(heights_m, factors)
    return {"cells_x": int(reduced.shape[1]), "cells_y": int(reduced.shape[0]),
            "heights_mm": np.round(reduced * 1e3, 4).tolist()}
