"""The clay as the operator and the engineer see it: a downsampled height map and the block
layout, as plain data for the recording (JSON) and the live view (compact bytes).

The slave's grid (e.g. 1024 x 256 cells) is reduced by an integer factor per axis (block
mean of the heights, the block of the top-left cell for the layout) to at most
``max_cells_x`` x ``max_cells_y``; the reduction is pure numpy (it releases the GIL on large
arrays) and is run off the control loop.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from haptic.slave_sim.workpiece import Workpiece

#: Default size of the downsampled map, cells.
DEFAULT_MAX_CELLS_X = 256
DEFAULT_MAX_CELLS_Y = 64
#: Height quantum of the compact map: uint16 micrometres (0 .. 65.5 mm).
HEIGHT_QUANTUM_M = 1e-6


def reduction_factors(cells_x: int, cells_y: int, max_cells_x: int = DEFAULT_MAX_CELLS_X,
                      max_cells_y: int = DEFAULT_MAX_CELLS_Y) -> tuple[int, int]:
    """Integer factors (fx, fy) so that the reduced map fits ``max_cells_x`` x
    ``max_cells_y``."""
    return max(1, math.ceil(cells_x / max_cells_x)), max(1, math.ceil(cells_y / max_cells_y))


def downsample_heights(heights_m: np.ndarray, factors: tuple[int, int]) -> np.ndarray:
    """Block mean of a (cells_y, cells_x) height map over ``factors`` = (fx, fy) cells, m
    (edge cells that do not fill a block are dropped)."""
    fx, fy = factors
    cy, cx = heights_m.shape
    ny, nx = cy // fy, cx // fx
    trimmed = np.asarray(heights_m)[: ny * fy, : nx * fx]
    # fx * fy strided adds: about 6x faster than reshape(...).mean() on a 1024 x 256 map
    total = np.zeros((ny, nx))
    for j in range(fy):
        for i in range(fx):
            total += trimmed[j::fy, i::fx]
    return total / (fx * fy)


def heights_to_bytes(heights_m: np.ndarray) -> bytes:
    """A reduced map as little-endian uint16 micrometres, row-major (y rows of x cells)."""
    quantised = np.clip(np.rint(np.asarray(heights_m) / HEIGHT_QUANTUM_M), 0, 65535)
    return quantised.astype("<u2").tobytes()


def heights_from_bytes(data: bytes, cells_x: int, cells_y: int) -> np.ndarray:
    """Inverse of :func:`heights_to_bytes`, m."""
    return np.frombuffer(data, "<u2").reshape(cells_y, cells_x) * HEIGHT_QUANTUM_M


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
