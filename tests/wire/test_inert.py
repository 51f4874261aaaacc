"""No silent inert sessions (issue 17, common/inert.py)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from haptic.common.inert import InertMonitor
from haptic.common.session import inert_flag


def test_monitor_flags_forces_off_with_the_peer_present() -> None:
    monitor = InertMonitor(2.0)
    for tick in range(2000):  # 2 s at 1 kHz: not yet
        assert not monitor.update(tick * 1e-3, True, False, "gate")
    assert monitor.update(2.0, True, False, "gate")
    assert monitor.status() == "  INERT: gate"
    assert [e["kind"] for e in monitor.events] == ["inert"]
    assert not monitor.update(3.0, True, True, "gate")
    summary = monitor.summary(4.0)
    assert summary["inert"] and summary["inert_episodes"] == 1
    assert summary["inert_time_s"] == pytest.approx(1.0)
    assert inert_flag({"master": summary, "slave": {"inert": False}}).count("INERT") == 1


def test_waiting_for_a_peer_is_not_inert() -> None:
    monitor = InertMonitor(0.5)
    for tick in range(3000):
        assert not monitor.update(tick * 1e-3, False, False, "no peer")
    assert not monitor.summary(3.0)["inert"]


@pytest.mark.slow
def test_100_ms_delay_start_up_is_not_silent(tmp_path) -> None:
    """The issue's case: 100 ms one-way delay and the default regulating operator: the master's
    start-up gate never opens because the operator already pushes when the link is in sync.
    The run is flagged inert in the summaries and in the session's report."""
    out = tmp_path / "session"
    done = subprocess.run(
        [sys.executable, "-m", "haptic.common.session", "--duration", "4", "--rig", "model",
         "--delay", "0.1", "--out", str(out),
        ],
        capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    master = json.loads((out / "master.json").read_text())
    assert master["inert"], {k: master.get(k) for k in ("inert", "inert_reason", "events")}
    assert "start-up gate" in master["inert_reason"]
    assert any(e["kind"] == "inert" for e in master["events"])
    assert "INERT SESSION: master" in (out / "report.md").read_text()
    assert "INERT SESSION: master" in done.stdout
