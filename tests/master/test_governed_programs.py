"""The margin governor over a real Zenoh link: haptic-master and haptic-slave as two
processes, k = 13, the tool's messages delayed 2 ms and then, from 1.5 s, 40 ms one way (a
round trip of about 42 ms, three times tau*(13) = 14.3 ms). The governor lowers k on both
sides and the run stays bounded. Behaviour is asserted, not timing."""

from __future__ import annotations

import json
import subprocess
import sys
import uuid
from pathlib import Path

import pytest

WAIT_S = 60.0


def _free_port() -> int:
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


CONFIG = """
[slave]
scenario = "constant-rate"
environment = "linear"
clay_impl = "numpy"
device = "cpu"

[link.watchdog]
max_message_age_s = 0.3     # the step leaves a 38 ms silence; the watchdog is not the test

[link.master.injection]
delay_profile = "step 0:0.002 1.5:0.040"

[link.slave.injection]
delay_s = 0.002

[governor]
enabled = true
recover_after_s = 0.0
"""


@pytest.fixture
def processes():
    started: list[subprocess.Popen] = []
    try:
        yield started
    finally:
        for process in started:  # each by its own PID, always reaped
            if process.poll() is None:
                process.kill()
            process.wait()
            if process.stdout is not None:
                process.stdout.close()


def _start(processes: list, args: list[str]) -> subprocess.Popen:
    process = subprocess.Popen([sys.executable, "-m", *args], stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True)
    processes.append(process)
    return process


def test_a_delay_step_lowers_k_on_both_sides_and_the_run_stays_bounded(tmp_path: Path,
                                                                        processes) -> None:
    config = tmp_path / "governed.toml"
    config.write_text(CONFIG)
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    common = ["--config", str(config), "--key-prefix", f"test/{uuid.uuid4().hex[:8]}",
              "--no-status", "--peer-wait", "40", "--k", "13"]
    master_json, slave_json = tmp_path / "master.json", tmp_path / "slave.json"
    slave = _start(processes, ["haptic.slave_sim.cli", *common, "--connect", endpoint,
                               "--json-summary", str(slave_json), "--duration", "30"])
    master = _start(processes, ["haptic.master.cli", *common, "--listen", endpoint, "--rig",
                                "model", "--operator", "constant:fx=1.0,onset=0.05",
                                "--json-summary", str(master_json), "--duration", "4"])
    out, _ = master.communicate(timeout=WAIT_S)
    assert master.returncode == 0, out
    assert "governor (lower_k" in out and "k 13: 14.3 ms" in out
    slave.terminate()
    slave_out, _ = slave.communicate(timeout=WAIT_S)
    summary = json.loads(master_json.read_text())
    assert summary["governor_nominal_k"] == 13.0
    lowest = summary["governor_table"]["k"][-1]
    assert summary["governor_table"]["delay_margin_s"][-1] is None  # any delay
    assert summary["governor_final_k"] == pytest.approx(lowest)
    assert summary["governor_max_round_trip_s"] > 0.040  # the step was measured
    kinds = [event["kind"] for event in summary["events"]]
    assert "governor_lower_k" in kinds and "governor_beyond_margin" not in kinds
    assert not summary["node_faulted"]
    assert summary["max_abs_force_N"] < 10.0  # bounded: the operator's 1 N, no growth
    slave_summary = json.loads(slave_json.read_text())
    assert slave_summary["slave_gain_k"] == pytest.approx(lowest)  # the slave followed
