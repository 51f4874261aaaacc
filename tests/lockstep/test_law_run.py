"""``haptic-sim run`` in the lane-law modes (lockstep/law_run.py): the comparison's lane
simulator on one task and network, the law's settings taken from ``[control]``, the paper
scheme's options refused with one line."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from haptic.common.config import ConfigError
from haptic.common.control.law_settings import LANE_CONTROLS, LawSettings
from haptic.lockstep.cli import main
from haptic.lockstep.law_run import run_law


@pytest.mark.parametrize("control", LANE_CONTROLS)
def test_each_law_pushes_into_the_wall_bounded(tmp_path, control) -> None:
    summary = run_law(control, LawSettings(), "wall", 0.05, 0.0, 0.0, 3.0, 0, tmp_path)
    assert summary["control"] == control and summary["bounded"]
    assert summary["peak_force_N"] > 0.5  # the hand pushed the tool into the wall
    assert summary["impact_overshoot_ratio"] is not None
    traces = np.load(tmp_path / "traces.npz")
    assert np.nanmax(traces["tool_position_x_m"]) > 0.01  # past the wall's surface


def test_the_configured_wave_impedance_is_the_one_that_runs(tmp_path) -> None:
    soft = run_law("wave", LawSettings(), "free-sine", 0.1, 0.0, 0.0, 1.5, 0, tmp_path)
    stiff = run_law("wave", replace(LawSettings(), wave_impedance_N_s_per_m=80.0),
                    "free-sine", 0.1, 0.0, 0.0, 1.5, 0, tmp_path)
    assert stiff["wave_impedance_N_s_per_m"] == 80.0
    assert stiff["rms_position_error_m"] != soft["rms_position_error_m"]


def test_a_period_other_than_the_lanes_is_refused(tmp_path) -> None:
    with pytest.raises(ConfigError, match="model.sample_period_s"):
        run_law("wave", replace(LawSettings(), period_s=0.001), "wall", 0.0, 0.0, 0.0, 1.0,
                0, tmp_path)


def test_the_cli_runs_a_law_and_refuses_the_paper_schemes_options(tmp_path, capsys) -> None:
    assert main(["run", "--control", "mmt", "--task", "clay-cut", "--duration", "3",
                 "--round-trip-delay", "0.02", "--out", str(tmp_path), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["control"] == "mmt" and summary["cut_force_N"] is not None
    with pytest.raises(SystemExit) as exited:
        main(["run", "--control", "wave", "--k", "2", "--out", str(tmp_path)])
    assert exited.value.code == 2
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 1 and "--k" in err[0]
