"""haptic-sim from the command line: run, sweep (with --check) and config errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from haptic.lockstep.cli import _floats, main


def test_run_writes_traces_and_plot(tmp_path, capsys) -> None:
    out = tmp_path / "run"
    assert main(["run", "--scenario", "constant-rate", "--environment", "linear",
                 "--duration", "0.2", "--round-trip-delay", "0.005", "--out", str(out),
                 "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["round_trip_delay_s"] == pytest.approx(9 * 0.00054)
    traces = np.load(out / "traces.npz")
    assert traces["handle_force_N"].shape == (370, 2)
    assert (out / "traces.png").stat().st_size > 0


def test_governed_run_lowers_k_after_a_delay_step(tmp_path, capsys) -> None:
    out = tmp_path / "run"
    assert main(["run", "--scenario", "constant-rate", "--environment", "linear", "--k", "13",
                 "--duration", "0.4", "--delay-profile-to-master", "step 0:0.002 0.2:0.040",
                 "--governor", "--safety", "off", "--out", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["governor_nominal_k"] == 13.0 and summary["governor_final_k"] < 8.6
    assert summary["governor_events"][0]["kind"] == "governor_lower_k"
    assert 0.2 < summary["governor_events"][0]["time_s"] < 0.24
    gains = np.load(out / "traces.npz")["gain_k"]
    assert gains[0] == 13.0 and gains[-1] == summary["governor_final_k"]


def test_quick_sweep_agrees_with_the_analysis(tmp_path, capsys) -> None:
    assert main(["sweep", "--gains", "3,13,19", "--delays", "0.004,0.011,0.02",
                 "--duration", "2", "--out", str(tmp_path), "--json", "--check"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["cells"] == 9 and summary["disagree_outside_band"] == 0
    assert summary["agree"] == 9
    rows = (tmp_path / "sweep.csv").read_text().splitlines()
    assert len(rows) == 10 and rows[0].startswith("k,round_trip_delay_s")
    assert (tmp_path / "sweep.png").stat().st_size > 0


@pytest.mark.parametrize("argv", [["run", "--round-trip-delay", "-1"], ["run", "--loss", "2"],
                                  ["run", "--operator", "dance:fx=1"],
                                  ["run", "--delay-profile-to-master", "step 0:0.002 3"],
                                  ["run", "--delay-profile-to-slave", "ramp 0:0.1"],
                                  ["sweep", "--gains", "0,3"]])
def test_bad_arguments_exit_2_with_one_line(argv, capsys) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_ranges() -> None:
    assert _floats("0:0.002:0.001") == pytest.approx((0.0, 0.001, 0.002))
    assert _floats("1,3") == (1.0, 3.0)


def test_run_reports_the_analysis_and_warns_when_it_calls_the_loop_unstable(tmp_path,
                                                                            capsys) -> None:
    """The paper's k = 13 against the clay (Tt = B s, B = 100 N s/m) is unstable even without
    delay in the sampled analysis; the simulator runs it and says so, and the summary carries
    the verdict next to what the run did (the tool flies off: far over the 3.6 N of a cut)."""
    out = tmp_path / "run"
    assert main(["run", "--k", "13", "--duration", "1.0", "--out", str(out), "--json"]) == 0
    captured = capsys.readouterr()
    summary = json.loads(captured.out)
    assert summary["environment"] == "clay"
    assert summary["analysis"]["stable"] is False and summary["analysis"]["k"] == 13.0
    assert "k = 13 at 0.00 ms round trip is UNSTABLE" in captured.err
    assert max(summary["peak_tool_force_N"]) > 50.0
    assert main(["run", "--k", "1", "--duration", "0.3", "--out", str(out), "--json"]) == 0
    captured = capsys.readouterr()
    assert json.loads(captured.out)["analysis"]["stable"] is True
    assert "UNSTABLE" not in captured.err


def test_run_prints_the_analysis_as_the_programs_stability_line(tmp_path, capsys) -> None:
    """Not a Python dict: the verdict as haptic-master and haptic-slave print it."""
    assert main(["run", "--environment", "linear", "--k", "13", "--duration", "0.1",
                 "--round-trip-delay", "0.005", "--out", str(tmp_path)]) == 0
    lines = capsys.readouterr().out.splitlines()
    analysis = [line for line in lines if line.startswith("analysis: ")]
    assert analysis == ["analysis: stability (sampled-data loop at Ts): k = 13, round-trip "
                        "delay 4.86 ms: stable; delay margin 14.31 ms (+9.45 ms left)"]
    assert not any("{" in line for line in lines)
