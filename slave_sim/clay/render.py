"""Render a workpiece's height map with its block boundaries and the tool path (PNG)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from haptic.slave_sim.clay.workpiece import Workpiece


def render_workpiece(path: str | Path, workpiece: Workpiece, heights_m: np.ndarray,
                     tool_path_xy: np.ndarray | None = None, title: str | None = None) -> None:
    """Write a PNG: heights in mm as an image, block outlines as contours, the tool path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    grid = workpiece.grid
    extent_mm = [1e3 * grid.x_range_m[0], 1e3 * grid.x_range_m[1],
                 1e3 * grid.y_range_m[0], 1e3 * grid.y_range_m[1]]
    aspect = (extent_mm[3] - extent_mm[2]) / (extent_mm[1] - extent_mm[0])
    figure, axes = plt.subplots(figsize=(10, max(2.5, 10 * aspect + 1.0)), dpi=120)
    image = axes.imshow(1e3 * heights_m, origin="lower", extent=extent_mm, cmap="viridis",
                        interpolation="nearest")
    figure.colorbar(image, ax=axes, label="clay height (mm)", shrink=0.8)
    xs, ys = workpiece.cell_centers_m()
    ids = workpiece.block_id
    for index, name in enumerate(workpiece.block_names):
        mask = (ids == index).astype(float)
        if mask.any():
            axes.contour(1e3 * xs, 1e3 * ys, mask, levels=[0.5], colors="white", linewidths=0.8)
            row, col = np.argwhere(ids == index).mean(axis=0)
            damping = workpiece.block_damping_N_s_per_m[index]
            axes.text(1e3 * xs[int(col)], 1e3 * ys[int(row)], f"{name}\n{damping:g} N s/m",
                      color="white", ha="center", va="center", fontsize=7)
    if tool_path_xy is not None and len(tool_path_xy):
        path_xy = np.asarray(tool_path_xy)
        axes.plot(1e3 * path_xy[:, 0], 1e3 * path_xy[:, 1], color="red", linewidth=1.0,
                  label="tool path")
        axes.legend(loc="upper right", fontsize=7)
    axes.set_xlabel("x (mm, cutting direction)")
    axes.set_ylabel("y (mm)")
    axes.set_title(title or "clay workpiece")
    figure.tight_layout()
    figure.savefig(path)
    plt.close(figure)
