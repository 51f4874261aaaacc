"""Clean failures (issue 17): an undecodable config file, a port in use, an unreachable router
and a file that is not MCAP each end in one line and the documented exit status."""

from __future__ import annotations

import os
import subprocess
import sys
import uuid

import pytest

from haptic.common.config import CONFIG_ERROR_EXIT_STATUS
from haptic.common.runtime.failures import LINK_ERROR_EXIT_STATUS
from haptic.common.wire.errors import LinkOpenError, one_line
from haptic.common.wire.link import Link
from haptic.common.wire.link_config import LinkConfig
from haptic.common.wire.ports import free_port

BINARY = bytes(range(256)) * 8


@pytest.fixture()
def binary_file(tmp_path):
    path = tmp_path / "config.toml"
    path.write_bytes(b"\x8a\xff\x00" + BINARY)
    return path


def _program_mains():
    from haptic.common.analysis import cli as analyze_cli
    from haptic.lockstep import cli as lockstep_cli
    from haptic.master import cli as master_cli
    from haptic.master.simulated_rig import cli as rig_sim_cli
    from haptic.slave_sim import cli as slave_cli
    from haptic.slave_sim.scenario import cli as run_scenario
    from haptic.view import cli as view_cli

    return {
        "haptic-master": (master_cli.main, []),
        "haptic-master --no-link": (master_cli.main, ["--no-link"]),
        "haptic-slave": (slave_cli.main, []),
        "haptic-analyze": (analyze_cli.main, []),
        "haptic-slave-sim": (run_scenario.main, []),
        "haptic-view": (view_cli.main, []),
        "haptic-rig-sim": (rig_sim_cli.main, []),
        "haptic-sim run": (lockstep_cli.main, None),
    }


@pytest.mark.parametrize("program", list(_program_mains()))
def test_binary_config_is_one_line_and_exit_2(program, binary_file, capsys):
    main, extra = _program_mains()[program]
    argv = (["--config", str(binary_file), "run"] if extra is None
            else ["--config", str(binary_file), *extra])
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == CONFIG_ERROR_EXIT_STATUS
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert "not UTF-8 text" in err[0] and str(binary_file) in err[0]


def test_binary_scenario_file_is_a_config_error(tmp_path):
    from haptic.common.config import ConfigError
    from haptic.common.config.scenario import load_scenario

    path = tmp_path / "scenario.toml"
    path.write_bytes(BINARY)
    with pytest.raises(ConfigError, match="not UTF-8 text"):
        load_scenario(str(path))


def test_replay_refuses_a_file_that_is_not_mcap(tmp_path, capsys):
    from haptic.view.replay.cli import main

    for name, data in (("junk.mcap", BINARY), ("text.mcap", b"hello"), ("empty.mcap", b"")):
        path = tmp_path / name
        path.write_bytes(data)
        assert main(["--no-plots", str(path)]) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "not an MCAP recording" in err[0], err


def test_link_on_a_port_in_use_raises_one_line():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    prefix = f"test/{uuid.uuid4().hex[:10]}"
    first = LinkConfig(side="master", key_prefix=prefix, listen=(endpoint,))
    with Link(first):
        with pytest.raises(LinkOpenError) as error_info:
            Link(LinkConfig(side="slave", key_prefix=prefix, listen=(endpoint,))).open()
    message = str(error_info.value)
    assert "\n" not in message and "Address already in use" in message
    assert ".rs:" not in message  # no Rust source positions


def test_link_client_without_router_raises_one_line():
    config = LinkConfig(side="master", key_prefix="test/x", mode="client",
                        connect=(f"tcp/127.0.0.1:{free_port()}",))
    with pytest.raises(LinkOpenError, match="Unable to connect"):
        Link(config).open()


def test_one_line_strips_rust_positions():
    text = "bound to tcp/x: [a: in use (os error 98) at /r/tcp.rs:61.]\n at /r/unicast.rs:338."
    assert one_line(text) == "bound to tcp/x: [a: in use (os error 98)]"


@pytest.mark.slow
@pytest.mark.parametrize("program", ["haptic-master", "haptic-slave"])
def test_program_on_a_port_in_use_exits_4_with_one_line(program):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    prefix = f"test/{uuid.uuid4().hex[:10]}"
    rig = ["--rig", "model"] if program == "haptic-master" else []
    with Link(LinkConfig(side="master", key_prefix=prefix, listen=(endpoint,))):
        module = {"haptic-master": "haptic.master.cli",
                  "haptic-slave": "haptic.slave_sim.cli"}[program]
        done = subprocess.run(
            [sys.executable, "-m", module, *rig, "--listen", endpoint, "--key-prefix", prefix,
             "--peer-wait", "1", "--duration", "1"],
            capture_output=True, text=True, timeout=120,
            env={**os.environ, "PYTHONWARNINGS": "ignore"},
        )
    assert done.returncode == LINK_ERROR_EXIT_STATUS, done.stderr
    errors = [line for line in done.stderr.splitlines() if "link error" in line]
    assert len(errors) == 1 and "Address already in use" in errors[0]
    assert "Traceback" not in done.stderr
