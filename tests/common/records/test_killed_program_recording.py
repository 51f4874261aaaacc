"""The issue's row: ``haptic-master`` SIGKILLed while recording. Its file opens with the
``mcap`` package's standard reader (``make_reader(...).iter_messages()``) up to its last
complete chunk, and ``haptic-replay`` reads it as cut short."""

from __future__ import annotations

import json
import signal
import time
import uuid
from pathlib import Path

import pytest
from mcap.reader import make_reader

from haptic.common.records.recording import read_recording
from haptic.common.wire.ports import free_port
from tests.helpers.programs import Programs, python_module

WAIT_S = 60.0


@pytest.mark.slow
def test_sigkilled_master_recording_opens_with_make_reader(tmp_path: Path) -> None:
    config = tmp_path / "linear.toml"
    config.write_text('[slave]\nscenario = "constant-rate"\nenvironment = "linear"\n'
                      'clay_impl = "numpy"\ndevice = "cpu"\n')
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    common = ["--config", str(config), "--key-prefix", f"test/{uuid.uuid4().hex[:8]}",
              "--no-status", "--peer-wait", "30"]
    record = tmp_path / "master.mcap"
    with Programs() as programs:
        master = programs.start(python_module(
            "haptic.master.cli", *common, "--listen", endpoint, "--rig", "model", "--record",
            str(record)))
        slave = programs.start(python_module(
            "haptic.slave_sim.cli", *common, "--connect", endpoint, "--duration", "30"))
        deadline = time.monotonic() + WAIT_S
        while time.monotonic() < deadline:
            if record.exists() and record.stat().st_size > 60_000:
                break
            assert master.running() and slave.running()
            time.sleep(0.1)
        master.stop(signal.SIGKILL)
    with open(record, "rb") as stream:
        messages = [(channel.topic, message) for _, channel, message
                    in make_reader(stream).iter_messages(log_time_order=False)]
    states = [json.loads(m.data) for topic, m in messages if topic == "/master/state"]
    assert len(states) > 100
    times = [s["time_s"] for s in states]
    assert times == sorted(times)
    assert any(topic == "/master/config" for topic, _ in messages)
    recording = read_recording(record)
    assert not recording.complete
    assert recording.counts()["/master/state"] == len(states)
