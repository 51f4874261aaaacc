"""The clay law pinned at its limits: geometry constants, engagement cap and threshold, the
removal-weighted damping, state resets and validations, the footprint window at the grid's
edge. Small grids on the CPU device: fast (the mutation score runs this file first)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from haptic.common.config.scenario import load_scenario
from haptic.slave_sim.clay.clay_numpy import yield_numpy
from haptic.slave_sim.clay.sim import (
    MIN_DISPLACEMENT_M,
    NumpyClay,
    WarpClay,
    device_problem,
    geometry_for,
    make_clay,
    resolve_device,
)

SAMPLE_PERIOD_S = 0.00054
#: A deep block at the grid's low x edge (5 mm above the tool's bottom, d_ref = 3 mm), air,
#: then two shallow blocks (1.5 mm) of different damping meeting at y = 0. 0.25 mm cells.
LIMITS_SCENARIO = """
[scenario]
name = "limits"
description = "small grid for the clay's limits"
environment = "clay"
[grid]
x_range_m = [0.0, 0.04]
y_range_m = [-0.01, 0.01]
cells_x = 160
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
blocks = ["deep", "a", "b"]
[blocks.deep]
shape = "box"
x_range_m = [0.0, 0.012]
y_range_m = [-0.01, 0.01]
height_m = 0.012
damping_N_s_per_m = 60.0
[blocks.a]
shape = "box"
x_range_m = [0.028, 0.04]
y_range_m = [-0.01, 0.0]
height_m = 0.0085
damping_N_s_per_m = 100.0
[blocks.b]
shape = "box"
x_range_m = [0.028, 0.04]
y_range_m = [0.0, 0.01]
height_m = 0.0085
damping_N_s_per_m = 40.0
"""
AIR_X_M = 0.02  # no block at this x


@pytest.fixture(scope="module")
def scenario(tmp_path_factory):
    path = tmp_path_factory.mktemp("limits") / "limits.toml"
    path.write_text(LIMITS_SCENARIO)
    return load_scenario(str(path))


@pytest.fixture(scope="module", params=["numpy", "warp"])
def impl(request) -> str:
    return request.param


def _clay(scenario, impl: str, **coupling: float):
    return make_clay(scenario, SAMPLE_PERIOD_S, impl, "cpu", **coupling)


def test_geometry_constants_from_the_tool_dimensions(scenario) -> None:
    """Radii, window sizes and the per-step cut cap, computed here from the tool's size."""
    geo = geometry_for(scenario, SAMPLE_PERIOD_S)
    radius, width, depth = 0.005, 0.001, 0.003
    dx = dy = 0.04 / 160
    assert geo.outer_radius == pytest.approx(0.0055, rel=1e-12)
    assert geo.inner_radius == pytest.approx(0.0045, rel=1e-12)
    # the window spans the footprint's diameter plus a cell each side: 2 x 5.5 mm / 0.25 mm
    assert (geo.window_x, geo.window_y) == (46, 46)
    assert geo.cells_x == 160 and geo.cells_y == 80
    # the smoothstep's steepest slope is 1.5 (at u = 1/2): the chamfer's is 1.5 d_ref / w
    u = np.linspace(0.0, 1.0, 100001)
    slope = np.gradient(u * u * (3 - 2 * u), u).max()
    assert slope == pytest.approx(1.5, rel=1e-6)
    assert geo.cut_cap == pytest.approx(slope * depth / width * 0.5 * SAMPLE_PERIOD_S, rel=1e-6)
    assert geo.cut_cap == pytest.approx(1.215e-3, rel=1e-12)
    assert geo.edge_height == depth and geo.inv_edge_width == pytest.approx(1 / width)
    assert geo.cell_area == pytest.approx(dx * dy, rel=1e-12)
    assert (geo.x0, geo.y0, geo.bottom_height) == (0.0, -0.01, 0.007)
    # coarse cells (6.7 x 5 mm): ceil(11 / 6.7) + 2 = 4 columns; ceil(11 / 5) + 2 = 5 rows is
    # more than the grid's 4: the window is the whole grid, never more
    coarse = geometry_for(scenario.with_grid(6, 4), SAMPLE_PERIOD_S)
    assert (coarse.window_x, coarse.window_y) == (4, 4)
    # a window of ceil(2 R_out / dx) + 2 covers every cell whose centre the footprint reaches
    assert radius + 0.5 * width == geo.outer_radius


