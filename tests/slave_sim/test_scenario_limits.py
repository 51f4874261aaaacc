"""Scenario files at their edges (common/config/scenario.py): the geometry checks at their
ties (blocks touching each other or the grid's edge, a tool starting on it, a chamfer as wide
as the tool), each pair of shapes overlapping or not, the workpiece list's checks one at a
time, the grid's cell counts and sizes, and a scenario path that cannot be one.
tests/slave_sim/test_scenario.py covers the shipped files and one error of each kind."""

from __future__ import annotations

import copy
import dataclasses
import tomllib
from pathlib import Path
from typing import Any

import pytest

from haptic.common.config import ConfigError
from haptic.common.config.scenario import (
    MAX_GRID_CELLS,
    BlockSpec,
    load_scenario,
    max_block_damping,
    scenario_from_table,
)
from tests.slave_sim.test_scenario import GOOD

BASE: dict[str, Any] = tomllib.loads(GOOD)


def scenario(blocks: dict[str, dict[str, Any]] | None = None, **tables: dict[str, Any]):
    """The GOOD scenario with ``blocks`` instead of its own (in order) and each table's keys
    changed as given."""
    table = copy.deepcopy(BASE)
    for name, changes in tables.items():
        table[name].update(changes)
    if blocks is not None:
        table["blocks"] = blocks
        table["workpiece"]["blocks"] = list(blocks)
    return scenario_from_table(table, "test")


def refused(key: str, words: str, blocks: dict[str, dict[str, Any]] | None = None,
            **tables: dict[str, Any]) -> None:
    with pytest.raises(ConfigError) as error:
        scenario(blocks, **tables)
    assert error.value.key == key and words in str(error.value), str(error.value)


def box(x: tuple[float, float], y: tuple[float, float], damping: float = 10.0
        ) -> dict[str, Any]:
    return {"shape": "box", "x_range_m": list(x), "y_range_m": list(y), "height_m": 0.01,
            "damping_N_s_per_m": damping}


def disc(center: tuple[float, float], radius: float) -> dict[str, Any]:
    return {"shape": "disc", "center_m": list(center), "radius_m": radius, "height_m": 0.01,
            "damping_N_s_per_m": 10.0}


def test_the_records_are_frozen_and_a_box_carries_no_disc() -> None:
    loaded = scenario()
    for record in (loaded, loaded.grid, loaded.tool, loaded.blocks[0]):
        with pytest.raises(dataclasses.FrozenInstanceError):
            record.source = ""  # type: ignore[misc]
    bare = BlockSpec("b", "disc", 0.01, 1.0)
    assert (bare.x_range_m, bare.y_range_m, bare.center_m, bare.radius_m) == (
        (0.0, 0.0), (0.0, 0.0), (0.0, 0.0), 0.0)
    assert bare.bounds_m() == (0.0, 0.0, 0.0, 0.0)


def test_the_grid_takes_1_to_16384_cells_and_sizes_them() -> None:
    assert MAX_GRID_CELLS == 16384
    grid = scenario(grid={"x_range_m": [-0.01, 0.1], "cells_x": 16384, "cells_y": 1}).grid
    assert (grid.cells_x, grid.cells_y) == (16384, 1)
    assert grid.cell_size_x_m == pytest.approx(0.11 / 16384, rel=1e-12)
    assert grid.cell_size_y_m == pytest.approx(0.04, rel=1e-12)
    for axis in ("cells_x", "cells_y"):
        refused(f"grid.{axis}", "must be <= 16384", grid={axis: 16385})
        refused(f"grid.{axis}", "must be >= 1", grid={axis: 0})
    refused("grid.x_range_m", "low end must be below the high end", grid={
        "x_range_m": [0.1, 0.1]})


def test_a_block_may_touch_the_grids_edges_but_not_cross_them() -> None:
    inside = {"a": box((0.0, 0.1), (-0.02, 0.02))}  # the grid: x 0..0.1, y -0.02..0.02
    assert scenario(inside).blocks[0].bounds_m() == (0.0, 0.1, -0.02, 0.02)
    for x, y in (((-0.001, 0.1), (-0.02, 0.02)), ((0.0, 0.101), (-0.02, 0.02)),
                 ((0.0, 0.1), (-0.021, 0.02)), ((0.0, 0.1), (-0.02, 0.021))):
        refused("blocks.a", "lies outside the grid", {"a": box(x, y)})


def test_blocks_that_touch_do_not_overlap_and_those_that_share_area_do() -> None:
    assert len(scenario({"a": box((0.0, 0.05), (-0.01, 0.01)),
                         "b": box((0.05, 0.1), (-0.01, 0.01)),
                         "c": box((0.0, 0.05), (0.01, 0.02))}).blocks) == 3
    refused("blocks.b", "blocks 'a' and 'b' overlap", {"a": box((0.0, 0.05), (-0.01, 0.01)),
                                                       "b": box((0.049, 0.1), (0.0, 0.01))})
    refused("blocks.b", "overlap", {"a": box((0.05, 0.1), (-0.01, 0.01)),
                                    "b": box((0.0, 0.051), (-0.02, 0.0))})
    # touching from the other side: the second block left of or below the first
    assert len(scenario({"a": box((0.05, 0.1), (-0.01, 0.01)),
                         "b": box((0.0, 0.05), (-0.01, 0.01))}).blocks) == 2
    assert len(scenario({"a": box((0.0, 0.05), (0.0, 0.02)),
                         "b": box((0.0, 0.05), (-0.02, 0.0))}).blocks) == 2


