"""``haptic-master`` and ``haptic-slave`` in the lane-law modes (``[control] mode`` = wave,
four-channel, four-channel-tdpa, mmt) over real Zenoh links on loopback: each pair runs, the
tool follows the handle and they end aligned (gap <= 1 mm), forces stay bounded; a pair in
different modes is refused at start on both sides with one line; the watchdog stops the tool
when the master is killed; a law mode refuses the paper scheme's parts with exit status 2.
The master drives the rig model (the subject is the law over Zenoh, not the CAN path).
Children are ended by their own PIDs and reaped; nothing here asserts timing."""

from __future__ import annotations

import json
import signal
import subprocess
import time
import uuid
from pathlib import Path

import numpy as np
import pytest

from haptic.common.control.law_settings import LANE_CONTROLS
from haptic.common.wire.ports import free_port
from haptic.master.cli import main as master_main
from haptic.slave_sim.cli import main as slave_main
from tests.helpers.programs import Program, Programs, python_module

WAIT_S = 90.0
OPERATOR = "constant:fx=1.0,onset=0.05,rise=0.5"
#: A run long enough for the push to come to rest before the end (s), on a busy machine too:
#: a tool still moving trails the handle by its speed times the link's age, which an end gap
#: of 1 mm cannot hold (docs/measurements/two_process_tests.md).
SETTLED_S = 6.0


def _config(tmp_path: Path, mode: str, environment: str = "linear", extra: str = "") -> Path:
    path = tmp_path / f"{mode}.toml"
    path.write_text(f'[slave]\nscenario = "constant-rate"\nenvironment = "{environment}"\n'
                    f'clay_impl = "warp"\ndevice = "cpu"\n\n[control]\nmode = "{mode}"\n'
                    + extra)
    return path


def _pair_args(tmp_path: Path, master_mode: str, slave_mode: str, duration_s: float,
               environment: str = "linear", extra: str = "") -> tuple[list[str], list[str]]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    common = ["--key-prefix", f"test/{uuid.uuid4().hex[:8]}", "--no-status", "--peer-wait",
              "30"]
    slave = python_module(
        "haptic.slave_sim.cli", "--config", str(_config(tmp_path, slave_mode, environment,
                                                       extra)),
        *common, "--connect", endpoint, "--json-summary", str(tmp_path / "slave.json"),
        "--out", str(tmp_path / "slave_out"), "--duration", str(duration_s + 1.5))
    master = python_module(
        "haptic.master.cli", "--config", str(_config(tmp_path, master_mode, environment,
                                                     extra)),
        *common, "--listen", endpoint, "--rig", "model", "--operator", OPERATOR,
        "--json-summary", str(tmp_path / "master.json"), "--duration", str(duration_s))
    return slave, master


def _ended(program: Program, timeout_s: float) -> subprocess.CompletedProcess[str]:
    status = program.wait(timeout_s=timeout_s)
    return subprocess.CompletedProcess(program.args, status, program.output())


@pytest.mark.slow
@pytest.mark.parametrize("control", [law for law in LANE_CONTROLS
                                     if law not in ("wave", "four-channel-tdpa")])
def test_each_law_runs_both_programs_bounded_and_aligned(tmp_path, control) -> None:
    """(wave: the session in tests/common/launch/test_session.py runs its two programs on
    the emulated CAN rig and the clay, ending aligned; four-channel-tdpa: the tests below.)"""
    master_summary, slave_summary, trace = _run_pair(tmp_path, control, SETTLED_S)
    assert master_summary["tdpa_layer"] == slave_summary["tdpa_layer"] == "off"
    gap_m = _final_gap_m(trace)
    assert gap_m <= 0.001
    # and the master's final handle is where the slave's tool stopped, within the motion of
    # the watchdog's silence limit at the end (the peer's last message may come late)
    final = np.array(slave_summary["final_tool_position_m"])
    assert np.hypot(*(final - master_summary["final_handle_position_m"])) <= 0.003


