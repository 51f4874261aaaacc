"""The comparison's grid, cell records and summaries, without simulating."""

from __future__ import annotations

import numpy as np
import pytest

from haptic.lockstep.compare import CompareResult, z_width_rows
from haptic.lockstep.compare_grid import CONTROLS, BoundSettings, CompareGrid, Lane, Network
from haptic.lockstep.compare_links import lane_schedules
from haptic.lockstep.compare_records import LaneRecords, bounded_lanes, cell_figures


def test_full_grid_has_every_network_once_per_task() -> None:
    grid = CompareGrid()
    networks = grid.networks()
    # a zero loss has one model; 5, 20, 50 % have two
    assert len(networks) == 9 * 2 * (1 + 3 * 2)
    assert len(set(networks)) == len(networks)
    # every control runs the three tasks, the clay cut included
    for control in CONTROLS:
        assert len(grid.cell_lanes(control)) == 3 * len(networks)
    free_and_wall = CompareGrid(tasks=("free-sine", "wall"))
    assert len(free_and_wall.cell_lanes("wave")) == 2 * len(networks)
    assert grid.duration_s == pytest.approx(3.0 + grid.task.settle_s)


def test_quick_grid_is_three_delays_two_losses_one_jitter_and_the_tasks() -> None:
    grid = CompareGrid.quick()
    assert len(grid.cell_lanes("mmt")) == len(grid.cell_lanes("paper")) == 3 * 2 * 1 * 3
    ladder = grid.ladder_lanes()
    assert all(lane.ladder and lane.network.constant_delay for lane in ladder)
    assert len(ladder) == 3 * len(grid.stiffness_ladder_N_per_m)


def test_bursty_loss_keeps_the_mean_rate() -> None:
    injection = Network(0.1, 0.2, "bursty", 0.0).injection()
    assert injection is not None and injection.loss_probability == 0.0
    enter, leave = injection.burst_enter_probability, injection.burst_exit_probability
    assert enter / (enter + leave) == pytest.approx(0.2)
    assert Network(0.1, 0.0, "independent", 0.0).injection() is None
    assert Network(0.1, 0.05, "independent", 0.01).injection().loss_probability == 0.05


def test_unknown_control_is_refused() -> None:
    with pytest.raises(ValueError, match="controls"):
        CompareGrid(controls=("paper", "wave-ish"))


def _records(forces: list[float], moving: bool = False) -> LaneRecords:
    records = LaneRecords.create(0.001, 100, len(forces), stride=1)
    for k in range(100):
        position = np.full(len(forces), 0.01 * np.sin(k) if moving else 0.0)
        records.add(k, position, position, np.asarray(forces, float), np.zeros(len(forces)))
    return records


def test_bounds_catch_a_large_force_a_non_finite_sample_and_a_fast_oscillation() -> None:
    bounds = BoundSettings(force_bound_N=20.0)
    assert bounded_lanes(_records([1.0, 25.0, np.nan]), bounds).tolist() == [True, False, False]
    assert not bounded_lanes(_records([1.0], moving=True), bounds)[0]


def test_a_steady_drift_is_not_an_oscillation() -> None:
    """Both devices still driven through the tail at 0.16 to 0.15 m/s (17 mJ of kinetic
    energy, over the 10 mJ bound: the clay cut's tool running on past the block) are bounded;
    a fast oscillation of 0.25 m/s amplitude (21 mJ) is not."""
    steps = 400
    records = LaneRecords.create(0.001, steps, 2, stride=1)
    time = np.arange(steps) * 0.001
    drift = 0.2 * time - 0.0625 * time * time  # 0.2 m/s at the start, 0.15 m/s at the end
    swing = 0.25 * np.sin(1000.0 * time) / 1000.0
    for k in range(steps):
        position = np.array([drift[k], swing[k]])
        records.add(k, position, position, np.zeros(2), np.zeros(2))
    assert bounded_lanes(records, BoundSettings()).tolist() == [True, False]


def test_z_width_is_the_last_rung_before_the_first_unbounded_one() -> None:
    grid = CompareGrid(controls=("wave",), round_trips_s=(0.0, 0.1),
                       stiffness_ladder_N_per_m=(100.0, 1e3, 1e4, 1e5))
    lanes = grid.ladder_lanes()
    verdicts = {(0.0, 100.0): True, (0.0, 1e3): True, (0.0, 1e4): False, (0.0, 1e5): True,
                (0.1, 100.0): False, (0.1, 1e3): True, (0.1, 1e4): True, (0.1, 1e5): True}
    bounded = np.array([verdicts[(lane.network.round_trip_s, lane.wall_stiffness_N_per_m)]
                        for lane in lanes])
    rows = z_width_rows("wave", grid, lanes + [Lane("wall", lanes[0].network, 1e6)],
                        np.append(bounded, True))
    assert [row["z_width_N_per_m"] for row in rows] == [1e3, None]
    assert rows[0]["ladder_bounded"] == [True, True, False, True]


def test_theory_counts_checked_predictions_and_disagreements() -> None:
    result = CompareResult(CompareGrid.quick())
    result.predictions = [
        {"control": "paper", "agree": True}, {"control": "paper", "agree": False},
        {"control": "wave", "agree": True}]
    theory = result.theory()
    assert theory["checked"] == 3 and theory["disagreements"] == 1
    assert theory["per_control"]["paper"] == {"checked": 2, "disagreements": 1}


def test_the_cut_figures_are_the_means_over_the_tool_ranges() -> None:
    records = LaneRecords.create(0.001, 2000, 1, stride=1)
    for k in range(2000):
        tool = np.array([0.0001 * k])  # 0.1 m/s, 0 to 0.2 m
        force = np.array([3.0 if 0.04 <= tool[0] <= 0.10 else 9.0])
        records.add(k, tool, tool, force, force)
    figures = cell_figures(records, 0, Lane("clay-cut", Network(0.0, 0.0, "independent", 0.0),
                                            2000.0), 0.0)
    assert figures["cut_force_N"] == pytest.approx(3.0)
    assert figures["cut_speed_m_per_s"] == pytest.approx(0.1)
    assert figures["perceived_stiffness_ratio"] is None


def test_every_control_meets_the_same_losses_on_a_cell() -> None:
    grid = CompareGrid.quick()
    steps, period = 2000, 0.00054
    # a run without the clay cut has fewer lanes: a cell's draws do not depend on them
    wave = CompareGrid(("wave",), ("free-sine", "wall"), grid.round_trips_s, grid.losses,
                       grid.loss_models, grid.jitters_s).cell_lanes("wave")
    paper = grid.cell_lanes("paper")
    assert len(wave) < len(paper)
    wave_schedules = lane_schedules(wave, steps, period, grid.seed)
    paper_schedules = lane_schedules(paper, steps, period, grid.seed)
    lossy = [i for i, lane in enumerate(wave) if lane.network.loss > 0]
    assert lossy
    for ours, theirs in zip(wave_schedules, paper_schedules, strict=True):
        assert (ours == theirs[:, :len(wave)]).all()
    # a lossy line skips messages: the newest receivable one repeats
    assert (np.diff(wave_schedules[0][:, lossy], axis=0) == 0).any()
