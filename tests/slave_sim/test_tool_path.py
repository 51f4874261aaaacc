"""The slave's bounded tool path (slave_sim/tool_path.py)."""

from __future__ import annotations

import numpy as np

from haptic.slave_sim.tool_path import ToolPath


def test_path_keeps_everything_until_full_then_thins_in_fixed_memory() -> None:
    path = ToolPath(capacity=8)
    for i in range(8):
        path.add(i * 1e-3, 0.0)
    assert len(path) == 8 and path.stride == 1
    for i in range(8, 1000):
        path.add(i * 1e-3, 0.0)
    points = path.array()
    assert len(path) <= 8 and points.shape[1] == 2
    assert points[0, 0] == 0.0  # the start is kept
    # evenly spaced at the current stride, in order, from the whole run
    spacing = np.diff(points[:, 0])
    assert np.allclose(spacing, path.stride * 1e-3)
    assert points[-1, 0] > 0.8


def test_empty_path_is_none() -> None:
    assert ToolPath().array() is None
