"""Scenario files: the shipped ones and clear errors for bad ones."""

from __future__ import annotations

import pytest

from haptic.common.config import ConfigError, load_config, override
from haptic.common.config.scenario import SCENARIO_NAMES, load_scenario
from haptic.slave_sim.clay.workpiece import build_workpiece

GOOD = """
[scenario]
name = "test"
description = "a test"
environment = "clay"
[grid]
x_range_m = [0.0, 0.1]
y_range_m = [-0.02, 0.02]
cells_x = 200
cells_y = 80
[tool]
radius_m = 0.005
bottom_height_m = 0.007
reference_depth_m = 0.003
edge_width_m = 0.001
max_speed_m_s = 0.5
start_position_m = [0.0, 0.0]
[operator]
handle_force_N = [3.0, 0.0]
[workpiece]
blocks = ["a", "b"]
[blocks.a]
shape = "box"
x_range_m = [0.02, 0.05]
y_range_m = [-0.01, 0.01]
height_m = 0.01
damping_N_s_per_m = 100.0
[blocks.b]
shape = "disc"
center_m = [0.07, 0.0]
radius_m = 0.01
height_m = 0.01
damping_N_s_per_m = 50.0
"""


def write(tmp_path, text: str):
    path = tmp_path / "scenario.toml"
    path.write_text(text)
    return path


def test_shipped_scenarios_load_with_the_papers_values() -> None:
    for name in SCENARIO_NAMES:
        assert load_scenario(name).name == name
    constant = load_scenario("constant-rate")
    (clay,) = constant.blocks
    assert clay.x_range_m == (0.02, 0.12) and clay.damping_N_s_per_m == 100.0
    assert constant.tool.start_position_m == (0.0, 0.0)
    variable = load_scenario("variable-rate")
    assert [b.damping_N_s_per_m for b in variable.blocks] == [100.0, 80.0, 60.0, 40.0, 20.0]
    assert [b.x_range_m[1] - b.x_range_m[0] for b in variable.blocks] == pytest.approx([0.03] * 5)
    assert variable.blocks[0].x_range_m[0] == 0.02 and variable.blocks[-1].x_range_m[1] == 0.17
    assert variable.handle_force_N == (3.0, 0.0)


def test_workpiece_rasterises_every_block(tmp_path) -> None:
    workpiece = build_workpiece(load_scenario(write(tmp_path, GOOD)))
    assert set(workpiece.block_id.ravel()) == {-1, 0, 1}
    area = (workpiece.block_id == 0).sum() * workpiece.cell_area_m2
    assert area == pytest.approx(0.03 * 0.02, rel=0.02)
    assert ((workpiece.heights_m > 0) == (workpiece.block_id >= 0)).all()


@pytest.mark.parametrize(
    ("change", "key", "words"),
    [
        (('blocks = ["a", "b"]', 'blocks = ["a", "b", "c"]'), "workpiece.blocks",
         "unknown block 'c'"),
        (('blocks = ["a", "b"]', 'blocks = ["a"]'), "blocks.b", "not listed"),
        (("x_range_m = [0.02, 0.05]", "x_range_m = [0.02, 0.065]"), "blocks.b", "overlap"),
        (("damping_N_s_per_m = 50.0", "damping_N_s_per_m = -5.0"), "blocks.b.damping_N_s_per_m",
         "negative damping"),
        (("center_m = [0.07, 0.0]", "center_m = [0.095, 0.0]"), "blocks.b", "outside the grid"),
        (('shape = "disc"', 'shape = "cone"'), "blocks.b.shape", "must be one of"),
        (("radius_m = 0.01\n", "radius_m = 0.01\ncolour = 1\n"), "blocks.b.colour", "unknown key"),
        (("height_m = 0.01\ndamping_N_s_per_m = 100.0", "damping_N_s_per_m = 100.0"),
         "blocks.a.height_m", "missing key"),
        (('environment = "clay"', 'environment = "water"'), "scenario.environment",
         "must be one of"),
        (("cells_x = 200", "cells_x = 0"), "grid.cells_x", ">= 1"),
        (("radius_m = 0.005", "radius_m = -0.005"), "tool.radius_m", "> 0"),
    ],
)
def test_bad_scenarios_name_the_problem(tmp_path, change, key, words) -> None:
    old, new = change
    assert old in GOOD
    with pytest.raises(ConfigError) as error:
        load_scenario(write(tmp_path, GOOD.replace(old, new, 1)))
    assert error.value.key == key
    assert words in str(error.value)


def test_unknown_scenario_name_is_an_error() -> None:
    with pytest.raises(ConfigError, match="unknown scenario 'no-such'"):
        load_scenario("no-such")


def test_slave_config_section_is_validated() -> None:
    config = load_config()
    assert {k: v for k, v in config["slave"].items() if k != "safety"} == {
                               "scenario": "constant-rate", "environment": "scenario",
                               "clay_impl": "warp", "device": "auto",
                               "pacing": {"follow_master_samples": True,
                                          "max_steps_per_tick": 4,
                                          "max_backlog_samples": 32},
                               "phase_lock": {"enabled": True, "margin_s": 3e-05}}
    assert override(config, "slave.device", "cuda:1")["slave"]["device"] == "cuda:1"
    with pytest.raises(ConfigError) as error:
        override(config, "slave.device", "tpu")
    assert error.value.key == "slave.device"
    with pytest.raises(ConfigError) as error:
        override(config, "slave.clay_impl", "taichi")
    assert error.value.key == "slave.clay_impl"
