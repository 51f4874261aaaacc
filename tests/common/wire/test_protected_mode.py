"""Protected mode (common/wire/protected_mode.py): a session that reaches other hosts with
neither a session key nor mutual TLS is refused before anything opens, unless ``--insecure``.

No test here sends anything beyond loopback: the refusals happen before the Zenoh session
opens (``zenoh.open`` is made to fail the test in this process, so a refusal that came too
late shows as a failure, never as traffic), the allowed non-loopback cases exercise only the
decision, and the sessions that do open are on 127.0.0.1. The one subprocess run is given a
wildcard listener only (it would send nothing even if it were not refused)."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest
import zenoh

from haptic.common.config import ConfigError, exit_on_config_error, load_config
from haptic.common.runtime.cli_options import add_run_options, run_options_from_args
from haptic.common.runtime.program_harness import ProgramHarness
from haptic.common.wire import link as link_module
from haptic.common.wire import protected_mode
from haptic.common.wire.auth import write_key_file
from haptic.common.wire.errors import LinkOpenError
from haptic.common.wire.link import Link, zenoh_config
from haptic.common.wire.link_config import LinkConfig
from haptic.common.wire.ports import free_port
from haptic.common.wire.protected_mode import (
    ZenohSettings,
    decide,
    reaches_other_hosts,
    require_protection,
)
from haptic.common.wire.router import cli as router_cli

#: The real ``zenoh.open``, for the one test that opens a session (on loopback).
ZENOH_OPEN = zenoh.open
ZENOH_FILES = Path(__file__).resolve().parents[3] / "deploy" / "zenoh"
LAN = "tcp/192.168.1.20:7447"
WILDCARD = "tcp/0.0.0.0:7447"
#: What the refusal names: the key option, mutual TLS and --insecure.
WAYS_OUT = ("--session-key", "mutual TLS", "--insecure")


@pytest.fixture(autouse=True)
def no_session_opens(monkeypatch):
    """Any Zenoh session opened in this process fails the test (a refusal must come before
    the session), but for the loopback one that a test lets open."""

    def refuse(*_args, **_kwargs):
        raise AssertionError("a Zenoh session was opened: the refusal came too late")

    monkeypatch.setattr(zenoh, "open", refuse)
    monkeypatch.setattr(link_module, "open_session", refuse)


def options(argv: list[str], side: str = "master"):
    parser = argparse.ArgumentParser()
    add_run_options(parser)
    return run_options_from_args(parser.parse_args(argv), side)


def verdict(link: LinkConfig) -> protected_mode.Protection:
    return decide(ZenohSettings.of(zenoh_config(link)), link.session_key is not None,
                  link.insecure)


@pytest.fixture
def key_file(tmp_path) -> str:
    return str(write_key_file(tmp_path / "rig.key"))


@pytest.mark.parametrize(("endpoint", "beyond"), [
    ("tcp/127.0.0.1:7447", False), ("tcp/127.8.9.10:1", False), ("tcp/[::1]:7447", False),
    ("tcp/localhost:7447", False), ("udp/LOCALHOST:7447", False),
    ("tcp/[::ffff:127.0.0.1]:7447", False), ("ws/127.0.0.1:80?x=1", False),
    ("unixsock-stream//tmp/haptic.sock", False),
    ("tcp/0.0.0.0:7447", True), ("tcp/[::]:0", True), ("udp/0.0.0.0:7447", True),
    (LAN, True), ("tcp/192.168.1.20:7447#iface=eth0", True), ("tls/10.0.0.5:7447", True),
    ("quic/[fe80::1%eth0]:7447", True), ("tcp/rig-pc.lab:7447", True),
    ("tcp/localhost.evil.example:7447", True), ("serial//dev/ttyUSB0", True),
])
def test_which_endpoints_reach_other_hosts(endpoint, beyond):
    assert reaches_other_hosts(endpoint) is beyond


@pytest.mark.parametrize(("argv", "side", "named"), [
    (["--listen", WILDCARD], "master", f"listen {WILDCARD}"),
    (["--listen", "tcp/[::]:7447"], "master", "listen tcp/[::]:7447"),
    (["--connect", LAN], "slave", f"connect {LAN}"),
    (["--mode", "client", "--connect", LAN], "master", f"connect {LAN}"),
    (["--listen", "udp/192.168.1.20:7447"], "master", "listen udp/192.168.1.20:7447"),
    (["--zenoh-set", f'listen/endpoints=["{WILDCARD}"]'], "master", f"listen {WILDCARD}"),
    (["--zenoh-set", "scouting/multicast/enabled=true"], "slave", "multicast scouting"),
])
def test_refused_without_key_or_tls_one_line_naming_the_ways_out(argv, side, named, capsys):
    with pytest.raises(SystemExit) as exited, exit_on_config_error():
        options(argv, side)
    assert exited.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("config error: link.security: protected")
    assert named in err and all(way in err for way in WAYS_OUT), err


def test_a_zenoh_file_that_listens_everywhere_is_seen(tmp_path):
    """The file's listen (or Zenoh's default, every interface, when it sets none) is judged as
    the flags are; without a file a side with no listen endpoint listens on none."""
    wide = tmp_path / "wide.json5"
    wide.write_text(f'{{ listen: {{ endpoints: ["{WILDCARD}"] }} }}')
    silent = tmp_path / "silent.json5"
    silent.write_text("{ transport: { link: { tx: { lease: 2000 } } } }")
    for path, named in ((wide, WILDCARD), (silent, "tcp/[::]:0")):
        with pytest.raises(ConfigError, match="protected mode") as caught:
            options(["--zenoh-config", str(path)], "slave")
        assert f"listen {named}" in str(caught.value)
    slave = options([], "slave").link
    assert dict(slave.zenoh_settings())["listen/endpoints"] == "[]"
    assert not verdict(slave).exposure.reachable


@pytest.mark.parametrize("argv", [
    [], ["--listen", "tcp/localhost:7447"], ["--listen", "tcp/[::1]:7447"],
    ["--mode", "client", "--connect", "tcp/127.0.0.1:7447"],
])
def test_loopback_without_a_key_is_allowed(argv):
    link = options(argv).link
    protection = verdict(link)
    assert protection.allowed and not protection.exposure.reachable
    assert protection.label == "loopback" and protection.marker == ""


@pytest.mark.parametrize(("argv", "side"), [
    (["--listen", WILDCARD], "master"), (["--connect", LAN], "slave"),
    (["--mode", "client", "--connect", LAN], "slave"),
    (["--zenoh-set", "scouting/multicast/enabled=true"], "master"),
])
def test_allowed_with_a_session_key(argv, side, key_file):
    link = options([*argv, "--session-key", key_file], side).link
    protection = verdict(link)
    assert protection.allowed and protection.exposure.reachable
    assert protection.label == "session key" and not protection.unauthenticated
    assert protection.marker == ""


def test_allowed_with_insecure_and_then_says_unauthenticated(tmp_path):
    link = options(["--listen", WILDCARD, "--insecure"]).link
    assert link.insecure
    protection = verdict(link)
    assert protection.allowed and protection.unauthenticated
    assert protection.marker == "UNAUTHENTICATED (--insecure)"
    assert protection.summary() == {"link_protection": "none (--insecure)",
                                    "link_unauthenticated": True,
                                    "link_reachable": [f"listen {WILDCARD}"]}
    config = tmp_path / "insecure.toml"
    config.write_text("[link.security]\ninsecure = true\n")
    assert options(["--config", str(config), "--connect", LAN], "slave").link.insecure
    config.write_text('[link.security]\ninsecure = "yes"\n')
    with pytest.raises(ConfigError) as caught:
        load_config(config)
    assert caught.value.key == "link.security.insecure"


def tls_overrides(name: str) -> list[str]:
    """``--zenoh-set`` flags pointing a shipped json5 file at certificate paths (never read:
    nothing opens)."""
    pairs = [("root_ca_certificate", "/certs/ca.pem")] + [
        (f"{end}_{what}", f"/certs/{name}.{ext}") for end in ("listen", "connect")
        for what, ext in (("private_key", "key"), ("certificate", "pem"))]
    return [arg for key, path in pairs
            for arg in ("--zenoh-set", f'transport/link/tls/{key}="{path}"')]


@pytest.mark.parametrize(("side", "file", "ends"), [
    ("master", "peer-master.json5", ["--listen", "tls/0.0.0.0:7447"]),
    ("slave", "peer-slave.json5", ["--connect", "tls/192.168.1.10:7447"]),
    ("master", "client-master.json5", ["--mode", "client", "--connect", "tls/10.0.0.5:7447"]),
])
def test_allowed_with_the_shipped_mutual_tls(side, file, ends):
    link = options([*ends, "--zenoh-config", str(ZENOH_FILES / file), *tls_overrides(side)],
                   side).link
    protection = verdict(link)
    assert protection.allowed and protection.mutual_tls and protection.label == "mutual TLS"


@pytest.mark.parametrize(("change", "why"), [
    ('transport/link/tls/enable_mtls=false', "enable_mtls is not true"),
    ('transport/link/tls/root_ca_certificate=""', "no root_ca_certificate"),
    ('transport/link/tls/listen_certificate=""', "no listen_certificate"),
    (f'listen/endpoints=["tls/0.0.0.0:7447", "{WILDCARD}"]', f"{WILDCARD} is not tls"),
    ("scouting/multicast/enabled=true", "multicast scouting"),
])
def test_tls_that_does_not_verify_both_ends_is_not_mutual_tls(change, why):
    argv = ["--listen", "tls/0.0.0.0:7447", "--zenoh-config",
            str(ZENOH_FILES / "peer-master.json5"), *tls_overrides("master")]
    if change.startswith("scouting"):  # the shipped file admits only tls: allow tcp too
        argv += ["--zenoh-set", 'transport/link/protocols=["tls", "tcp"]']
    with pytest.raises(ConfigError, match="not mutual TLS: .*" + why.split()[0]) as caught:
        options([*argv, "--zenoh-set", change])
    assert why in str(caught.value)


def test_plain_tls_endpoint_without_client_certificates_is_refused():
    with pytest.raises(ConfigError, match="not mutual TLS"):
        options(["--listen", "tls/0.0.0.0:7447", "--zenoh-set",
                 'transport/link/tls/root_ca_certificate="/certs/ca.pem"'])


def test_a_router_is_judged_by_its_listeners_not_its_default_scouting():
    config = router_cli.router_config(None, ["tcp/127.0.0.1:7447"], [])
    assert require_protection(config, False, False).label == "loopback"
    with pytest.raises(ConfigError, match="multicast scouting"):  # unless it autoconnects
        require_protection(router_cli.router_config(
            None, ["tcp/127.0.0.1:7447"], ['scouting/multicast/autoconnect={router: ["peer"]}']),
            False, False)


@pytest.mark.parametrize("argv", [[], ["--listen", LAN]])
def test_router_refuses_without_mutual_tls_exit_2(argv, capsys):
    assert router_cli.main(argv) == 2  # the default listener is tcp/0.0.0.0:7447
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("haptic-router: protected mode")
    assert "mutual TLS" in err and "--insecure" in err


def test_link_itself_refuses_before_its_session_opens():
    link = Link(LinkConfig(side="master", listen=(WILDCARD,)))
    with pytest.raises(LinkOpenError, match="protected mode"):
        link.open()
    assert not link.is_open


@pytest.mark.parametrize(("module", "argv"), [
    ("haptic.master.cli", ["--listen", LAN]),
    ("haptic.slave_sim.cli", ["--connect", LAN]),
    ("haptic.view.cli", ["--connect", LAN]),
])
def test_the_programs_refuse_with_one_line_and_exit_2(module, argv, capsys):
    main = __import__(module, fromlist=["main"]).main
    with pytest.raises(SystemExit) as exited:
        main(argv)
    assert exited.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "protected mode" in err and "--insecure" in err
    assert "--session-key" in err


def test_the_installed_entry_refuses_in_its_own_process():
    done = subprocess.run([sys.executable, "-m", "haptic.slave_sim.cli", "--listen",
                           "tcp/0.0.0.0:0", "--peer-wait", "1", "--duration", "1"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "listen tcp/0.0.0.0:0" in lines[0]
    assert all(way in lines[0] for way in WAYS_OUT)


def test_status_line_and_summary_say_unauthenticated_with_insecure(monkeypatch, capsys):
    def loopback_session(config: zenoh.Config, psk: bytes | None) -> zenoh.Session:
        assert psk is None and not protected_mode.exposure(ZenohSettings.of(config)).reachable
        return ZENOH_OPEN(config)

    monkeypatch.setattr(link_module, "open_session", loopback_session)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    watchdog = SimpleNamespace(state=SimpleNamespace(value="waiting"))
    for insecure in (True, False):
        config = LinkConfig(side="master", listen=(endpoint,), insecure=insecure,
                            key_prefix="test/protected")
        with Link(config) as link:
            harness = ProgramHarness("haptic-master", "slave", SimpleNamespace(json_summary=None),
                                     link, 0.001)
            line = harness.status_line(watchdog, "k 1")
            summary = link.summary()
            harness.finish({"steps": 1, "rate_hz": 1000.0, "overruns": 0, "events": [],
                            "max_abs_force_N": 0.0, "watchdog_trips": 0, **summary})
        err = capsys.readouterr().err
        assert line.startswith("UNAUTHENTICATED (--insecure)  link p50") is insecure, line
        assert ("session UNAUTHENTICATED (--insecure)" in err) is insecure, err
        assert summary["link_unauthenticated"] is True and summary["link_reachable"] == []
        assert summary["link_protection"] == ("none (--insecure)" if insecure else "loopback")
