"""Cells of the comparison on cases whose outcome is known (short runs of small grids)."""

from __future__ import annotations

import gc

import numpy as np
import pytest

from haptic.common.config import load_config
from haptic.common.model.teleop import model_from_config
from haptic.lockstep.compare import run_compare
from haptic.lockstep.compare_grid import CompareGrid, Lane, Network, TaskSettings
from haptic.lockstep.compare_lanes import simulate_lanes

CELL_KEYS = {"control", "task", "round_trip_s", "loss", "loss_model", "jitter_s", "bounded",
             "peak_force_N", "impact_overshoot_ratio", "rms_position_error_m",
             "rms_force_error_N", "final_position_gap_m", "perceived_stiffness_ratio"}


def _wall_grid(controls: tuple[str, ...], stiffness_N_per_m: float,
               round_trips_s: tuple[float, ...]) -> CompareGrid:
    return CompareGrid(controls, ("wall",), round_trips_s, (0.0,), ("independent",), (0.0,),
                       (stiffness_N_per_m,),
                       TaskSettings(wall_stiffness_N_per_m=stiffness_N_per_m, settle_s=3.0))


def test_a_soft_wall_without_delay_feels_like_itself_through_wave_and_four_channel() -> None:
    result = run_compare(_wall_grid(("wave", "four-channel"), 300.0, (0.0,)))
    assert len(result.cells) == 2
    for cell in result.cells:
        assert set(cell) >= CELL_KEYS
        assert cell["bounded"], cell
        assert cell["perceived_stiffness_ratio"] == pytest.approx(1.0, abs=0.2), cell
        assert cell["final_position_gap_m"] < 1e-3
        assert cell["predicted_bounded"] is True
    assert [row["z_width_N_per_m"] for row in result.z_width] == [300.0, 300.0]
    # passivity (wave) and Llewellyn without delay (four-channel) predict the rung bounded
    assert [row["predicted_z_width_N_per_m"] for row in result.z_width] == [300.0, 300.0]
    assert result.theory()["checked"] == 2 and result.theory()["disagreements"] == 0


def test_the_passivity_layer_on_four_channel_keeps_the_soft_wall_and_yields_on_it() -> None:
    """Without delay the soft wall still feels like itself through four-channel-tdpa, which
    passivity predicts bounded; the master's account runs short when the wall gives energy
    back a period before the slave's account of it arrives, so the handle yields and ends
    millimetres from the tool (the layer has no drift correction)."""
    result = run_compare(_wall_grid(("four-channel-tdpa",), 300.0, (0.0,)))
    (cell,) = result.cells
    assert cell["bounded"] and cell["predicted_bounded"] is True
    assert cell["perceived_stiffness_ratio"] == pytest.approx(1.0, abs=0.2), cell
    assert 1e-3 < cell["final_position_gap_m"] < 5e-3
    assert result.theory()["checked"] == 1 and result.theory()["disagreements"] == 0


def test_free_motion_has_no_contact_figures() -> None:
    grid = CompareGrid(("mmt",), ("free-sine",), (0.05,), (0.0,), ("independent",), (0.0,),
                       (300.0,), TaskSettings(settle_s=2.0))
    (cell,) = run_compare(grid).cells
    assert cell["bounded"]
    assert cell["impact_overshoot_ratio"] is None and cell["perceived_stiffness_ratio"] is None
    assert 0.0 < cell["rms_position_error_m"] < 0.01
    assert "predicted_bounded" not in cell  # no theory for model-mediated control


def test_the_paper_scheme_beyond_its_delay_margin_is_reported_unbounded() -> None:
    # a 500 N/m spring leaves the paper's loop a round-trip margin of about 81 ms
    model = model_from_config(load_config(None))
    result = run_compare(_wall_grid(("paper",), 500.0, (0.04, 0.16)), model)
    below, beyond = result.cells
    assert below["bounded"] and below["predicted_bounded"] is True
    assert not beyond["bounded"] and beyond["predicted_bounded"] is False
    margins = {item["margin_s"] for item in result.theory()["predictions"]}
    assert len(margins) == 1 and 0.04 < margins.pop() < 0.16
    assert result.theory()["checked"] == 2 and result.theory()["disagreements"] == 0
    # the ladder's one rung: the Nyquist margin's Z-width, kept below it, none beyond it
    widths = [(row["z_width_N_per_m"], row["predicted_z_width_N_per_m"])
              for row in result.z_width]
    assert widths == [(500.0, 500.0), (None, None)]
    assert result.theory()["z_width_checked"] == 2
    assert result.theory()["z_width_disagreements"] == 0