def test_window_covers_the_footprint_and_the_first_step_cuts_at_most_the_cap(scenario,
                                                                             impl) -> None:
    clay = _clay(scenario, impl)
    state = clay.initial_state(1)
    before = state.heights_m()[0]
    position = np.array([[0.006, 0.0]])  # inside the deep block
    result = clay.step(state, position, position, np.zeros((1, 2)))
    cut = before - state.heights_m()[0]
    x, y = clay.workpiece.cell_centers_m()
    distance = np.hypot(x[None, :] - 0.006, y[:, None])
    under_flat = distance < clay.geometry.inner_radius
    # 5 mm of clay over the flat bottom, capped to cut_cap per step, every cell of it
    assert cut[under_flat] == pytest.approx(clay.geometry.cut_cap, rel=1e-12)
    assert cut.max() == pytest.approx(clay.geometry.cut_cap, rel=1e-12)
    assert (cut[distance >= clay.geometry.outer_radius] == 0.0).all()
    assert (cut[distance < clay.geometry.outer_radius] > 0.0).all()
    assert result.removed_volume_m3[0] == pytest.approx(cut.sum() * clay.geometry.cell_area,
                                                        rel=1e-12)
    # a removal far above the reference cut for a still tool: engagement 1 (cutting)
    assert result.engagement[0] == 1.0 and result.cutting[0]
    assert result.damping_N_s_per_m[0] == pytest.approx(60.0, rel=1e-12)


def test_footprint_at_the_grid_edge_cuts_the_first_column(scenario, impl) -> None:
    """A tool centred on the grid's low x edge: the window starts at column 0 and cuts it."""
    clay = _clay(scenario, impl)
    state = clay.initial_state(1)
    position = np.array([[0.0, 0.0]])
    ix0, iy0 = clay.footprint_windows(position)
    assert ix0[0] == 0 and 0 < iy0[0] < 80 - 46
    clay.step(state, position, position, np.zeros((1, 2)))
    cut = clay.workpiece.heights_m - state.heights_m()[0]
    _, y = clay.workpiece.cell_centers_m()
    rows = np.abs(y) < 0.004
    assert cut[rows, 0] == pytest.approx(clay.geometry.cut_cap, rel=1e-12)
    # at the high edge too (the window's last column is the grid's)
    state = clay.initial_state(1)
    clay.step(state, np.array([[0.04, 0.0]]), np.array([[0.04, 0.0]]), np.zeros((1, 2)))
    cut = clay.workpiece.heights_m - state.heights_m()[0]
    assert (cut[rows, -1] > 0.0).all()


def test_cut_across_two_blocks_weights_the_damping_by_removal(scenario, impl) -> None:
    clay = _clay(scenario, impl)
    state = clay.initial_state(1)
    position = np.array([[0.034, 0.0015]])  # more of the footprint in b (y > 0) than in a
    result = clay.step(state, position, position, np.zeros((1, 2)))
    cut = clay.workpiece.heights_m - state.heights_m()[0]
    block = clay.workpiece.block_id
    volume_a = cut[block == 1].sum() * clay.geometry.cell_area
    volume_b = cut[block == 2].sum() * clay.geometry.cell_area
    assert volume_a > 0.0 and volume_b > 1.5 * volume_a
    expected = (100.0 * volume_a + 40.0 * volume_b) / (volume_a + volume_b)
    assert result.damping_N_s_per_m[0] == pytest.approx(expected, rel=1e-12)
    assert result.removed_volume_m3[0] == pytest.approx(volume_a + volume_b, rel=1e-12)


