"""Rasterise a scenario's blocks onto the height-field grid.

Each cell of the ``(cells_y, cells_x)`` grid gets the height of the block whose outline
contains the cell centre (m) and that block's index (``-1``: no clay, height 0). Boxes are
half-open ranges ``[low, high)`` and discs open, so blocks that only touch never claim the
same cell.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from haptic.common.config.scenario import GridSpec, Scenario

NO_BLOCK = -1


@dataclass(frozen=True, eq=False)
class Workpiece:
    """The initial workpiece on its grid (heights m, block index per cell, damping N s/m)."""

    grid: GridSpec
    block_names: tuple[str, ...]
    block_damping_N_s_per_m: np.ndarray  # (n_blocks,)
    block_id: np.ndarray  # (cells_y, cells_x) int32, NO_BLOCK where there is no clay
    heights_m: np.ndarray  # (cells_y, cells_x) float64

    @property
    def cell_area_m2(self) -> float:
        """Area of one cell, m^2."""
        return self.grid.cell_size_x_m * self.grid.cell_size_y_m

    def cell_centers_m(self) -> tuple[np.ndarray, np.ndarray]:
        """x (cells_x,) and y (cells_y,) coordinates of the cell centres, m."""
        g = self.grid
        xs = g.x_range_m[0] + (np.arange(g.cells_x) + 0.5) * g.cell_size_x_m
        ys = g.y_range_m[0] + (np.arange(g.cells_y) + 0.5) * g.cell_size_y_m
        return xs, ys


def build_workpiece(scenario: Scenario) -> Workpiece:
    """The scenario's blocks on its grid."""
    grid = scenario.grid
    xs = grid.x_range_m[0] + (np.arange(grid.cells_x) + 0.5) * grid.cell_size_x_m
    ys = grid.y_range_m[0] + (np.arange(grid.cells_y) + 0.5) * grid.cell_size_y_m
    cx, cy = np.meshgrid(xs, ys)
    block_id = np.full((grid.cells_y, grid.cells_x), NO_BLOCK, dtype=np.int32)
    heights = np.zeros((grid.cells_y, grid.cells_x))
    for index, block in enumerate(scenario.blocks):
        if block.shape == "box":
            inside = ((cx >= block.x_range_m[0]) & (cx < block.x_range_m[1])
                      & (cy >= block.y_range_m[0]) & (cy < block.y_range_m[1]))
        else:
            inside = ((cx - block.center_m[0]) ** 2 + (cy - block.center_m[1]) ** 2
                      < block.radius_m ** 2)
        inside &= block_id == NO_BLOCK
        block_id[inside] = index
        heights[inside] = block.height_m
    return Workpiece(
        grid=grid,
        block_names=tuple(b.name for b in scenario.blocks),
        block_damping_N_s_per_m=np.array([b.damping_N_s_per_m for b in scenario.blocks]),
        block_id=block_id,
        heights_m=heights,
    )
