"""The haptic-slave-sim command."""

from __future__ import annotations

import numpy as np
import pytest

from haptic.slave_sim.scenario.cli import main


def test_runs_a_scenario_and_writes_the_workpiece(tmp_path, capsys) -> None:
    assert main(["--scenario", "variable-rate", "--duration", "0.6", "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "variable-rate" in printed and "p100" in printed
    saved = np.load(tmp_path / "clay.npz")
    assert saved["removed_total_m3"] > 0
    assert saved["heights_m"].min() >= 0 and saved["heights_m"].max() == pytest.approx(0.01)
    assert (tmp_path / "clay.png").stat().st_size > 10_000


def test_bad_scenario_exits_2(capsys) -> None:
    with pytest.raises(SystemExit) as stop:
        main(["--scenario", "no-such-scenario"])
    assert stop.value.code == 2
    assert "slave.scenario" in capsys.readouterr().err
