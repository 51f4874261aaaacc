"""The shipped deployment files load, and client mode through the Python router works."""

from __future__ import annotations

import signal
import time
import uuid
from dataclasses import replace
from pathlib import Path

import pytest

from haptic.common.config import ConfigError, load_config, override
from haptic.common.runtime.cli_options import check_protected_mode
from haptic.common.wire.auth import write_key_file
from haptic.common.wire.link import Link
from haptic.common.wire.link_config import link_config_from
from haptic.common.wire.ports import free_port
from tests.helpers.programs import Program, python_module

DEPLOY = Path(__file__).resolve().parents[2] / "deploy"


SHIPPED_KEY = "/etc/haptic/rig-1.key"

#: How long a started router may take to say it listens, s.
READY_S = 60.0


def with_test_key(path: Path, tmp_path: Path) -> dict:
    """The shipped file's configuration with its key file (on the hosts, /etc/haptic/) replaced
    by a fresh one under ``tmp_path``."""
    config = load_config(path)
    assert config["link"]["security"]["session_key_file"] == SHIPPED_KEY
    key = write_key_file(tmp_path / "rig-1.key")
    return override(config, "link.security.session_key_file", str(key))


def test_two_hosts_config(tmp_path):
    config = with_test_key(DEPLOY / "two-hosts.toml", tmp_path)
    master = link_config_from(config, "master")
    slave = link_config_from(config, "slave")
    assert master.listen == ("tcp/0.0.0.0:7447",) and master.mode == "peer"
    assert slave.connect == ("tcp/192.168.1.10:7447",)
    for link in (master, slave):  # the protected mode admits them: a key (nothing is opened)
        assert link.session_key is not None and not link.insecure
        check_protected_mode(link)


def test_router_config(tmp_path):
    config = with_test_key(DEPLOY / "router.toml", tmp_path)
    for side in ("master", "slave"):
        link = link_config_from(config, side)
        assert link.mode == "client" and link.connect == ("tcp/192.168.1.5:7447",)
        check_protected_mode(link)
        with pytest.raises(ConfigError, match="protected mode"):  # the same without the key
            check_protected_mode(replace(link, session_key=None))


def test_client_mode_through_the_python_router():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with Program(python_module("haptic.common.wire.router.cli", "--listen", endpoint),
                 stop_signal=signal.SIGTERM) as router:
        router.wait_for("listening", timeout_s=READY_S)
        config = load_config()
        prefix = f"test/{uuid.uuid4().hex[:10]}"
        links = [
            link_config_from(config, side, mode="client", connect=(endpoint,), listen=(),
                             key_prefix=prefix)
            for side in ("master", "slave")
        ]
        with Link(links[0]) as master, Link(links[1]) as slave:
            deadline = time.monotonic() + 10
            while not (master.peer_alive and slave.peer_alive):
                master.poll()
                slave.poll()
                assert time.monotonic() < deadline
                time.sleep(0.001)
            sent = master.send_handle((1.0, 2.0), (0.0, 0.0))
            got = None
            while got is None:
                got = slave.poll()
                assert time.monotonic() < deadline
                time.sleep(0.001)
            assert got == sent
        assert router.stop(signal.SIGTERM, grace_s=10.0) == 0, router.output()