def _run_pair(tmp_path: Path, control: str, duration_s: float, extra: str = ""
              ) -> tuple[dict, dict, dict[str, np.ndarray]]:
    """Both programs in ``control`` for ``duration_s`` (s), the operator pushing 1 N:
    (master's summary, slave's summary, slave's trace), after the checks every law passes
    (exit 0, the law's stages, forces bounded, the tool moved by the push)."""
    with Programs() as programs:
        started = [programs.start(args)
                   for args in _pair_args(tmp_path, control, control, duration_s, extra=extra)]
        slave, master = (_ended(program, WAIT_S) for program in started)
    assert master.returncode == 0, master.stdout
    assert slave.returncode == 0, slave.stdout
    master_summary = json.loads((tmp_path / "master.json").read_text())
    slave_summary = json.loads((tmp_path / "slave.json").read_text())
    assert master_summary["control"] == slave_summary["control"] == control
    assert not master_summary["node_faulted"]
    # the law's stages, one driver: the summary times each
    assert set(master_summary["stages"]) == {"read", "poll", "law", "write", "send",
                                             "telemetry"}
    assert set(slave_summary["stages"]) == {"poll", "law", "move", "send", "telemetry"}
    # bounded: the operator pushes 1 N; nothing near the force limits
    assert 0.1 < master_summary["max_abs_force_N"] < 5.0
    assert slave_summary["max_abs_force_N"] < 5.0
    trace = dict(np.load(tmp_path / "slave_out" / "slave_trace.npz"))
    assert np.all(np.isfinite(trace["tool_position_x_m"]))
    last = np.flatnonzero(trace["forces_enabled"] > 0.5)[-1]
    assert trace["tool_position_x_m"][last] > 0.005  # the push moved the tool
    return master_summary, slave_summary, trace


def _final_gap_m(trace: dict[str, np.ndarray]) -> float:
    """At the last sample with forces on: how far the tool is from the handle as its message
    carried it (these laws send the handle's position), m."""
    last = np.flatnonzero(trace["forces_enabled"] > 0.5)[-1]
    return float(np.hypot(trace["tool_position_x_m"][last] - trace["handle_position_x_m"][last],
                          trace["tool_position_y_m"][last] - trace["handle_position_y_m"][last]))


def _assert_passive(master: dict, slave: dict) -> None:
    """The passivity layer's contract, from both programs' summaries (J): the link delivered
    no energy the peer did not hand over; each account closes (what it holds is its input,
    less its output, plus what it received, less what it handed on or the cap forgot); and
    no side gave out more than it had but by a deficit the controller's caps left, under
    1 mJ."""
    for own, peer in ((master, slave), (slave, master)):
        assert own["tdpa_layer"] == "tdpa"
        assert own["tdpa_received_J"] <= peer["tdpa_sent_J"] + 1e-12
        assert own["tdpa_reserve_J"] == pytest.approx(
            own["tdpa_input_energy_J"] - own["tdpa_output_energy_J"] + own["tdpa_received_J"]
            - own["tdpa_sent_J"] - own["tdpa_forgotten_energy_J"], abs=1e-9)
        assert own["tdpa_reserve_J"] > -0.001


@pytest.mark.slow
def test_four_channel_tdpa_runs_both_programs_passive_and_reports_its_accounts(tmp_path
                                                                               ) -> None:
    """The shipped settings: the master keeps ``master_keep_J`` of the operator's input and
    hands on the rest, but the slave's environment (the paper's Tt, a damper) takes about all
    of it, so the slave's account runs short and its layer yields through the push. The
    yield is not corrected (docs/architectures.md), and how much of it is left at the end
    depends on the link's timing, so this test asserts the layer's contract and its accounts,
    not the end gap."""
    master_summary, slave_summary, trace = _run_pair(tmp_path, "four-channel-tdpa", 3.0)
    master, slave = master_summary, slave_summary
    _assert_passive(master, slave)
    assert master["tdpa_input_energy_J"] > 0.01  # the push worked on the handle
    # the master handed on all of its own input but what it keeps (master_keep_J, 2 mJ)
    assert master["tdpa_reserve_J"] <= 0.002 + master["tdpa_received_J"] + 1e-9
    # the slave's layer acted and dissipated what it was short of
    assert slave["tdpa_active_steps"] > 0 and slave["tdpa_dissipated_energy_J"] > 0.0
    assert np.isfinite(_final_gap_m(trace))


