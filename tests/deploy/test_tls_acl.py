"""The shipped Zenoh configurations (deploy/zenoh/) on one host: they load, mutual TLS admits
only certificates of the deployment's CA, and the access control passes handle state only
from the master and tool state only from the slave."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import zenoh

from haptic.common.config import load_config
from haptic.common.wire.link import Link, zenoh_config
from haptic.common.wire.link_config import link_config_from
from haptic.common.wire.ports import free_port
from haptic.common.wire.router.cli import router_config
from tests.helpers.programs import Program, python_module

DEPLOY = Path(__file__).resolve().parents[2] / "deploy"
ZENOH = DEPLOY / "zenoh"
PREFIX = "haptic/rig-1"  # the key prefix the access control names

#: How long a started router may take to say it listens, s.
READY_S = 60.0


def test_every_zenoh_config_loads():
    files = sorted(ZENOH.glob("*.json5"))
    assert {f.name for f in files} >= {"router.json5", "client-master.json5",
                                       "client-slave.json5", "peer-master.json5",
                                       "peer-slave.json5"}
    for path in files:
        config = zenoh.Config.from_file(str(path))
        assert config.get_json("transport/link/tls/enable_mtls") == "true", path.name
    for name in ("router", "peer-master", "peer-slave"):
        config = zenoh.Config.from_file(str(ZENOH / f"{name}.json5"))
        assert config.get_json("access_control/enabled") == "true"
        assert config.get_json("access_control/default_permission") == '"deny"'


def test_tls_toml_files_match_the_zenoh_files():
    router = load_config(DEPLOY / "router-tls.toml")
    peers = load_config(DEPLOY / "two-hosts-tls.toml")
    for side in ("master", "slave"):
        link = link_config_from(router, side)
        assert link.mode == "client" and link.connect[0].startswith("tls/")
        assert link.key_prefix == PREFIX
    assert link_config_from(peers, "master").listen == ("tls/0.0.0.0:7447",)
    assert link_config_from(peers, "slave").connect[0].startswith("tls/")


def test_router_config_layers_file_listen_and_overrides():
    config = router_config(str(ZENOH / "router.json5"), ["tls/127.0.0.1:1"],
                           ['transport/link/tls/root_ca_certificate="/x/ca.pem"'])
    assert config.get_json("mode") == '"router"'
    assert config.get_json("listen/endpoints") == '["tls/127.0.0.1:1"]'
    assert config.get_json("transport/link/tls/root_ca_certificate") == '"/x/ca.pem"'
    with pytest.raises(ValueError):
        router_config(None, [], ["no-equals"])


def test_make_certs_chain_and_names(certs):
    if shutil.which("openssl") is None:
        pytest.skip("openssl is not installed")
    good, rogue = str(certs.good / "ca.pem"), str(certs.rogue / "ca.pem")
    for name in ("router", "master", "slave", "intruder"):
        pem = str(certs.good / f"{name}.pem")
        subprocess.run(["openssl", "verify", "-CAfile", good, pem], check=True,
                       capture_output=True)
        subject = subprocess.run(["openssl", "x509", "-in", pem, "-noout", "-subject"],
                                 check=True, capture_output=True, text=True).stdout
        assert f"CN = haptic-{name}" in subject or f"CN=haptic-{name}" in subject
    foreign = subprocess.run(["openssl", "verify", "-CAfile", good,
                              str(certs.rogue / "master.pem")], capture_output=True)
    assert foreign.returncode != 0
    assert (certs.rogue / "ca.pem").read_bytes() != (certs.good / "ca.pem").read_bytes()
    assert rogue != good
    assert os.stat(certs.good / "master.key").st_mode & 0o077 == 0


def client_link(side: str, endpoint: str, overrides, zenoh_file: str) -> Link:
    config = link_config_from(
        load_config(), side, mode="client", connect=(endpoint,), listen=(), key_prefix=PREFIX,
        zenoh_config_file=str(ZENOH / zenoh_file), zenoh_overrides=overrides,
    )
    return Link(config)


def wait_alive(*links: Link, timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not all(link.peer_alive for link in links):
        for link in links:
            link.poll()
        assert time.monotonic() < deadline, "the peers never saw each other"
        time.sleep(0.002)


def drain(link: Link, seconds: float) -> list:
    got, deadline = [], time.monotonic() + seconds
    while time.monotonic() < deadline:
        message = link.poll()
        if message is not None:
            got.append(message)
        time.sleep(0.002)
    return got


def test_router_tls_and_access_control_on_one_host(certs):
    endpoint = f"tls/localhost:{free_port()}"
    overrides = [a for k, v in certs.tls_overrides("router") for a in ("--zenoh-set", f"{k}={v}")]
    with Program(python_module("haptic.common.wire.router.cli", "--zenoh-config",
                               str(ZENOH / "router.json5"), "--listen", endpoint, *overrides),
                 stop_signal=signal.SIGTERM) as router:
        router.wait_for("listening", timeout_s=READY_S)
        master = client_link("master", endpoint, certs.tls_overrides("master"),
                             "client-master.json5")
        slave = client_link("slave", endpoint, certs.tls_overrides("slave"), "client-slave.json5")
        with master, slave:
            wait_alive(master, slave)
            sent = [master.send_handle((0.1 * i, 0.0), (0.0, 0.0)) for i in range(5)]
            assert drain(slave, 0.5)[-1] == sent[-1]
            tool = slave.send_tool((1.0, 2.0), (0.0, 0.0), (0.0, 0.0), 0.0, 0.0)
            assert drain(master, 0.5)[-1] == tool
            # a certificate of the same CA whose CN the access control does not name
            intruder = client_link("master", endpoint, certs.tls_overrides("intruder"),
                                   "client-master.json5")
            intruder_tool = client_link("slave", endpoint, certs.tls_overrides("intruder"),
                                        "client-slave.json5")
            with intruder, intruder_tool:
                for _ in range(20):
                    intruder.send_handle((9.0, 9.0), (0.0, 0.0))
                    intruder_tool.send_tool((9.0, 9.0), (0.0, 0.0), (0.0, 0.0), 0.0, 0.0)
                    time.sleep(0.005)
                assert drain(slave, 0.5) == [], "a handle message of a CN not allowed arrived"
                assert drain(master, 0.1) == [], "a tool message of a CN not allowed arrived"
            # the master and slave still get through
            sent = master.send_handle((0.5, 0.5), (0.0, 0.0))
            assert drain(slave, 0.3)[-1] == sent
            # a certificate of another CA: the TLS handshake fails, no session
            rogue = client_link("master", endpoint, certs.tls_overrides("master", rogue=True),
                                "client-master.json5")
            with pytest.raises(Exception, match="(?i)connect"):
                rogue.open()
            rogue.close()
            # no client certificate, or plain TCP: no session
            for protocol, ca in (("tls", True), ("tcp", False)):
                bare = zenoh.Config()
                bare.insert_json5("mode", '"client"')
                bare.insert_json5("connect/endpoints",
                                  f'["{protocol}/{endpoint.split("/", 1)[1]}"]')
                if ca:
                    bare.insert_json5("transport/link/tls/root_ca_certificate",
                                      f'"{certs.good / "ca.pem"}"')
                with pytest.raises(Exception, match="(?i)connect"):
                    zenoh.open(bare).close()


def peer_link(side: str, endpoint: str, overrides) -> Link:
    ends = {"listen": (endpoint,), "connect": ()} if side == "master" else {
        "listen": (), "connect": (endpoint,)}
    config = link_config_from(
        load_config(), side, mode="peer", key_prefix=PREFIX,
        zenoh_config_file=str(ZENOH / f"peer-{side}.json5"), zenoh_overrides=overrides, **ends,
    )
    return Link(config)


def test_direct_peers_tls_and_access_control_on_one_host(certs):
    endpoint = f"tls/localhost:{free_port()}"
    master = peer_link("master", endpoint, certs.tls_overrides("master"))
    slave = peer_link("slave", endpoint, certs.tls_overrides("slave"))
    with master, slave:
        wait_alive(master, slave)
        sent = master.send_handle((0.3, 0.0), (0.0, 0.0))
        assert drain(slave, 0.5)[-1] == sent
        tool = slave.send_tool((1.0, 2.0), (0.0, 0.0), (0.0, 0.0), 0.0, 0.0)
        assert drain(master, 0.5)[-1] == tool
        # same CA, a CN the master's access control does not name: its tool state is dropped
        intruder = peer_link("slave", endpoint, certs.tls_overrides("intruder"))
        with intruder:
            time.sleep(0.3)
            for _ in range(20):
                intruder.send_tool((9.0, 9.0), (0.0, 0.0), (0.0, 0.0), 0.0, 0.0)
                time.sleep(0.005)
            assert drain(master, 0.5) == [], "a tool message of a CN not allowed arrived"
        # another CA: a peer's session opens (peers retry in the background) but the TLS
        # handshake fails, so it never has a peer and nothing it sends arrives
        rogue = peer_link("slave", endpoint, certs.tls_overrides("slave", rogue=True))
        with rogue, zenoh.open(zenoh_config(rogue.config)) as probe:
            for _ in range(20):
                rogue.send_tool((9.0, 9.0), (0.0, 0.0), (0.0, 0.0), 0.0, 0.0)
                time.sleep(0.01)
            assert drain(master, 0.5) == [], "a tool message from a foreign CA arrived"
            assert list(probe.info.peers_zid()) == []


def test_router_cli_rejects_a_bad_override_and_the_old_wrapper_runs(tmp_path):
    bad = subprocess.run(
        [sys.executable, "-m", "haptic.common.wire.router.cli", "--zenoh-set", "oops"],
        capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "KEY=VALUE" in bad.stderr
    missing = subprocess.run(
        [sys.executable, "-m", "haptic.common.wire.router.cli", "--zenoh-config",
         str(tmp_path / "no.json5")],
        capture_output=True, text=True, timeout=60)
    assert missing.returncode == 2 and missing.stderr.startswith("haptic-router:")
    wrapper = subprocess.run([sys.executable, str(DEPLOY / "zenoh_router.py"), "--help"],
                             capture_output=True, text=True, timeout=60)
    assert wrapper.returncode == 0 and "--zenoh-config" in wrapper.stdout
