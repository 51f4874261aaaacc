"""The tool's path for the end-of-run picture, in bounded memory.

The slave keeps every ``path_every``-th tool position for ``clay.png``. A Python list of tuples
grows without bound over a long run (about 112 bytes a point, most of what a running slave's
memory grew by: bench/record_memory_bench.py). :class:`ToolPath` keeps the points in a
preallocated array of ``capacity`` rows; when it is full it keeps every other point and from
then on takes every other offered point, so a run of any length keeps its whole path at a
coarser spacing in fixed memory.
"""

from __future__ import annotations

import numpy as np


class ToolPath:
    """Tool positions (x, y) in m, at most ``capacity`` of them (see the module)."""

    def __init__(self, capacity: int = 65536) -> None:
        if capacity < 2:
            raise ValueError(f"capacity must be >= 2 (got {capacity})")
        self._points = np.empty((capacity, 2))
        self._count = 0
        self._stride = 1
        self._offered = 0

    def add(self, x_m: float, y_m: float) -> None:
        """Offer one position, m."""
        offered = self._offered
        self._offered = offered + 1
        if offered % self._stride:
            return
        if self._count == len(self._points):
            kept = self._points[: self._count : 2].copy()
            self._count = len(kept)
            self._points[: self._count] = kept
            self._stride *= 2
            if offered % self._stride:
                return
        self._points[self._count] = (x_m, y_m)
        self._count += 1

    def __len__(self) -> int:
        return self._count

    @property
    def stride(self) -> int:
        """Offered points per kept point."""
        return self._stride

    def array(self) -> np.ndarray | None:
        """The kept points as an (n, 2) array in m, or None when there are none."""
        return self._points[: self._count].copy() if self._count else None
