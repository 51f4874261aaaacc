"""Both programs recording a real run (``--record``) over Zenoh on loopback, then
``haptic-replay`` on the files: every channel with the right message counts, a SIGTERMed
program's file closed properly, the summary and the PNGs.

Children are ended by their own PIDs and always reaped; every wait is bounded."""

from __future__ import annotations

import json
import signal
import uuid
from pathlib import Path

import pytest

from haptic.common.records.recording import read_recording
from haptic.common.wire.ports import free_port
from haptic.view.replay import cli as replay
from tests.helpers.programs import Programs, python_module

WAIT_S = 60.0


@pytest.fixture(scope="module")
def recorded_run(tmp_path_factory: pytest.TempPathFactory):
    tmp_path = tmp_path_factory.mktemp("recorded")
    config = tmp_path / "clay.toml"
    config.write_text('[slave]\nscenario = "constant-rate"\nenvironment = "clay"\n'
                      'clay_impl = "numpy"\ndevice = "cpu"\n')
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    common = ["--config", str(config), "--key-prefix", f"test/{uuid.uuid4().hex[:8]}",
              "--no-status", "--peer-wait", "30"]
    files = {side: tmp_path / f"{side}.mcap" for side in ("master", "slave")}
    summaries = {side: tmp_path / f"{side}.json" for side in ("master", "slave")}
    with Programs() as programs:
        master = programs.start(python_module(
            "haptic.master.cli", *common, "--listen", endpoint, "--rig", "model", "--operator",
            "regulate:fx=3.6,onset=0.1,max=5", "--record", str(files["master"]),
            "--json-summary", str(summaries["master"])))
        slave = programs.start(python_module(
            "haptic.slave_sim.cli", *common, "--connect", endpoint, "--duration", "2.5",
            "--record", str(files["slave"]), "--record-every", "2", "--json-summary",
            str(summaries["slave"])))
        assert slave.wait(timeout_s=WAIT_S) == 0, slave.output()
        # the master runs until stopped
        assert master.stop(signal.SIGTERM, grace_s=WAIT_S) == 0, master.output()
    return files, {side: json.loads(path.read_text()) for side, path in summaries.items()}


def test_recorded_run_and_replay(recorded_run, tmp_path: Path, capsys) -> None:
    files, summaries = recorded_run
    for side, every in (("master", 1), ("slave", 2)):
        summary = summaries[side]
        recording = read_recording(files[side])
        assert recording.complete, side  # closed properly (duration end, SIGTERM)
        counts = recording.counts()
        steps = summary["steps"]
        assert counts[f"/{side}/state"] == (steps + every - 1) // every
        assert counts[f"/{side}/config"] == 1 and counts[f"/{side}/summary"] == 1
        assert counts[f"/{side}/link"] >= 1
        assert summary["record_dropped"] == 0
        assert summary["record_written"] == sum(counts.values())
        assert recording.last(f"/{side}/config")["model"] is not None
        assert recording.last(f"/{side}/summary")["steps"] == steps
        link = recording.last(f"/{side}/link")
        assert link["link_received"] > 0
        events = [m["kind"] for _, m in recording.messages[f"/{side}/events"]]
        assert "forces_enabled" in events
    master = read_recording(files["master"])
    assert master.last("/master/summary")["stop_reason"] == "SIGTERM"
    slave = read_recording(files["slave"])
    # the map at the start, at 2 Hz from the display thread, and at the end
    assert slave.counts()["/slave/workpiece"] == 1 and slave.counts()["/slave/clay"] >= 3
    first, last = (slave.messages["/slave/clay"][i][1]["heights_mm"] for i in (0, -1))
    assert sum(map(sum, last)) < sum(map(sum, first))  # the tool cut clay
    state = slave.columns("/slave/state")
    assert state["tool_position_x_m"][-1] > state["tool_position_x_m"][0]

    out = tmp_path / "plots"
    assert replay.main([str(files["slave"]), str(files["master"]), "--out", str(out),
                        "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    sides = [r["side"] for r in printed["recordings"]]
    assert sides == ["slave", "master"]
    assert printed["recordings"][0]["cut_mean_force_N"] > 0.0
    names = sorted(Path(p).name for p in printed["plots"])
    assert names == ["clay.png", "force_position.png", "force_time.png",
                     "velocity_position.png"]
    for name in names:
        assert (out / name).stat().st_size > 5000


def test_replay_into_the_view_state(recorded_run) -> None:
    from haptic.view.replay.playback import play
    from haptic.view.state import ViewState

    files, _ = recorded_run
    state = ViewState()
    frames = play([read_recording(files["slave"]), read_recording(files["master"])], state,
                  speed=5.0)
    assert frames > 10
    snapshot = state.snapshot()
    assert snapshot["tool"]["tool_position_m"][0] > 0.0
    assert snapshot["handle"]["handle_position_m"][0] is not None
    assert set(snapshot["status"]) == {"master", "slave"}
    assert snapshot["layout"]["block_names"] == ["clay"]
    assert state.clay_version >= 3 and snapshot["clay"]["header"]["cells_x"] > 0
