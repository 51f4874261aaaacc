"""``haptic-master`` and the ``[master]`` configuration."""

from __future__ import annotations

import json
import uuid

import pytest

from haptic.common.config import ConfigError, load_config, override
from haptic.master.cli import main


def test_shipped_master_section_loads() -> None:
    config = load_config()
    master = config["master"]
    assert master["rig"] == "sim"
    assert master["can"]["x_node_id"] != master["can"]["y_node_id"]
    assert set(master) == {"rig", "can", "sim", "safety", "tool_input"}


@pytest.mark.parametrize(("key", "value"), [
    ("master.rig", "simulated"),
    ("master.sim.operator", "constant:fq=1"),
    ("master.can.force_scale_N_per_count", [0.01]),
    ("master.can.x_node_id", 128),
    ("master.safety.ramp_small_samples", 0),
    ("master.tool_input.clear_after_messages", 0),
    ("master.can.sync_counter_overflow", 1),
])
def test_bad_master_values_name_their_key(key: str, value: object) -> None:
    with pytest.raises(ConfigError) as caught:
        override(load_config(), key, value)
    assert caught.value.key == key


def test_unknown_key_in_a_master_table_is_refused(tmp_path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text('[master]\nrig = "sim"\nspeed = 3\n')
    with pytest.raises(ConfigError) as caught:
        load_config(path)
    assert caught.value.key == "master.speed"


def _sim_config(tmp_path) -> str:
    path = tmp_path / "sim.toml"
    path.write_text(
        "[master]\nrig = \"sim\"\n[master.sim]\n"
        f'channel = "cli-{uuid.uuid4().hex}"\n'
        "pdo_timeout_s = 0.5\n"
        'operator = "constant:fx=1,fy=0,onset=0.02"\n'
        "force_noise_std_N = 0.0\nseed = 0\ninitial_position_m = [0.0, 0.0]\n"
        # the master runs in the test process: a pause of it (a gen-2 collection of a long
        # session's heap) beyond the shipped 0.3 s heartbeat consumer time faults the emulated
        # drives with EMCY 0x8130 (test_rig_emulator.py's _config)
        "[master.can]\nheartbeat_timeout_s = 5.0\n"
    )
    return str(path)


def test_cli_runs_the_node_on_the_simulated_rig(tmp_path, capsys) -> None:
    status = main(["--config", _sim_config(tmp_path), "--rig", "sim", "--duration", "0.1",
                   "--no-pace", "--json", "--no-link"])
    printed = capsys.readouterr()
    assert status == 0, printed.err  # a hardware error prints one line there, no JSON
    result = json.loads(printed.out)
    assert result["rig"] == "sim" and result["cycles"] == 185
    assert result["final_position_m"][0] > 0.0
    assert result["events"][0]["kind"] == "enable"
    assert not result["safe_state"]


def test_cli_config_errors_exit_2_with_one_line(capsys) -> None:
    with pytest.raises(SystemExit) as caught:
        main(["--operator", "wiggle", "--duration", "0.1"])
    assert caught.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "master.sim.operator" in err[0]
    with pytest.raises(SystemExit) as caught:
        main(["--duration", "-1"])
    assert caught.value.code == 2


def test_cli_reports_a_can_bus_that_cannot_open(capsys) -> None:
    # The default CAN interface (socketcan can0) does not exist on a test machine.
    status = main(["--rig", "can", "--duration", "0.01"])
    assert status == 1
    assert "hardware error" in capsys.readouterr().err


def test_master_alone_flags_are_refused_in_the_linked_run(capsys) -> None:
    with pytest.raises(SystemExit) as caught:
        main(["--no-pace", "--duration", "0.1"])
    assert caught.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--no-pace" in err[0] and "--no-link" in err[0]


@pytest.mark.parametrize("argv, words", [
    (["--rig", "can", "--rig-time", "1"], ("--rig-time", "simulated rig", "--duration")),
    (["--rig", "model", "--rig-time", "nan"], ("--rig-time", "> 0")),
    (["--rig", "model", "--rig-time", "0"], ("--rig-time", "> 0")),
    (["--no-link", "--rig-time", "1"], ("--rig-time", "--no-link")),
])
def test_rig_time_is_refused_where_the_rig_has_no_time_of_its_own(argv, words, capsys) -> None:
    """``--rig-time`` steps a simulated rig's time; a real rig runs on the wall clock."""
    with pytest.raises(SystemExit) as caught:
        main(argv)
    assert caught.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and all(word in err[0] for word in words), err


def test_rig_time_counts_ticks_of_the_period() -> None:
    from haptic.master.cli import rig_time_steps

    assert rig_time_steps(4.0, "sim", 0.00054) == 7407
    assert rig_time_steps(1e-9, "model", 0.00054) == 1