@pytest.mark.slow
def test_four_channel_tdpa_that_keeps_nothing_back_ends_aligned(tmp_path) -> None:
    """``master_keep_J = 0``: the master hands on all of the operator's input, the slave is
    no longer short of what its environment takes, its layer hardly acts, and the sides end
    within 1 mm, as the plain four-channel law's do."""
    master_summary, slave_summary, trace = _run_pair(tmp_path, "four-channel-tdpa", SETTLED_S,
                                                     extra="master_keep_J = 0.0\n")
    master, slave = master_summary, slave_summary
    _assert_passive(master, slave)
    assert master["tdpa_reserve_J"] <= master["tdpa_received_J"] + 1e-9
    assert slave["tdpa_dissipated_energy_J"] < 0.1 * master["tdpa_input_energy_J"]
    assert _final_gap_m(trace) <= 0.001


@pytest.mark.slow
@pytest.mark.parametrize(("master_mode", "slave_mode"), [("tdpa", "mmt")])
def test_a_pair_in_different_modes_is_refused_on_both_sides(tmp_path, master_mode,
                                                            slave_mode) -> None:
    """The programs' side of the pairing's check (a law against the programs' family the
    other way round, and two laws, over the link alone: tests/common/wire/
    test_hello_control.py)."""
    with Programs() as programs:
        started = [programs.start(args) for args in _pair_args(
            tmp_path, master_mode, slave_mode, 3.0)]
        slave, master = (_ended(program, WAIT_S) for program in started)
    for run, own, peer in ((master, master_mode, slave_mode), (slave, slave_mode, master_mode)):
        assert run.returncode == 4, run.stdout
        error = [line for line in run.stdout.splitlines() if "link error" in line]
        assert len(error) == 1, run.stdout
        assert f'"{own}"' in error[0] or own in ("paper", "tdpa"), error[0]
        assert "set the same [control] mode on both sides" in error[0]
        if peer not in ("paper", "tdpa"):
            assert f'mode = "{peer}"' in error[0]
    assert not (tmp_path / "master.json").exists()


@pytest.mark.slow
def test_the_slave_holds_its_tool_when_the_master_dies(tmp_path) -> None:
    slave_args, master_args = _pair_args(tmp_path, "wave", "wave", 30.0, environment="clay")
    with Programs() as programs:
        slave = programs.start(slave_args)
        master = programs.start(master_args)
        master.wait_for("waiting for the slave", WAIT_S)
        slave.wait_for("waiting for the master", WAIT_S)
        # let the push move the tool, then kill the master without its stopping message
        time.sleep(4.0)
        master.send_signal(signal.SIGKILL)
        master.wait(timeout_s=WAIT_S)
        time.sleep(2.0)  # the slave's watchdog trips on the silence, then holds
        slave.stop(signal.SIGINT)
    summary = json.loads((tmp_path / "slave.json").read_text())
    assert summary["watchdog_trips"] >= 1
    trip_s = min(event["time_s"] for event in summary["events"] if event["kind"] == "trip")
    trace = np.load(tmp_path / "slave_out" / "slave_trace.npz")
    after = trace["time_s"] > trip_s + 0.05
    assert after.sum() > 10
    assert not trace["forces_enabled"][after].any()
    moved = np.ptp(trace["tool_position_x_m"][after])
    assert moved < 2e-4  # the servo holds the tool where forces went off


@pytest.mark.parametrize(("extra", "key"), [
    ('\n[governor]\nenabled = true\n', "governor.enabled"),
    ('\n[model]\nposition_ratio_ah1 = [[2.0, 0.0], [0.0, 2.0]]\n', "model.position_ratio_ah1"),
])
def test_a_law_mode_refuses_the_paper_schemes_parts(tmp_path, capsys, extra, key) -> None:
    config = _config(tmp_path, "wave", extra=extra)
    for main in (master_main, slave_main):
        with pytest.raises(SystemExit) as exited:
            main(["--config", str(config), "--duration", "1", "--no-status",
                  "--peer-wait", "1"])
        assert exited.value.code == 2
        lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
        assert len(lines) == 1 and key in lines[0], lines


def test_an_unknown_mode_is_a_one_line_configuration_error(tmp_path, capsys) -> None:
    with pytest.raises(SystemExit) as exited:
        master_main(["--config", str(_config(tmp_path, "waves")), "--duration", "1"])
    assert exited.value.code == 2
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(lines) == 1 and "control.mode" in lines[0] and "wave" in lines[0], lines
