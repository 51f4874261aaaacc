"""Recordings readable after a crash by the standard tools (issue 17): a SIGKILLed recorder's
file opens with the ``mcap`` package's own ``make_reader(...).iter_messages()`` up to its last
complete chunk, between any two of its writes, and a closed file still has its summary.

A reader that races the writer can see two versions of the file at once: it reads in
pieces, and a chunk written over the provisional trailer between two of its reads gives it the
old trailer's start and the new chunk's middle (a CI run read such a file:
``RecordLengthLimitExceeded``; beside two CPU hogs about one live read in three does here,
where 4 KiB chunks go out every few ms). The live reads here retry that case and must find
the file whole on a retry."""

from __future__ import annotations

import json
import shutil
import signal
import struct
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from mcap.exceptions import McapError
from mcap.reader import make_reader

from haptic.common.records.recorder import McapRecorder
from haptic.common.records.recording import read_recording
from tests.helpers.programs import Program

WRITER = textwrap.dedent("""
    import sys, time
    from haptic.common.records.recorder import McapRecorder
    recorder = McapRecorder(sys.argv[1], "master", chunk_size=4096).open()
    recorder.add_channel("/master/state", ("time_s", "handle_force_x_N"))
    i = 0
    while True:
        recorder.record("/master/state", time.time_ns(), (i * 1e-3, 1.0))
        i += 1
        if i % 100 == 0:
            time.sleep(0.002)
""")


def _standard_read(path: Path) -> list[float]:
    with open(path, "rb") as stream:
        return [json.loads(message.data)["time_s"]
                for _, _, message in make_reader(stream).iter_messages(log_time_order=False)]


def _live_read(path: Path, torn_reads: list[str]) -> int:
    """Messages a standard reader finds in a file being written, retried while a write
    lands during its read (each such read's error appended to ``torn_reads``)."""
    for _ in range(20):
        try:
            return len(_standard_read(path))
        except (McapError, struct.error) as error:
            torn_reads.append(type(error).__name__)
            time.sleep(0.002)
    raise AssertionError(f"20 reads in a row raced a write: {torn_reads[-20:]}")


def test_sigkilled_recording_opens_with_make_reader(tmp_path: Path) -> None:
    path = tmp_path / "killed.mcap"
    live_reads: list[int] = []
    torn_reads: list[str] = []
    with Program([sys.executable, "-c", WRITER, str(path)]) as writer:
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline:
            if path.exists() and path.stat().st_size > 2_000:
                live_reads.append(_live_read(path, torn_reads))  # readable while it is written
            if path.exists() and path.stat().st_size > 40_000:
                break
            time.sleep(0.05)
        writer.stop(signal.SIGKILL)
    values = _standard_read(path)
    assert len(values) > 100
    # every message up to the last complete chunk, in order, none missing
    assert values[:3] == [0.0, 0.001, 0.002]
    assert all(abs(b - a - 1e-3) < 1e-9 for a, b in zip(values, values[1:], strict=False))
    assert live_reads and live_reads == sorted(live_reads)
    recording = read_recording(path)
    assert not recording.complete and recording.counts()["/master/state"] == len(values)
    _doctor_finds_no_error(path, len(values))


def _doctor_finds_no_error(path: Path, messages: int) -> None:
    """``pymcap-cli doctor`` (PyPI's MCAP command line with a ``doctor``; the Go ``mcap`` CLI
    is not on the package registries) checks the file against the MCAP container
    specification: no error, no warning (a killed file has no summary: info only)."""
    doctor = shutil.which("pymcap-cli") or str(Path(sys.executable).with_name("pymcap-cli"))
    if not Path(doctor).exists():
        pytest.skip("pymcap-cli is not installed (the [test] extra installs it)")
    result = subprocess.run([doctor, "doctor", "--format", "jsonl", str(path)],
                            capture_output=True, text=True, timeout=120)
    lines = [json.loads(line) for line in result.stdout.splitlines() if line.startswith("{")]
    summary = next(line for line in lines if line["type"] == "summary")
    problems = [line for line in lines if line.get("severity") in ("error", "warning")]
    assert result.returncode == 0 and not problems, problems
    assert summary["errors"] == 0 and summary["warnings"] == 0
    assert summary["messages"] >= messages


def test_closed_recording_keeps_its_summary_and_no_provisional_footer(tmp_path: Path) -> None:
    path = tmp_path / "closed.mcap"
    with McapRecorder(path, "slave", chunk_size=1024) as recorder:
        recorder.add_channel("/slave/state", ("time_s",))
        for i in range(2000):
            recorder.record("/slave/state", 1_000 + i, (i * 1e-3,))
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None and len(summary.chunk_indexes) > 1
        assert sum(1 for _ in reader.iter_messages()) == 2000
    recording = read_recording(path)
    assert recording.complete and recording.metadata["recorder"]["written"] == "2000"
