"""``haptic-sim compare`` end to end: the quick grid of two controls in a child process, its
JSON's shape, its files and the theory's agreements counted; a bad control list refused.

The whole quick grid (every control) runs in CI's own ``compare --quick --real-link`` step,
whose exit status judges its cells; each control's cells are tested in
tests/lockstep/test_compare_cells.py. Here the command's output is the subject: two controls,
the paper's scheme and a lane law, show every part of it at a third of the grid's time."""

from __future__ import annotations

import json

from haptic.lockstep.cli import main
from haptic.lockstep.compare_grid import CONTROLS
from haptic.lockstep.compare_heatmap import HEATMAP_METRICS
from tests.helpers.programs import Program, python_module

#: The quick grid's budget in CI on a loaded 2-core machine, s (it runs in well under it).
QUICK_TIMEOUT_S = 240.0
CELL_KEYS = {"control", "task", "round_trip_s", "loss", "loss_model", "jitter_s", "bounded",
             "peak_force_N", "impact_overshoot_ratio", "rms_position_error_m",
             "rms_force_error_N", "final_position_gap_m", "perceived_stiffness_ratio",
             "cut_force_N", "cut_speed_m_per_s"}


#: The controls the command runs here: the paper's scheme and one lane law.
SHOWN_CONTROLS = ("paper", "four-channel")


def test_quick_compare_prints_every_cell_z_width_and_theory_as_json(tmp_path) -> None:
    assert set(SHOWN_CONTROLS) <= set(CONTROLS)
    with Program(python_module("haptic.lockstep.cli", "compare", "--quick", "--json",
                               "--controls", ",".join(SHOWN_CONTROLS),
                               "--out", str(tmp_path))) as program:
        assert program.wait(QUICK_TIMEOUT_S) == 0, program.output()
        line = next(text for text in reversed(program.output().splitlines())
                    if text.startswith("{"))
    data = json.loads(line)
    assert set(data) >= {"controls", "cells", "z_width", "theory", "simulated_seconds",
                         "wall_seconds"}
    assert data["controls"] == list(SHOWN_CONTROLS)
    # the controls x 3 tasks x 3 delays x (no loss, 20 % bursty) x no jitter
    assert len(data["cells"]) == len(SHOWN_CONTROLS) * 3 * 3 * 2
    cuts = [cell for cell in data["cells"] if cell["task"] == "clay-cut"]
    assert {cell["control"] for cell in cuts} == set(SHOWN_CONTROLS)
    # without delay the paper's scheme cuts steadily, near the paper's 3.6 N at 38 mm/s
    paper_cut = next(cell for cell in cuts if cell["control"] == "paper"
                     and cell["round_trip_s"] == 0.0 and cell["loss"] == 0.0)
    assert paper_cut["bounded"] and 2.0 < paper_cut["cut_force_N"] < 4.0
    assert 0.02 < paper_cut["cut_speed_m_per_s"] < 0.045
    assert all(set(cell) >= CELL_KEYS for cell in data["cells"])
    assert {cell["loss_model"] for cell in data["cells"] if cell["loss"] > 0} == {"bursty"}
    assert len(data["z_width"]) == len(SHOWN_CONTROLS) * 3
    theory = data["theory"]
    # the paper's scheme: every constant-delay cell; four-channel: where Llewellyn holds
    assert theory["checked"] >= 2 * 3
    assert theory["disagreements"] == sum(not p["agree"] for p in theory["predictions"])
    assert 0 < data["wall_seconds"] < data["simulated_seconds"]
    assert json.loads((tmp_path / "compare.json").read_text())["cells"] == data["cells"]
    assert len((tmp_path / "cells.csv").read_text().splitlines()) == 1 + len(data["cells"])
    for metric in HEATMAP_METRICS:
        assert (tmp_path / f"heatmap_{metric.key}.svg").read_text().startswith("<svg")


def test_an_unknown_control_is_a_config_error(capsys) -> None:
    try:
        status = main(["compare", "--quick", "--controls", "wave,teleport"])
    except SystemExit as stop:
        status = stop.code
    assert status == 2
    assert "teleport" in capsys.readouterr().err