def _shifted_scenario(tmp_path, shift_m: tuple[float, float]):
    """LIMITS_SCENARIO with every x and y range and the start moved by ``shift_m``, m."""
    lines = []
    for line in LIMITS_SCENARIO.splitlines():
        key, _, value = line.partition(" = ")
        if key in ("x_range_m", "y_range_m", "start_position_m"):
            numbers = [float(v) for v in value.strip("[]").split(",")]
            if key == "start_position_m":
                numbers = [numbers[0] + shift_m[0], numbers[1] + shift_m[1]]
            else:
                numbers = [n + shift_m[key == "y_range_m"] for n in numbers]
            line = f"{key} = [{', '.join(repr(n) for n in numbers)}]"
        lines.append(line)
    path = tmp_path / "shifted.toml"
    path.write_text("\n".join(lines) + "\n")
    return load_scenario(str(path))


@pytest.mark.parametrize("shift_m", [(0.05, 0.03), (-0.05, -0.03)])
def test_the_cut_does_not_depend_on_where_the_grid_starts(scenario, impl, tmp_path,
                                                          shift_m) -> None:
    """The same cut, cell for cell, on a grid whose origin is moved either way, m (the row
    scan's chord is computed from the grid's origin: a sign slip there would skip cells under
    the tool on one side or the other)."""
    cuts, removed = [], []
    for grid_scenario, (dx, dy) in ((scenario, (0.0, 0.0)),
                                    (_shifted_scenario(tmp_path, shift_m), shift_m)):
        clay = _clay(grid_scenario, impl)
        state = clay.initial_state(1)
        position = np.array([[0.034 + dx, 0.0015 + dy]])  # across the blocks a and b
        result = clay.step(state, position, position, np.zeros((1, 2)))
        cuts.append(clay.workpiece.heights_m - state.heights_m()[0])
        removed.append(result.removed_volume_m3[0])
    assert removed[0] > 0.0
    assert removed[1] == pytest.approx(removed[0], rel=1e-9)
    np.testing.assert_allclose(cuts[1], cuts[0], rtol=0.0, atol=1e-9)


#: Cells of 2^-10 m and a tool of outer radius 5 x 2^-10 m: from a tool on a cell's centre,
#: twelve cell centres lie exactly on the outer radius (offsets (5, 0), (0, 5), (4, 3) and
#: (3, 4) cells, mirrored), every distance exact in binary. The block stands above the
#: chamfer's top (2 + 1 mm), so the tool would cut a cell its footprint reached.
EXACT_SCENARIO = """
[scenario]
name = "exact"
description = "binary-exact cells and tool"
environment = "clay"
[grid]
x_range_m = [0.0, 0.0625]
y_range_m = [-0.03125, 0.03125]
cells_x = 64
cells_y = 64
[tool]
radius_m = 0.00390625
bottom_height_m = 0.002
reference_depth_m = 0.001
edge_width_m = 0.001953125
max_speed_m_s = 0.5
start_position_m = [0.0, 0.0]
[operator]
handle_force_N = [3.0, 0.0]
[workpiece]
blocks = ["clay"]
[blocks.clay]
shape = "box"
x_range_m = [0.0, 0.0625]
y_range_m = [-0.03125, 0.03125]
height_m = 0.005
damping_N_s_per_m = 100.0
"""


def test_a_cell_centred_exactly_on_the_outer_radius_is_not_cut(tmp_path, impl) -> None:
    """The footprint is the open disc: distance < outer radius is cut, = is not."""
    path = tmp_path / "exact.toml"
    path.write_text(EXACT_SCENARIO)
    clay = _clay(load_scenario(str(path)), impl)
    cell = 2.0 ** -10
    assert clay.geometry.outer_radius == 5 * cell and clay.geometry.dx == cell
    state = clay.initial_state(1)
    position = np.array([[20.5 * cell, -0.03125 + 31.5 * cell]])  # cell (20, 31)'s centre
    clay.step(state, position, position, np.zeros((1, 2)))
    cut = clay.workpiece.heights_m - state.heights_m()[0]
    on_circle = {(31 + sy * dy, 20 + sx * dx) for dx, dy in ((5, 0), (0, 5), (4, 3), (3, 4))
                 for sx in (-1, 1) for sy in (-1, 1)}
    assert len(on_circle) == 12
    for row, column in on_circle:
        assert cut[row, column] == 0.0, (row, column)
    # one cell further in along each axis is cut, at the chamfer's height there
    for row, column in ((31, 24), (31, 16), (35, 20), (27, 20)):
        assert cut[row, column] > 0.0, (row, column)
    x, y = clay.workpiece.cell_centers_m()
    distance = np.hypot(x[None, :] - position[0, 0], y[:, None] - position[0, 1])
    assert (cut[distance >= clay.geometry.outer_radius] == 0.0).all()
    assert (cut[distance < clay.geometry.outer_radius] > 0.0).all()


