"""The margin governor over a real Zenoh link: haptic-master and haptic-slave as two
processes, k = 13, the tool's messages delayed 2 ms and then, from 1.5 s, 40 ms one way (a
round trip of about 42 ms, three times tau*(13) = 14.3 ms). The governor lowers k on both
sides (``lower_k``), or switches the passivity layer on at both sides (``tdpa``), and the run
stays bounded. Behaviour is asserted, not timing."""

from __future__ import annotations

import json
import re
import signal
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

from haptic.common.wire.ports import free_port
from tests.helpers.programs import Programs, python_module

WAIT_S = 60.0
#: When the tool's delay steps from 2 to 40 ms one way, s (CONFIG's delay_profile).
STEP_AT_S = 1.5


CONFIG = f"""
[slave]
scenario = "constant-rate"
environment = "linear"
clay_impl = "numpy"
device = "cpu"

[link.watchdog]
max_message_age_s = 0.3     # the step leaves a 38 ms silence; the watchdog is not the test

[link.master.injection]
delay_profile = "step 0:0.002 {STEP_AT_S}:0.040"

[link.slave.injection]
delay_s = 0.002

[governor]
enabled = true
recover_after_s = 0.0
"""


@pytest.fixture
def programs() -> Iterator[Programs]:
    with Programs() as started:
        yield started


def _governed_run(tmp_path: Path, programs: Programs, extra_config: str = ""
                  ) -> tuple[str, dict, dict]:
    """The two programs over the step; returns the master's output and both summaries."""
    config = tmp_path / "governed.toml"
    config.write_text(CONFIG + extra_config)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    common = ["--config", str(config), "--key-prefix", f"test/{uuid.uuid4().hex[:8]}",
              "--no-status", "--peer-wait", "40", "--k", "13"]
    master_json, slave_json = tmp_path / "master.json", tmp_path / "slave.json"
    slave = programs.start(python_module(
        "haptic.slave_sim.cli", *common, "--connect", endpoint, "--json-summary",
        str(slave_json), "--duration", "30"))
    master = programs.start(python_module(
        "haptic.master.cli", *common, "--listen", endpoint, "--rig", "model", "--operator",
        "constant:fx=1.0,onset=0.05", "--json-summary", str(master_json), "--duration", "4"))
    assert master.wait(timeout_s=WAIT_S) == 0, master.output()
    slave.stop(signal.SIGTERM, grace_s=WAIT_S)
    return master.output(), json.loads(master_json.read_text()), json.loads(
        slave_json.read_text())


def test_a_delay_step_lowers_k_on_both_sides_and_the_run_stays_bounded(tmp_path: Path,
                                                                        programs) -> None:
    out, summary, slave_summary = _governed_run(tmp_path, programs)
    assert "governor (lower_k" in out and "k 13: 14.3 ms" in out
    assert summary["governor_nominal_k"] == 13.0
    lowest = summary["governor_table"]["k"][-1]
    assert summary["governor_table"]["delay_margin_s"][-1] is None  # any delay
    assert summary["governor_final_k"] == pytest.approx(lowest)
    assert summary["governor_max_round_trip_s"] > 0.040  # the step was measured
    kinds = [event["kind"] for event in summary["events"]]
    assert "governor_lower_k" in kinds and "governor_beyond_margin" not in kinds
    assert not summary["node_faulted"]
    assert summary["max_abs_force_N"] < 10.0  # bounded: the operator's 1 N, no growth
    assert summary["tdpa_layer"] == "off" and not summary["tdpa_active"]
    assert slave_summary["slave_gain_k"] == pytest.approx(lowest)  # the slave followed
    assert slave_summary["tdpa_layer"] == "standby" and not slave_summary["tdpa_active"]
    assert max(abs(v) for v in slave_summary["final_position_gap_m"]) < 3e-3


def test_a_delay_step_switches_the_passivity_layer_on_at_both_sides(tmp_path: Path,
                                                                    programs) -> None:
    """``action = "tdpa"`` in paper mode: the master's layer waits on standby, the step
    switches it on (TDPA_SWITCHED on the wire), the slave's follows; k stays 13."""
    out, summary, slave_summary = _governed_run(tmp_path, programs, "action = \"tdpa\"\n")
    assert "governor (tdpa" in out
    assert summary["governor_final_k"] == 13.0 and summary["governor_min_k"] == 13.0
    assert summary["governor_tdpa_requested"] and summary["governor_max_round_trip_s"] > 0.040
    kinds = [event["kind"] for event in summary["events"]]
    assert "governor_tdpa_request" in kinds and "tdpa_on" in kinds
    assert "governor_lower_k" not in kinds and "governor_beyond_margin" not in kinds
    # switched when the measured round trip passed 0.9 tau*(13), or 0.7 tau* for confirm_s: at
    # the step, or earlier on a loaded machine (the echo then says so); never without cause
    request = next(e for e in summary["events"] if e["kind"] == "governor_tdpa_request")
    measured_ms = float(re.search(r"round trip ([0-9.]+) ms", request["reason"]).group(1))
    assert measured_ms > 0.7 * 14.3
    on = next(e for e in summary["events"] if e["kind"] == "tdpa_on")
    assert on["time_s"] == pytest.approx(request["time_s"], abs=0.01)
    assert summary["tdpa_layer"] == "standby" and summary["tdpa_active"]
    assert not summary["node_faulted"]
    assert summary["max_abs_force_N"] < 10.0  # bounded: the operator's 1 N, no growth
    assert slave_summary["slave_gain_k"] == pytest.approx(13.0)
    assert slave_summary["tdpa_layer"] == "standby" and slave_summary["tdpa_active"]
    slave_kinds = [event["kind"] for event in slave_summary["events"]]
    assert slave_kinds.count("tdpa_on") == 1
    # the layer observed the push from the switch on, and nothing crossed twice
    assert summary["tdpa_input_energy_J"] > 0.0
    assert slave_summary["tdpa_received_J"] <= summary["tdpa_sent_J"]
    assert summary["tdpa_received_J"] <= slave_summary["tdpa_sent_J"]
    # The slave's event says how far apart the sides were when its layer went on. Where they
    # end is not asserted here: under a sustained push beyond the margin the layer trades
    # alignment for passivity, by how much depends on the timing of the machine the two
    # programs share (quiet: about 1.2 mm, the approach's offset, which the switch at rest
    # keeps; beside two CPU hogs, at the step 2.4-4.7 mm, switched on earlier -16 to +3 mm;
    # docs/control.md section 2). The lockstep pins that physics deterministically
    # (tests/lockstep/test_governed.py: the switch at rest keeps the offset).
    switched = next(e for e in slave_summary["events"] if e["kind"] == "tdpa_on")
    assert len(switched["position_gap_m"]) == 2 and "mm apart" in switched["reason"]
