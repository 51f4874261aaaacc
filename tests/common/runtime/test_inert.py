"""No silent inert sessions (issue 17, common/runtime/inert.py)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from haptic.common.launch.cli import inert_flag
from haptic.common.runtime.inert import InertMonitor


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


def _session(out, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "haptic.common.launch.cli", "--duration", "4", "--rig", "model",
         "--out", str(out), *extra], capture_output=True, text=True, timeout=300)


@pytest.mark.slow
def test_100_ms_delay_start_up_is_not_silent(tmp_path) -> None:
    """The issue's case: 100 ms one-way delay and the default regulating operator. Either the
    forces come on (the simulated operator now waits for the ready lamp) or the run says it
    was inert; never 4 s with command 0 and no word."""
    out = tmp_path / "session"
    done = _session(out, "--one-way-delay", "0.1")
    assert done.returncode == 0, done.stderr[-2000:]
    master = json.loads((out / "master.json").read_text())
    enabled = any(e["kind"] == "node_enable" for e in master["events"])
    assert enabled != master["inert"], master["events"]
    assert master["inert"] == ("INERT SESSION: master" in (out / "report.md").read_text())


@pytest.mark.slow
def test_a_session_that_never_runs_is_flagged(tmp_path) -> None:
    """The slave refuses every handle message (a plausible-position box the handle is never
    in): the peer is present, the forces never come on; both sides say so, with the reason,
    on the status line's terms, in the summaries and in the session's report."""
    config = tmp_path / "box.toml"
    config.write_text("[slave.safety]\nposition_min_m = [0.05, 0.05]\n"
                      "position_max_m = [0.06, 0.06]\n\n[supervision]\ninert_after_s = 1.0\n")
    out = tmp_path / "session"
    done = _session(out, "--config", str(config))
    assert done.returncode == 0, done.stderr[-2000:]
    slave = json.loads((out / "slave.json").read_text())
    master = json.loads((out / "master.json").read_text())
    assert slave["inert"] and slave["inert_reason"] == "input fault", slave["inert_reason"]
    assert slave["input_guard"]["faults"] > 100
    assert master["inert"] and "resync does not complete" in master["inert_reason"]
    assert any(e["kind"] == "inert" for e in master["events"])
    report = (out / "report.md").read_text()
    assert "INERT SESSION: master" in report and "INERT SESSION: slave" in report
    assert "INERT SESSION" in done.stdout
