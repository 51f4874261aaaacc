"""``haptic-session``'s exit status is the first program's own: a master that refuses the
loop (exit status 3) makes the session exit 3, whatever the slave it then had to stop says
(a slave still starting dies of the SIGTERM, status -15)."""

from __future__ import annotations

import subprocess
import sys
from typing import Any

from haptic.common.launch import cli


def test_the_first_side_to_fail_decides_the_status() -> None:
    assert cli.session_failure({"slave": -15, "master": 3}, ["master"]) == (3, [
        "haptic-session: master exited with status 3",
        "haptic-session: slave stopped by the session after the master ended (status -15)"])
    assert cli.session_failure({"slave": 3, "master": 3}, ["slave", "master"])[0] == 3
    assert cli.session_failure({"slave": -9, "master": 0}, ["slave"])[0] == 1
    assert cli.session_failure({"slave": 0, "master": 0}, ["master"]) == (0, [])
    # the master done, the slave failing when the session stopped it
    status, lines = cli.session_failure({"slave": -15, "master": 0}, ["master"])
    assert status == 1 and lines == [
        "haptic-session: slave exited with status -15 when the session stopped it"]


def test_a_refused_loop_exits_3_not_the_stopped_slaves_signal(tmp_path, monkeypatch,
                                                              capsys) -> None:
    """The docs' refusing configuration (k = 19 at a 21 ms round trip); the slave held in its
    start-up, so the session's SIGTERM finds it there (what a slow host does)."""
    real_popen = subprocess.Popen

    def popen(command: list[str], *args: Any, **kwargs: Any) -> subprocess.Popen:
        if "haptic.slave_sim.cli" in command:
            command = [sys.executable, "-c", "import time; time.sleep(60)"]
        return real_popen(command, *args, **kwargs)

    monkeypatch.setattr(cli.subprocess, "Popen", popen)
    assert cli.main(["--k", "19", "--one-way-delay", "0.01", "--out", str(tmp_path)]) == 3
    err = capsys.readouterr().err
    assert "haptic-session: master exited with status 3" in err
    assert "slave exited with status -15" not in err
