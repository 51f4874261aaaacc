"""``haptic-session`` end to end, briefly: both programs as child processes, the report."""

from __future__ import annotations

import json
import subprocess
import sys

from haptic.common.summary import REQUIRED_SUMMARY_KEYS


def test_session_runs_both_programs_and_writes_the_report(tmp_path) -> None:
    out = tmp_path / "session"
    process = subprocess.Popen(
        [sys.executable, "-m", "haptic.common.session", "--duration", "1.5", "--out", str(out)],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )
    try:
        log, _ = process.communicate(timeout=90)
    finally:
        if process.poll() is None:
            process.kill()
        process.wait()
    assert process.returncode == 0, log
    assert "session summary" in log and "in the clay" in log
    for name in ("report.md", "master.json", "slave.json", "clay.png", "clay.npz",
                 "session.png", "master_trace.npz", "slave_trace.npz"):
        assert (out / name).is_file(), name
    for side in ("master", "slave"):
        summary = json.loads((out / f"{side}.json").read_text())
        assert set(REQUIRED_SUMMARY_KEYS) <= set(summary)
        assert summary["side"] == side and summary["steps"] > 0
    slave = json.loads((out / "slave.json").read_text())
    assert slave["removed_volume_m3"] > 0.0  # the tool reached the clay and cut it
    report = (out / "report.md").read_text()
    assert "## master summary" in report and "## slave summary" in report