def test_discs_overlap_only_closer_than_their_radii() -> None:
    touching = {"a": disc((0.03, 0.0), 0.01), "b": disc((0.06, 0.0), 0.02)}
    assert len(scenario(touching).blocks) == 2  # 0.03 apart, radii 0.01 + 0.02
    refused("blocks.b", "overlap", {"a": disc((0.03, 0.0), 0.01),
                                    "b": disc((0.055, 0.0), 0.02)})


def test_a_disc_and_a_box_overlap_by_the_nearest_point_either_way_round() -> None:
    # the disc's bounding square reaches into the box's corner, the disc does not
    corner = {"a": box((0.0, 0.05), (-0.02, 0.0)), "b": disc((0.06, 0.005), 0.0105)}
    assert len(scenario(corner).blocks) == 2
    reversed_corner = {"b": corner["b"], "a": corner["a"]}
    assert len(scenario(reversed_corner).blocks) == 2
    # touching the box's corner exactly (a 3-4-5 triangle in binary fractions: exact)
    assert len(scenario({"a": box((0.0, 0.0625), (-0.02, 0.0)),
                         "b": disc((0.0625 + 3 * 2 ** -9, 4 * 2 ** -9), 5 * 2 ** -9)}).blocks) == 2
    # a disc left of the box reaching into it
    refused("blocks.b", "overlap", {"a": box((0.05, 0.1), (-0.02, 0.02)),
                                    "b": disc((0.04, 0.0), 0.011)})
    refused("blocks.b", "overlap", {"a": disc((0.04, 0.0), 0.011),
                                    "b": box((0.05, 0.1), (-0.02, 0.02))})
    # below the box's y range, its nearest point on the box's low y edge (4 mm away)
    refused("blocks.b", "overlap", {"a": box((0.0, 0.1), (0.005, 0.02)),
                                    "b": disc((0.05, 0.001), 0.006)})


def test_the_workpiece_lists_each_block_once_by_name() -> None:
    for names, words in ((("a",), "defined but not listed"), ([], "non-empty list"),
                         ("a", "non-empty list"), (["a", 1], "non-empty list"),
                         (["a", "a", "b"], "listed twice")):
        table = copy.deepcopy(BASE)
        table["workpiece"]["blocks"] = list(names) if isinstance(names, tuple) else names
        with pytest.raises(ConfigError, match=words):
            scenario_from_table(table, "test")
    table = copy.deepcopy(BASE)
    table["workpiece"]["extra"] = 1
    with pytest.raises(ConfigError, match="unknown key") as error:
        scenario_from_table(table, "test")
    assert error.value.key == "workpiece.extra"
    table = copy.deepcopy(BASE)
    table["extra"] = {}
    with pytest.raises(ConfigError, match="unknown table") as error:
        scenario_from_table(table, "test")
    assert error.value.key == "extra"


def test_a_block_damping_of_zero_is_allowed_and_below_it_named() -> None:
    assert scenario({"a": box((0.0, 0.05), (-0.01, 0.01), damping=0.0)}).blocks[0] \
        .damping_N_s_per_m == 0.0
    assert scenario({"a": box((0.0, 0.05), (-0.01, 0.01), damping=0.5)}).blocks[0] \
        .damping_N_s_per_m == 0.5
    refused("blocks.a.damping_N_s_per_m", "negative damping (-0.5 N s/m)",
            {"a": box((0.0, 0.05), (-0.01, 0.01), damping=-0.5)})


def test_the_chamfer_must_be_narrower_than_the_tool() -> None:
    assert scenario(tool={"radius_m": 0.004, "edge_width_m": 0.0079}).tool.edge_width_m == 0.0079
    refused("tool.edge_width_m", "must be below the tool diameter 0.008 m",
            tool={"radius_m": 0.004, "edge_width_m": 0.008})
    refused("tool.edge_width_m", "diameter 0.008 m",
            tool={"radius_m": 0.004, "edge_width_m": 0.011})  # above 2 r, below 3 r


def test_the_tool_may_start_on_the_grids_edge_but_not_beyond() -> None:
    for start in ([0.0, -0.02], [0.1, 0.02]):
        assert scenario(tool={"start_position_m": start}).tool.start_position_m == tuple(start)
    for start in ([-0.001, 0.0], [0.101, 0.0], [0.05, -0.021], [0.05, 0.021], [0.2, 0.5]):
        refused("tool.start_position_m", "lies outside the grid",
                tool={"start_position_m": start})


def test_environment_changes_are_checked() -> None:
    loaded = scenario()
    assert loaded.with_environment("linear").environment == "linear"
    with pytest.raises(ConfigError, match="must be one of clay, linear"):
        loaded.with_environment("rubber")
    assert max_block_damping(loaded) == 100.0
    assert max_block_damping(dataclasses.replace(loaded, blocks=())) is None


def test_a_scenario_path_is_a_toml_file_that_exists(tmp_path: Path) -> None:
    for name in ("no-such", "", "a\x00b", "x" * 5000):  # the last too long for a file name
        with pytest.raises(ConfigError, match="unknown scenario") as error:
            load_scenario(name)
        assert error.value.key == "slave.scenario"
    missing = tmp_path / "missing.toml"  # a suffix: read, and its error named
    with pytest.raises(ConfigError, match="cannot read scenario file") as error:
        load_scenario(missing)
    assert error.value.key == "slave.scenario"
    existing = tmp_path / "scenario"  # no suffix, but it exists: read
    existing.write_text(GOOD)
    assert load_scenario(existing).name == "test"