def _hand_made_steps(area: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Six lanes' proxy moves (before, after) (6, 2), m, and cut sums (6, 2): removed m^3,
    damping-weighted m^3 N s/m, for the step's bookkeeping."""
    before = np.zeros((6, 2))
    after = np.array([
        [3e-4, 4e-4],  # diagonal, 0.5 mm: half the reference cut
        [3e-4, -4e-4],  # diagonal the other way: three reference cuts, capped at 1
        [MIN_DISPLACEMENT_M, 0.0],  # exactly at the threshold: counts as still
        [1e-4, 0.0],  # moved, nothing removed
        [0.0, 0.0],  # still, a speck removed
        [0.0, 0.0],  # still, nothing removed
    ])
    assert np.hypot(after[2, 0], after[2, 1]) == MIN_DISPLACEMENT_M
    volume_a, volume_b = 0.2 * area * 5e-4, 0.3 * area * 5e-4  # two blocks
    removed = np.array([volume_a + volume_b, 3 * area * 5e-4, 1e-20, 0.0, 1e-30, 0.0])
    weighted = np.array([100.0 * volume_a + 40.0 * volume_b, 60.0 * removed[1],
                         80.0 * 1e-20, 0.0, 20.0 * 1e-30, 0.0])
    return before, after, np.stack([removed, weighted], axis=1)


def test_result_engagement_and_damping_by_hand(scenario) -> None:
    """The step's bookkeeping on hand-made sums: lanes 0..5."""
    clay = NumpyClay(scenario, SAMPLE_PERIOD_S)
    area = clay.reference_area_m2
    assert area == pytest.approx(2 * 0.005 * 0.003, rel=1e-12)
    lanes = 6
    state = clay.initial_state(lanes)
    before, after, sums = _hand_made_steps(area)
    removed = sums[:, 0]
    force = np.arange(2 * lanes, dtype=float).reshape(lanes, 2)
    result = clay._result(state, sums, before, after, force)
    np.testing.assert_array_equal(result.cutting, [True, True, True, False, True, False])
    np.testing.assert_allclose(result.engagement, [0.5, 1.0, 1.0, 0.0, 1.0, 0.0], rtol=1e-12)
    np.testing.assert_allclose(result.damping_N_s_per_m, [64.0, 60.0, 80.0, 0.0, 20.0, 0.0],
                               rtol=1e-12)
    np.testing.assert_array_equal(result.removed_volume_m3, removed)
    np.testing.assert_array_equal(state.removed_total_m3, removed)
    np.testing.assert_array_equal(result.force_N, force)
    np.testing.assert_array_equal(result.proxy_position_m, after)
    with pytest.raises(dataclasses.FrozenInstanceError):
        result.engagement = np.ones(lanes)  # type: ignore[misc]


def test_the_warp_yield_kernel_keeps_the_books_numpy_keeps(scenario) -> None:
    """The Warp clay's bookkeeping runs in its yield kernel: on the hand-made steps its
    result columns are numpy's (``_result``), bit for bit."""
    reference = NumpyClay(scenario, SAMPLE_PERIOD_S)
    clay = WarpClay(scenario, SAMPLE_PERIOD_S, device="cpu")
    before, after, sums = _hand_made_steps(clay.reference_area_m2)
    expected = reference._result(reference.initial_state(6), sums, before, after,
                                 np.zeros((6, 2)))
    state = clay.initial_state(6)
    arrays = state.runtime["arrays"]
    arrays["proxy_prev"].numpy()[...] = before
    arrays["proxy"].numpy()[...] = after
    arrays["sums"].numpy()[...] = sums
    # the resistance and direction from an earlier cut: kept by the lanes that did not move
    # (lane 2 exactly at the threshold among them), replaced or cleared by those that did
    earlier_resistance = np.full(6, 7.0)
    earlier_direction = np.tile([0.6, 0.8], (6, 1))
    state.resistance.numpy()[...] = earlier_resistance
    state.direction.numpy()[...] = earlier_direction
    state.runtime["launches"][2].launch()  # the yield kernel alone
    result = state.runtime["host"]["result"]
    np.testing.assert_array_equal(result[:, 0], expected.removed_volume_m3)
    np.testing.assert_array_equal(result[:, 1] > 0.0, expected.cutting)
    np.testing.assert_array_equal(result[:, 2], expected.engagement)
    np.testing.assert_array_equal(result[:, 3], expected.damping_N_s_per_m)
    resistance, direction = earlier_resistance.copy(), earlier_direction.copy()
    yield_numpy(after.copy(), before.copy(), sums, resistance, direction, reference.contact)
    np.testing.assert_array_equal(state.resistance.numpy(), resistance)
    np.testing.assert_array_equal(state.direction.numpy(), direction)
    assert resistance[2] == 7.0 and tuple(direction[2]) == (0.6, 0.8)
    assert resistance[3] == 0.0 and resistance[0] == pytest.approx(64.0 * 0.5, rel=1e-12)


def test_a_steady_diagonal_shallow_cut_has_partial_engagement(scenario, impl) -> None:
    """Across a/b diagonally at 45 degrees, 1.5 mm deep: engagement ~0.45 every steady step,
    equal to the removal over the reference cut of the proxy's own travel."""
    clay = _clay(scenario, impl)
    state = clay.initial_state(1)
    speed = 0.04
    velocity = np.array([[speed, speed]]) / math.sqrt(2)
    position = np.array([[0.03, -0.007]])
    engagement, ratio = [], []
    for _ in range(300):
        previous = position
        position = previous + velocity * SAMPLE_PERIOD_S
        proxy_before = state.proxy_position_m()
        result = clay.step(state, previous, position, velocity)
        travel = np.hypot(*(result.proxy_position_m[0] - proxy_before[0]))
        engagement.append(result.engagement[0])
        ratio.append(result.removed_volume_m3[0] / (clay.reference_area_m2 * travel))
    late = slice(200, None)
    assert 0.3 < np.mean(engagement[late]) < 0.6
    np.testing.assert_allclose(engagement[late], ratio[late], rtol=1e-9)


def test_reset_of_some_lanes_and_of_all(scenario, impl) -> None:
    clay = _clay(scenario, impl)
    state = clay.initial_state(2)
    velocity = np.array([[0.04, 0.0], [0.04, 0.0]])
    position = np.array([[0.004, -0.003], [0.004, 0.003]])
    for _ in range(40):  # into the deep block: both lanes resist
        previous = position
        position = previous + velocity * SAMPLE_PERIOD_S
        clay.step(state, previous, position, velocity)
    resistance = state.resistance_N_s_per_m()
    proxy = state.proxy_position_m()
    assert (resistance > 0.0).all()
    target = np.array([0.03, 0.001])
    state.place_proxy(target, np.array([True, False]))
    np.testing.assert_array_equal(state.proxy_position_m(), [target, proxy[1]])
    np.testing.assert_array_equal(np.array(_host(state.proxy_prev))[0], target)
    np.testing.assert_array_equal(state.resistance_N_s_per_m(), [0.0, resistance[1]])
    state.place_proxy([[0.01, 0.002], [0.02, -0.002]])
    np.testing.assert_array_equal(state.proxy_position_m(), [[0.01, 0.002], [0.02, -0.002]])
    np.testing.assert_array_equal(_host(state.proxy_prev), [[0.01, 0.002], [0.02, -0.002]])
    np.testing.assert_array_equal(state.resistance_N_s_per_m(), [0.0, 0.0])
    assert state.contact_ready.tolist() == [True, True]


def _host(array) -> np.ndarray:
    return np.array(array.numpy() if hasattr(array, "numpy") else array)


def test_first_step_places_the_proxy_at_the_previous_position(scenario, impl) -> None:
    clay = _clay(scenario, impl)
    state = clay.initial_state()
    assert state.lanes == 1 and state.contact_ready.tolist() == [False]
    previous = np.array([[AIR_X_M, 0.0]])
    result = clay.step(state, previous, previous + [[1e-5, 0.0]], np.array([[0.02, 0.0]]))
    assert state.contact_ready.tolist() == [True]
    np.testing.assert_array_equal(_host(state.proxy_prev), previous)
    assert not result.cutting[0] and result.engagement[0] == 0.0


def test_a_state_says_once_every_lane_has_its_proxy(scenario, impl) -> None:
    """``contact_all_ready``: false until the first step has placed every lane's proxy, then
    true for good (the slave's one-launch catch-up, slave_sim/catch_up.py, runs only then)."""
    clay = _clay(scenario, impl)
    state = clay.initial_state(2)
    assert state.contact_all_ready is False
    position = np.array([[AIR_X_M, 0.0], [AIR_X_M, 0.001]])
    for _ in range(2):
        previous, position = position, position + [[1e-5, 0.0], [1e-5, 0.0]]
        clay.step(state, previous, position, np.array([[0.02, 0.0], [0.02, 0.0]]))
        assert state.contact_all_ready is True
        assert state.contact_ready.tolist() == [True, True]


def test_a_move_through_air_leaves_no_resistance(scenario, impl) -> None:
    """Cutting, then a step out into the air: the resistance drops to exactly 0 (not NaN)."""
    clay = _clay(scenario, impl)
    state = clay.initial_state(1)
    velocity = np.array([[-0.04, 0.0]])  # into the deep block towards -x
    position = np.array([[0.008, 0.0]])
    for _ in range(20):
        previous = position
        position = previous + velocity * SAMPLE_PERIOD_S
        clay.step(state, previous, position, velocity)
    assert state.resistance_N_s_per_m()[0] > 0.0
    # the tool pulls back out of the clay to the air gap: the proxy follows, nothing is cut
    velocity = -velocity
    away = np.array([[AIR_X_M, 0.0]])
    result = clay.step(state, position, away, velocity)
    assert not result.cutting[0]
    assert state.resistance_N_s_per_m().tolist() == [0.0]
    result = clay.step(state, away, away + [[1e-4, 0.0]], velocity)
    assert state.resistance_N_s_per_m().tolist() == [0.0]
    assert not result.force_N.any()


def test_block_damping_validation_at_zero(scenario, impl) -> None:
    clay = _clay(scenario, impl)
    state = clay.initial_state(2)
    state.set_block_damping(np.zeros(3))
    np.testing.assert_array_equal(state.block_damping_N_s_per_m(), np.zeros((2, 3)))
    state.set_block_damping([0.5, 0.25, 0.0])
    np.testing.assert_array_equal(state.block_damping_N_s_per_m(), [[0.5, 0.25, 0.0]] * 2)
    with pytest.raises(ValueError, match="damping"):
        state.set_block_damping([1.0, -1e-12, 1.0])
    np.testing.assert_array_equal(state.block_damping_N_s_per_m(), [[0.5, 0.25, 0.0]] * 2)
    assert isinstance(state.block_damping_N_s_per_m(), np.ndarray)


def test_coupling_validation_at_its_limits(scenario) -> None:
    for stiffness, damping in ((0.0, 1.0), (-1.0, 1.0), (1000.0, -1e-12)):
        with pytest.raises(ValueError, match="coupling"):
            NumpyClay(scenario, SAMPLE_PERIOD_S, stiffness, damping)
    clay = NumpyClay(scenario, SAMPLE_PERIOD_S, 1e-9, 0.0)
    assert (clay.coupling_stiffness_N_per_m, clay.coupling_damping_N_s_per_m) == (1e-9, 0.0)
    assert WarpClay(scenario, SAMPLE_PERIOD_S, "cpu", 1e-9, 0.0).contact.damping == 0.0


def test_device_auto_with_one_cuda_device(monkeypatch) -> None:
    """One CUDA device is enough for "auto" to pick it (no GPU needed: the count is asked)."""
    import warp as wp

    wp.init()
    for count, expected in ((0, "cpu"), (1, "cuda"), (2, "cuda")):
        monkeypatch.setattr(wp, "get_cuda_device_count", lambda count=count: count)
        assert resolve_device("auto") == expected
    assert resolve_device("cuda:1") == "cuda:1"



def test_a_cuda_device_this_machine_lacks_is_named(monkeypatch) -> None:
    """The clay's device check, by CUDA device count (no GPU needed: the count is asked):
    the device's form first, then its index (none: 0) against the count."""
    import warp as wp

    wp.init()
    for count, present, absent in ((0, (), ("cuda", "cuda:0")),
                                   (1, ("cuda", "cuda:0"), ("cuda:1",)),
                                   (2, ("cuda", "cuda:1"), ("cuda:2", "cuda:3"))):
        monkeypatch.setattr(wp, "get_cuda_device_count", lambda count=count: count)
        assert device_problem("cpu") is None
        assert "got 'gpu'" in device_problem("gpu")  # a bad name, whatever the count
        for device in present:
            assert device_problem(device) is None, (count, device)
        for device in absent:
            assert device_problem(device) == (
                f"no CUDA device {device!r} on this machine ({count} found)")


needs_cuda = pytest.mark.skipif(not __import__("warp").get_cuda_device_count(),
                                reason="needs a CUDA device")
#: Two lanes cutting on the CUDA device and in the numpy reference: one along x through the
#: deep block, one along y across the shallow blocks' seam (m/s and m).
CUDA_LANE_VELOCITY_M_S = np.array([[0.04, 0.0], [0.0, 0.04]])
CUDA_LANE_START_M = np.array([[0.003, 0.0], [0.03, -0.006]])


def _cut_on_cuda_and_numpy(scenario, steps: int, before_step=None):
    """Both clays stepped side by side for ``steps`` steps along the lanes above, every step's
    force, damping and proxy compared; ``before_step(step, cuda_state, numpy_state,
    position)`` changes both states first. Returns the two states."""
    ref = _clay(scenario, "numpy")
    cuda = make_clay(scenario, SAMPLE_PERIOD_S, "warp", "cuda")
    a, b = cuda.initial_state(2), ref.initial_state(2)
    position = CUDA_LANE_START_M
    for step in range(steps):
        if before_step is not None:
            before_step(step, a, b, position)
        previous = position
        position = previous + CUDA_LANE_VELOCITY_M_S * SAMPLE_PERIOD_S
        ra = cuda.step(a, previous, position, CUDA_LANE_VELOCITY_M_S)
        rb = ref.step(b, previous, position, CUDA_LANE_VELOCITY_M_S)
        np.testing.assert_allclose(ra.force_N, rb.force_N, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(ra.damping_N_s_per_m, rb.damping_N_s_per_m, rtol=1e-9,
                                   atol=1e-12)
        np.testing.assert_allclose(ra.proxy_position_m, rb.proxy_position_m, rtol=0, atol=1e-15)
    np.testing.assert_allclose(a.heights_m(), b.heights_m(), rtol=0, atol=1e-15)
    return a, b


@needs_cuda
def test_cuda_device_matches_numpy(scenario) -> None:
    """The CUDA path (pinned host buffers copied in and out) against the numpy reference."""
    cuda_state, _ = _cut_on_cuda_and_numpy(scenario, 60)
    assert (cuda_state.removed_total_m3 > 0).all()


@needs_cuda
def test_cuda_graph_sees_damping_and_proxy_changes_made_after_capture(scenario) -> None:
    """The CUDA step is a graph captured with the state: block damping set and a proxy placed
    mid-run (both written into the state's arrays in place) reach the next steps as they
    reach numpy's."""

    def change(step: int, cuda_state, numpy_state, position: np.ndarray) -> None:
        if step == 30:
            damping = numpy_state.block_damping_N_s_per_m() * np.array([[1.5], [0.5]])
            cuda_state.set_block_damping(damping)
            numpy_state.set_block_damping(damping)
        if step == 50:
            lane = np.array([True, False])
            cuda_state.place_proxy(position, lane)
            numpy_state.place_proxy(position, lane)

    cuda_state, numpy_state = _cut_on_cuda_and_numpy(scenario, 80, change)
    np.testing.assert_allclose(cuda_state.block_damping_N_s_per_m(),
                               numpy_state.block_damping_N_s_per_m())
