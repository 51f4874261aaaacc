"""haptic-replay times the cut on the samples' clock, as the slave does: a master that fell
behind real time stretches the cut on the wall clock (here to twice its length), not in the
figures. A recording without the sample clock says its figures are on the wall clock."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from haptic.common.records.recorder import McapRecorder
from haptic.slave_sim.program import SLAVE_RECORD_COLUMNS
from haptic.view.replay import cli as replay

TS = 0.00054
#: The cut: 2000 node steps (1.08 s of the samples' clock) at 38 mm/s along x.
STEPS = 2000
SPEED_M_S = 0.038


def _write(path: Path, columns: tuple[str, ...]) -> None:
    """A slave recording whose wall clock runs at half the samples' rate (a master at half
    its rate: each node step takes two of the slave's ticks)."""
    with McapRecorder(path, "slave") as recorder:
        recorder.add_channel("/slave/state", columns)
        for tick in range(2 * STEPS + 1):
            sample_s, wall_s = (tick // 2) * TS, tick * TS
            x = 0.02 + SPEED_M_S * sample_s
            row = {"time_s": wall_s, "sample_time_s": sample_s, "tool_position_x_m": x,
                   "tool_velocity_x_m_s": SPEED_M_S, "tool_force_x_N": 3.6, "cutting": 1.0,
                   "running": 1.0, "handle_force_x_N": 3.6}
            recorder.record("/slave/state", 10**9 + round(wall_s * 1e9),
                            tuple(row.get(name, 0.0) for name in columns))


def _cut(path: Path, capsys: pytest.CaptureFixture) -> tuple[dict, str]:
    assert replay.main([str(path), "--no-plots", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)["recordings"][0]
    assert replay.main([str(path), "--no-plots"]) == 0
    return summary, capsys.readouterr().out


def test_the_cut_is_timed_on_the_sample_clock(tmp_path: Path, capsys) -> None:
    assert "sample_time_s" in SLAVE_RECORD_COLUMNS  # what the slave records
    path = tmp_path / "slave.mcap"
    _write(path, SLAVE_RECORD_COLUMNS)
    summary, text = _cut(path, capsys)
    assert summary["cut_clock"] == "sample"
    assert summary["cutting_time_s"] == pytest.approx(STEPS * TS, rel=1e-3)
    assert summary["cut_mean_speed_m_s"] == pytest.approx(SPEED_M_S, rel=1e-3)
    assert "cut: 1.08 s in the clay, mean |ft| 3.600 N, mean speed 38.0 mm/s\n" in text


def test_a_recording_without_the_sample_clock_says_it_is_on_the_wall_clock(
        tmp_path: Path, capsys) -> None:
    path = tmp_path / "old.mcap"
    _write(path, tuple(name for name in SLAVE_RECORD_COLUMNS if name != "sample_time_s"))
    summary, text = _cut(path, capsys)
    assert summary["cut_clock"] == "wall"
    assert summary["cutting_time_s"] == pytest.approx(2 * STEPS * TS, rel=1e-3)
    assert "mean speed 19.0 mm/s (on the wall clock: the recording holds no sample clock)" in text
