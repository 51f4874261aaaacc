"""The shared command-line helper and the [link] configuration."""

from __future__ import annotations

import argparse

import pytest

from haptic.common.config import ConfigError, exit_on_config_error, load_config
from haptic.common.runtime.cli_options import add_run_options, run_options_from_args
from haptic.common.wire.link_config import LinkConfig, link_config_from


def parse(argv: list[str], side: str = "slave", config_file=None):
    parser = argparse.ArgumentParser()
    add_run_options(parser)
    if config_file is not None:
        argv = ["--config", str(config_file), *argv]
    return run_options_from_args(parser.parse_args(argv), side)


def test_defaults_master_listens_slave_connects():
    master = parse([], "master").link
    slave = parse([], "slave").link
    assert master.listen == ("tcp/127.0.0.1:7447",) and master.connect == ()
    assert slave.connect == ("tcp/127.0.0.1:7447",) and slave.listen == ()
    assert master.publish_key == "haptic/rig-1/handle" == slave.subscribe_key
    assert slave.publish_key == "haptic/rig-1/tool" == master.subscribe_key
    assert master.liveliness_key("slave") == "haptic/rig-1/alive/slave"
    assert not master.injection.active


def test_flags_override_config_for_this_side_only():
    options = parse([
        "--one-way-delay", "0.02", "--jitter", "0.005", "--jitter-distribution", "normal",
        "--loss", "0.1", "--burst-enter", "0.01", "--burst-exit", "0.2",
        "--connect", "tcp/10.0.0.1:7447", "--connect", "tcp/10.0.0.2:7447",
        "--key-prefix", "haptic/lab-3", "--duration", "5", "--json-summary", "out.json",
        "--zenoh-set", "transport/link/tx/lease=2000", "--max-message-age", "0.05",
        "--insecure",  # LAN addresses without a key (tests/common/wire/test_protected_mode.py)
    ])
    link = options.link
    assert link.injection.delay_s == 0.02 and link.injection.jitter_s == 0.005
    assert link.injection.jitter_distribution == "normal"
    assert link.injection.loss_probability == 0.1
    assert link.injection.burst_enter_probability == 0.01
    assert link.connect == ("tcp/10.0.0.1:7447", "tcp/10.0.0.2:7447")
    assert link.key_prefix == "haptic/lab-3"
    assert link.max_message_age_s == 0.05
    assert options.duration_s == 5.0 and str(options.json_summary) == "out.json"
    assert ("transport/link/tx/lease", "2000") == link.zenoh_settings()[-1]
    # the other side's injection is untouched
    assert options.config["link"]["master"]["injection"]["delay_s"] == 0.0


def test_client_mode_connects_to_the_router_only():
    link = parse(["--mode", "client", "--connect", "tcp/127.0.0.1:7448"], "master").link
    keys = dict(link.zenoh_settings())
    assert keys["mode"] == '"client"'
    assert "listen/endpoints" not in keys
    assert keys["connect/endpoints"] == '["tcp/127.0.0.1:7448"]'


@pytest.mark.parametrize(
    ("argv", "named"),
    [
        (["--one-way-delay", "-0.1"], "--one-way-delay (link.slave.injection.delay_s)"),
        (["--loss", "1.5"], "--loss (link.slave.injection.loss_probability)"),
        (["--burst-exit", "0"], "--burst-exit"),
        (["--connect", "localhost"], "--connect (link.slave.endpoints.connect)"),
        (["--key-prefix", "haptic/*"], "--key-prefix (link.transport.key_prefix)"),
        (["--duration", "0"], "--duration"),
        (["--zenoh-set", "novalue"], "--zenoh-set"),
        (["--zenoh-set", "transport/link/tx/lease=[oops"], "--zenoh-set"),
        (["--zenoh-config", "/nonexistent/zenoh.json5"], "--zenoh-config"),
        (["--max-message-age", "0"], "--max-message-age"),
    ],
)
def test_bad_flags_name_the_flag_and_exit_2(argv, named, capsys):
    with pytest.raises(ConfigError) as caught:
        parse(argv)
    assert str(caught.value).startswith(named)
    with pytest.raises(SystemExit) as exited, exit_on_config_error():
        parse(argv)
    assert exited.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and named in err


def test_config_file_link_table(tmp_path):
    path = tmp_path / "run.toml"
    path.write_text(
        '[link.slave.endpoints]\nlisten = ""\nconnect = "tcp/192.168.1.10:7447"\n'
        "[link.slave.injection]\n"
        'delay_s = 0.01\njitter_s = 0.0\njitter_distribution = "uniform"\n'
        "preserve_order = true\nloss_probability = 0.05\nburst_enter_probability = 0.0\n"
        "burst_exit_probability = 1.0\nburst_loss_probability = 1.0\nseed = 3\n"
    )
    link = parse(["--one-way-delay", "0.03", "--insecure"], "slave", config_file=path).link
    assert link.connect == ("tcp/192.168.1.10:7447",)
    assert link.injection.loss_probability == 0.05
    assert link.injection.delay_s == 0.03  # the flag wins over the file
    assert link.seed == 3
    assert link.key_prefix == "haptic/rig-1"  # the tables the file leaves out keep defaults


def test_config_file_errors_name_the_dotted_key(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text('[link.master.endpoints]\nlisten = "tcp/127.0.0.1:1"\nconnect = "bogus"\n')
    with pytest.raises(ConfigError) as caught:
        load_config(path)
    assert caught.value.key == "link.master.endpoints.connect"


def test_link_config_checks_itself():
    with pytest.raises(ConfigError, match="side"):
        LinkConfig(side="operator")
    with pytest.raises(ConfigError, match="router"):
        LinkConfig(side="slave", mode="client")
    config = load_config()
    assert link_config_from(config, "slave", seed=9).seed == 9


def _parsers():
    from haptic.common.analysis import cli as analyze_cli
    from haptic.common.launch import cli as session
    from haptic.lockstep import cli as lockstep_cli
    from haptic.master import cli as master_cli
    from haptic.slave_sim import cli as slave_cli

    return {
        "haptic-analyze": (analyze_cli.build_parser, []),
        "haptic-sim run": (lockstep_cli.build_parser, ["run"]),
        "haptic-master": (master_cli.build_parser, []),
        "haptic-slave": (slave_cli.build_parser, []),
        "haptic-session": (session.build_parser, []),
    }


@pytest.mark.parametrize("program", ["haptic-analyze", "haptic-sim run", "haptic-master",
                                     "haptic-slave", "haptic-session"])
def test_a_bare_delay_is_refused_naming_both_delays(program: str, capsys) -> None:
    build, prefix = _parsers()[program]
    with pytest.raises(SystemExit) as caught:
        build().parse_args([*prefix, "--delay", "0.01"])
    assert caught.value.code == 2
    error = capsys.readouterr().err
    assert "--one-way-delay" in error and "--round-trip-delay" in error


@pytest.mark.parametrize(("program", "flag", "dest"), [
    ("haptic-analyze", "--round-trip-delay", "delay"),
    ("haptic-sim run", "--round-trip-delay", "delay"),
    ("haptic-master", "--one-way-delay", "delay"),
    ("haptic-slave", "--one-way-delay", "delay"),
    ("haptic-session", "--one-way-delay", "delay"),
])
def test_each_program_names_the_delay_it_takes(program: str, flag: str, dest: str) -> None:
    build, prefix = _parsers()[program]
    args = build().parse_args([*prefix, flag, "0.004"])
    assert getattr(args, dest) == 0.004
