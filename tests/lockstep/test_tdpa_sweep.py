"""``haptic-sim sweep --control {paper,tdpa}`` (issue 16): the JSON's per-cell figures and
counts, over a jitter-and-loss grid; the passivity layer bounds cells the paper's scheme does
not."""

from __future__ import annotations

import json

import pytest

from haptic.lockstep.cli import main

CELL_KEYS = {"round_trip_s", "jitter_s", "loss", "k", "bounded", "max_abs_force_N",
             "rms_force_error_N", "rms_position_error_m", "final_position_gap_m"}


def _sweep(capsys, control: str, *extra: str) -> dict:
    status = main(["sweep", "--control", control, "--gains", "13", "--delays", "0,0.05",
                   "--duration", "1.5", "--json", *extra])
    out = json.loads(capsys.readouterr().out)
    out["status"] = status
    return out


@pytest.mark.slow
def test_sweep_json_has_per_cell_figures_and_tdpa_bounds_what_paper_does_not(capsys) -> None:
    paper = _sweep(capsys, "paper")
    tdpa = _sweep(capsys, "tdpa", "--jitter", "0,0.01", "--loss", "0,0.2", "--bursty",
                  "--check")
    assert paper["control"] == "paper" and tdpa["control"] == "tdpa"
    assert paper["cells"] == 2 and len(paper["per_cell"]) == 2
    assert tdpa["cells"] == 8 and len(tdpa["per_cell"]) == 8  # 2 delays x 2 jitters x 2 losses
    for summary in (paper, tdpa):
        assert summary["bounded"] + summary["unbounded"] == summary["cells"]
        assert summary["agree"] + summary["disagree"] == summary["cells"]  # today's keys
        for cell in summary["per_cell"]:
            assert CELL_KEYS <= set(cell)
    by_delay = {round(c["round_trip_s"], 2): c for c in paper["per_cell"]}
    assert by_delay[0.0]["bounded"] and not by_delay[0.05]["bounded"]  # tau* = 14.3 ms
    assert tdpa["unbounded"] == 0 and tdpa["status"] == 0  # --check passes
    assert all(c["max_abs_force_N"] <= 2.0 for c in tdpa["per_cell"])
    assert {(c["jitter_s"], c["loss"]) for c in tdpa["per_cell"]} == {
        (0.0, 0.0), (0.0, 0.2), (0.01, 0.0), (0.01, 0.2)}
