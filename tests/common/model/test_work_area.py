"""The work area both sides hold (common/model/work_area.py): the handle's workspace times
Ah1 and the slave's work area, the tighter bound of each applied to both."""

from __future__ import annotations

import dataclasses

import pytest

from haptic.common.config import ConfigError, load_config
from haptic.common.config.scenario import load_scenario
from haptic.common.model.work_area import (
    HANDLE_WORKSPACE,
    SLAVE_WORK_AREA,
    WORK_AREA_MARGIN_M,
    shared_work_area,
    slave_work_area_m,
    work_area_from_config,
)


def test_the_paper_defaults_take_the_tighter_bound_of_each_side() -> None:
    # handle +-150 mm on both axes (Ah1 = 1); the constant-rate grid x 0..160, y -20..20 mm
    grid = load_scenario("constant-rate").grid
    area = work_area_from_config(load_config(), grid.x_range_m, grid.y_range_m)
    assert area.tool_low_m == pytest.approx((-0.01, -0.03), abs=1e-15)
    assert area.tool_high_m == pytest.approx((0.15, 0.03), abs=1e-15)
    assert area.handle_low_m == area.tool_low_m and area.handle_high_m == area.tool_high_m
    assert area.limited_by == (SLAVE_WORK_AREA, HANDLE_WORKSPACE, SLAVE_WORK_AREA,
                               SLAVE_WORK_AREA)
    assert "x -10.0..150.0 mm (low: slave work area, high: handle workspace)" in area.describe()


def test_the_slave_work_area_is_the_grid_plus_the_margin() -> None:
    assert WORK_AREA_MARGIN_M == 0.01
    assert slave_work_area_m((0.0, 0.16), (-0.02, 0.02)) == pytest.approx(
        (-0.01, 0.17, -0.03, 0.03))


def test_a_position_ratio_maps_the_bounds_both_ways() -> None:
    # Ah1 = 2 on x: the handle's +-50 mm reach the tool's +-100 mm; the tool's area cuts the
    # high side at 80 mm, which the handle holds at 40 mm
    area = shared_work_area((2.0, 1.0), (-0.05, -0.1), (0.05, 0.1), (-0.2, 0.08, -0.05, 0.2))
    assert area.tool_low_m == pytest.approx((-0.1, -0.05))
    assert area.tool_high_m == pytest.approx((0.08, 0.1))
    assert area.handle_low_m == pytest.approx((-0.05, -0.05))
    assert area.handle_high_m == pytest.approx((0.04, 0.1))
    assert area.limited_by == (HANDLE_WORKSPACE, SLAVE_WORK_AREA, SLAVE_WORK_AREA,
                               HANDLE_WORKSPACE)


def test_a_negative_ratio_swaps_the_handle_bounds() -> None:
    # Ah1 = -1 on x: the tool's high bound is the handle's low one
    area = shared_work_area((-1.0, 1.0), (-0.02, -0.1), (0.15, 0.1), (-0.1, 0.01, -1.0, 1.0))
    assert area.tool_low_m[0] == pytest.approx(-0.1)
    assert area.tool_high_m[0] == pytest.approx(0.01)
    assert area.handle_low_m[0] == pytest.approx(-0.01)
    assert area.handle_high_m[0] == pytest.approx(0.1)


def test_the_handle_bounds_never_round_past_the_workspace() -> None:
    area = shared_work_area((3.0, 1.0), (-0.1, -0.1), (0.1, 0.1), (-1.0, 1.0, -1.0, 1.0))
    assert area.handle_low_m[0] >= -0.1 and area.handle_high_m[0] <= 0.1


def test_areas_that_do_not_overlap_are_a_configuration_error() -> None:
    with pytest.raises(ConfigError) as error:
        shared_work_area((1.0, 1.0), (-0.15, -0.15), (0.15, 0.15), (0.2, 0.3, -0.1, 0.1))
    assert error.value.key == "master.safety.workspace_max_m"
    assert "do not overlap on x" in str(error.value)
    with pytest.raises(ConfigError, match="non-zero on y"):
        shared_work_area((1.0, 0.0), (-0.15, -0.15), (0.15, 0.15), (-1, 1, -1, 1))


def test_the_work_area_is_frozen() -> None:
    area = shared_work_area((1.0, 1.0), (-0.1, -0.1), (0.1, 0.1), (-1.0, 1.0, -1.0, 1.0))
    with pytest.raises(dataclasses.FrozenInstanceError):
        area.tool_low_m = (0.0, 0.0)  # type: ignore[misc]


def test_the_description_names_each_bound_and_its_value_in_mm() -> None:
    # x: the slave's area binds low, the handle high; y: the handle low, the slave high
    area = shared_work_area((1.0, 1.0), (-0.2, -0.0125), (0.0375, 0.2), (-0.0625, 1.0, -1.0,
                                                                         0.0875))
    assert area.describe() == (
        "tool and handle (times Ah1) held to x -62.5..37.5 mm (low: slave work area, high: "
        "handle workspace); y -12.5..87.5 mm (low: handle workspace, high: slave work area)")


def test_a_bound_the_two_sides_share_exactly_is_the_handles() -> None:
    area = shared_work_area((1.0, 1.0), (-0.05, -0.05), (0.05, 0.05), (-0.05, 0.05, -0.05, 0.05))
    assert area.limited_by == (HANDLE_WORKSPACE,) * 4
    assert area.tool_low_m == (-0.05, -0.05) and area.tool_high_m == (0.05, 0.05)


def test_boxes_that_only_touch_leave_no_position_and_the_error_gives_both() -> None:
    with pytest.raises(ConfigError) as error:
        shared_work_area((1.0, 1.0), (-0.25, -0.1), (0.125, 0.1), (0.125, 0.5, -0.1, 0.1))
    assert ("the handle's workspace times Ah1 (-0.25..0.125 m) and the slave's work area "
            "(0.125..0.5 m) do not overlap on x") in str(error.value)


def test_the_tools_bound_maps_back_to_the_handle_through_the_ratio() -> None:
    # Ah1 = 2 on x: the slave's area cuts the low side at -60 mm, the handle's at -30 mm
    area = shared_work_area((2.0, 1.0), (-0.05, -0.1), (0.05, 0.1), (-0.06, 1.0, -1.0, 1.0))
    assert area.tool_low_m[0] == -0.06 and area.handle_low_m[0] == pytest.approx(-0.03)
    assert area.handle_high_m[0] == 0.05 and area.tool_high_m[0] == pytest.approx(0.1)


def test_the_configuration_gives_each_axis_its_own_ratio() -> None:
    config = load_config()
    config["model"]["position_ratio_ah1"] = [[2.0, 0.0], [0.0, 0.5]]
    area = work_area_from_config(config, (-1.0, 1.0), (-1.0, 1.0))
    assert area.tool_high_m == pytest.approx((0.3, 0.075))  # the handle's 150 mm times Ah1
    assert area.handle_high_m == pytest.approx((0.15, 0.15))
