"""What the control laws' Warp kernels share: the device (the CPU, whose arrays numpy views
share, as the nodes' kernels) and float64 buffers over lanes with their numpy views."""

from __future__ import annotations

from typing import Any

import numpy as np

#: The Warp device of the laws' buffers: the CPU, so ``.numpy()`` is a view, not a copy.
DEVICE = "cpu"


def warp() -> Any:
    """Warp, initialised quietly (the programs print JSON on stdout)."""
    import warp as wp

    wp.config.log_level = wp.LOG_WARNING
    wp.init()
    return wp


class LaneBuffers:
    """Named Warp buffers on :data:`DEVICE` with their numpy views (``.view[name]``): the
    kernels write the buffers, callers read and fill the views in place."""

    def __init__(self) -> None:
        self.arrays: dict[str, Any] = {}
        self.view: dict[str, np.ndarray] = {}

    def add(self, name: str, initial: np.ndarray, dtype: Any = None) -> Any:
        """A buffer holding a copy of ``initial`` (float64 unless ``dtype``, a Warp type)."""
        wp = warp()
        array = wp.array(np.ascontiguousarray(initial), dtype=dtype or wp.float64,
                         device=DEVICE)
        self.arrays[name] = array
        self.view[name] = array.numpy()
        return array


__all__ = ["DEVICE", "LaneBuffers", "warp"]
