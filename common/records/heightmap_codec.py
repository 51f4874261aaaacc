"""The compact height-map codec of the live view and the recording: a (cells_y, cells_x)
height map (m) reduced by an integer block mean per axis and carried as uint16 micrometres.

Plain numpy, no knowledge of the workpiece (haptic.slave_sim.clay.clay_view adds the layout), so
the display feed (haptic.common.runtime.display) and the view can use it without the slave.
"""

from __future__ import annotations

import math

import numpy as np

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
    """A reduced map as little-endian uint16 micrometres, row-major (y rows of x cells); a
    height below 0 or NaN is 0, one above 65.535 mm is 65535."""
    quantised = np.clip(np.nan_to_num(np.rint(np.asarray(heights_m) / HEIGHT_QUANTUM_M),
                                      nan=0.0), 0, 65535)
    return quantised.astype("<u2").tobytes()


def heights_from_bytes(data: bytes, cells_x: int, cells_y: int) -> np.ndarray:
    """Inverse of :func:`heights_to_bytes`, m; :class:`ValueError` unless ``data`` holds
    exactly ``cells_x`` x ``cells_y`` words."""
    if cells_x < 0 or cells_y < 0 or len(data) != 2 * cells_x * cells_y:
        raise ValueError(f"{len(data)} bytes are not {cells_x} x {cells_y} uint16 heights")
    return np.frombuffer(data, "<u2").reshape(cells_y, cells_x) * HEIGHT_QUANTUM_M
