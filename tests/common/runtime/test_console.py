"""The console scripts that print a lot end quietly when the reader of their output has gone
(``haptic-replay --json FILE | head``): the exit status a shell gives a process ended by
SIGPIPE, and no traceback."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from haptic.common.records.recorder import McapRecorder
from haptic.common.runtime.console import (
    BROKEN_PIPE_EXIT_STATUS,
    quiet_on_closed_stdout,
    script_description,
)


def test_a_broken_pipe_is_an_exit_status_not_a_traceback() -> None:
    @quiet_on_closed_stdout
    def main(argv: list[str]) -> int:
        raise BrokenPipeError(32, "Broken pipe")

    assert main([]) == BROKEN_PIPE_EXIT_STATUS == 141
    assert quiet_on_closed_stdout(lambda: 5)() == 5


def test_a_description_is_whole_sentences_without_markup() -> None:
    doc = """``haptic-x [--port N]``: the thing that does ``y``,
    with `z`.

    More."""
    assert script_description(doc) == "The thing that does y, with z."


def _recording(path: Path) -> Path:
    with McapRecorder(path, "slave") as recorder:
        recorder.add_channel("/slave/state", ("time_s", "tool_force_x_N"))
        for i in range(10):
            recorder.record("/slave/state", 10**9 + i * 540_000, (i * 0.00054, 1.0))
    return path


@pytest.mark.parametrize("command", [
    ["haptic.view.replay.cli", "--json", "--no-plots", "RECORDING"],
    ["haptic.common.analysis.cli", "--json"],
    ["haptic.lockstep.cli", "sweep", "--gains", "3", "--delays", "0", "--duration", "1",
     "--json"],
])
def test_a_closed_stdout_ends_the_program_quietly(command: list[str], tmp_path: Path) -> None:
    argv = [str(_recording(tmp_path / "slave.mcap")) if part == "RECORDING" else part
            for part in command]
    process = subprocess.Popen([sys.executable, "-m", *argv], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    process.stdout.close()  # the reader is gone before the program writes
    _, err = process.communicate(timeout=120)
    assert "Traceback" not in err and "BrokenPipeError" not in err, err
    assert process.returncode == BROKEN_PIPE_EXIT_STATUS, err
