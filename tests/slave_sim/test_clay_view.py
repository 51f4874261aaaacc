"""The reduced height map and layout of the view and the recording."""

from __future__ import annotations

import numpy as np

from haptic.common.config.scenario import load_scenario
from haptic.common.records.heightmap_codec import (
    downsample_heights,
    heights_from_bytes,
    heights_to_bytes,
    reduction_factors,
)
from haptic.common.runtime.display import decode_clay, encode_clay
from haptic.slave_sim.clay.clay_view import workpiece_layout
from haptic.slave_sim.clay.workpiece import build_workpiece


def test_block_mean_and_factors() -> None:
    rng = np.random.default_rng(3)
    heights = rng.uniform(0.0, 0.01, (10, 13))
    reduced = downsample_heights(heights, (3, 2))
    assert reduced.shape == (5, 4)
    expected = heights[:10, :12].reshape(5, 2, 4, 3).mean(axis=(1, 3))
    assert np.allclose(reduced, expected)
    assert reduction_factors(1024, 256) == (4, 4)
    assert reduction_factors(100, 30) == (1, 1)


def test_bytes_round_trip_to_a_micrometre() -> None:
    heights = np.array([[0.0, 0.0101234], [0.065, 0.002]])
    back = heights_from_bytes(heights_to_bytes(heights), 2, 2)
    assert np.abs(back - heights).max() <= 0.5e-6
    header, data = decode_clay(encode_clay({"cells_x": 2, "cells_y": 2}, b"\x01\x02", 7))
    assert header == {"cells_x": 2, "cells_y": 2, "seq": 7} and data == b"\x01\x02"


def test_layout_of_the_constant_rate_workpiece() -> None:
    workpiece = build_workpiece(load_scenario("constant-rate"))
    grid = workpiece.grid
    layout = workpiece_layout(workpiece, reduction_factors(grid.cells_x, grid.cells_y))
    assert (layout["cells_x"], layout["cells_y"]) == (256, 64)
    ids = np.array(layout["block_id"])
    assert ids.shape == (64, 256) and set(np.unique(ids)) == {-1, 0}
    assert layout["block_names"] == ["clay"]
    assert max(map(max, layout["initial_heights_mm"])) > 0.0