def test_model_mediated_rests_on_the_wall_whatever_the_delay() -> None:
    """The master renders the model locally: past the first touch the delay does not matter.
    The quick grid's 3.2 s; at 50 ms the model used to vanish at each release and the handle
    to fall through it (a touch-and-release cycle, 98 N peaks)."""
    grid = CompareGrid(("mmt",), ("wall",), (0.01, 0.05), (0.0,), ("independent",), (0.0,),
                       (2000.0,), TaskSettings(settle_s=3.15))
    result = run_compare(grid)
    for cell in result.cells:
        assert cell["bounded"], cell  # the first touch's impact under the 20 N bound
        # at rest on the wall, pushed with the hand's 3.9 N: the same spot as without delay
        assert cell["final_position_gap_m"] < 5e-4, cell


def test_the_lane_simulator_controls_cut_the_clay_without_delay() -> None:
    # 2.2 s: the push ramps in over 1 s, the tool reaches the block at 2 cm and cuts past 4 cm
    grid = CompareGrid(("wave", "four-channel", "mmt"), ("clay-cut",), (0.0,), (0.0,),
                       ("independent",), (0.0,), (300.0,), TaskSettings(settle_s=2.2))
    result = run_compare(grid)
    assert [cell["control"] for cell in result.cells] == ["wave", "four-channel", "mmt"]
    for cell in result.cells:
        assert cell["task"] == "clay-cut" and cell["bounded"], cell
        assert "predicted_bounded" not in cell  # no theory for the clay cut
        # the clay (100 N s/m) resists the 3.6 N push: a cutting force and speed of the
        # paper's order (3.6 N at 38 mm/s), well below the free push's
        assert 1.0 < cell["cut_force_N"] < 4.0, cell
        assert 0.01 < cell["cut_speed_m_per_s"] < 0.045, cell
        assert cell["cut_force_N"] / cell["cut_speed_m_per_s"] == pytest.approx(100.0, rel=0.2)


def test_a_clay_lane_beside_them_leaves_the_other_lanes_bit_for_bit() -> None:
    network = Network(0.05, 0.2, "bursty", 0.0)
    grid = CompareGrid(("four-channel",), ("wall", "clay-cut"), (0.05,), (0.2,), ("bursty",),
                       (0.0,), (2000.0,), TaskSettings(settle_s=0.3))
    wall = Lane("wall", network, 2000.0)
    alone = simulate_lanes("four-channel", [wall], grid)
    beside = simulate_lanes("four-channel", [wall, Lane("clay-cut", network, 2000.0)], grid)
    for name in ("handle_position_m", "tool_position_m", "handle_force_N",
                 "environment_force_N"):
        assert np.array_equal(getattr(alone, name)[:, 0], getattr(beside, name)[:, 0]), name


@pytest.mark.usefixtures("thawed_heap")
def test_a_lane_run_freezes_the_heap_from_before_it_and_thaws_it_after(monkeypatch) -> None:
    """As the lockstep simulator's runs: what was alive before is not rescanned by a
    collection during the run, and is collectable again after."""
    import haptic.lockstep.compare_lanes as compare_lanes

    frozen_during: list[int] = []
    hand_force = compare_lanes.hand_force_N

    def watched(*args, **kwargs):
        frozen_during.append(gc.get_freeze_count())
        return hand_force(*args, **kwargs)

    monkeypatch.setattr(compare_lanes, "hand_force_N", watched)
    grid = CompareGrid(("wave",), ("wall",), (0.0,), (0.0,), ("independent",), (0.0,),
                       (300.0,), TaskSettings(settle_s=0.05))
    alive_before = len(gc.get_objects())
    simulate_lanes("wave", [Lane("wall", Network(0.0, 0.0, "independent", 0.0), 300.0)], grid)
    assert frozen_during and min(frozen_during) >= alive_before
    assert gc.get_freeze_count() == 0
