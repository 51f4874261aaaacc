"""Zenoh transport authentication from the session key (issue 17,
common/wire/transport_auth.py), over real Zenoh on loopback: a stranger cannot join the
programs' session, so it can neither read their messages nor put anything on their keys; a
peer with another key cannot connect; the dictionary file does not outlive the open."""

from __future__ import annotations

import json
import os
import tempfile
import time
import uuid

import pytest
import zenoh

from haptic.common.config import ConfigError, load_config, override
from haptic.common.wire.auth import write_key_file
from haptic.common.wire.link import Link, zenoh_config
from haptic.common.wire.link_config import LinkConfig, link_config_from
from haptic.common.wire.messages import KIND_TOOL
from haptic.common.wire.ports import free_port
from haptic.common.wire.transport_auth import (
    open_session,
    transport_key,
    transport_password,
)
from tests.helpers.attacks import forged_payload
from tests.helpers.link_helpers import WAIT_S, pair

PSK = bytes(range(32))


def _configs(master_key: bytes | None = PSK, slave_key: bytes | None = PSK):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    common = {"key_prefix": f"test/{uuid.uuid4().hex[:8]}", "congestion_control": "block",
              "stale_after_s": 10.0}
    master = LinkConfig(side="master", listen=(endpoint,), session_key=master_key, **common)
    slave = LinkConfig(side="slave", connect=(endpoint,), session_key=slave_key, **common)
    return master, slave, endpoint


def _plain_config(endpoint: str) -> zenoh.Config:
    config = zenoh.Config()
    config.insert_json5("connect/endpoints", json.dumps([endpoint]))
    config.insert_json5("scouting/multicast/enabled", "false")
    return config


def test_credentials_follow_the_key() -> None:
    password = transport_password(PSK)
    assert len(password) == 64 and int(password, 16) >= 0
    assert transport_password(PSK) == password
    assert transport_password(bytes(32)) != password
    assert transport_key(PSK, True, "peer") == PSK
    assert transport_key(None, True, "peer") is None
    assert transport_key(PSK, False, "peer") is None
    assert transport_key(PSK, True, "client") is None  # a router relays: deploy/'s mTLS


def test_configuration_turns_it_on_with_a_key(tmp_path) -> None:
    key_file = write_key_file(tmp_path / "rig.key")
    keyed = override(load_config(), "link.security.session_key_file", str(key_file))
    assert link_config_from(keyed, "master").transport_key is not None
    assert link_config_from(load_config(), "master").transport_key is None
    off = override(keyed, "link.security.transport_auth", False)
    assert link_config_from(off, "master").transport_key is None
    with pytest.raises(ConfigError) as error:
        override(load_config(), "link.security.transport_auth", "yes")
    assert error.value.key == "link.security.transport_auth"


def test_the_dictionary_file_does_not_outlive_the_open(monkeypatch) -> None:
    made: list[str] = []
    real_mkdtemp = tempfile.mkdtemp

    def recording_mkdtemp(*args, **kwargs) -> str:
        folder = real_mkdtemp(*args, **kwargs)
        made.append(folder)
        assert os.stat(folder).st_mode & 0o077 == 0  # private to this user
        return folder

    monkeypatch.setattr(tempfile, "mkdtemp", recording_mkdtemp)
    master, _, _ = _configs()
    with open_session(zenoh_config(master), master.transport_key):
        assert made and not os.path.exists(made[0])


def test_a_stranger_cannot_join_read_or_put() -> None:
    """The paired programs exchange messages; a process without the key that connects to the
    master's endpoint has no peer: it receives none of their messages, and the forged
    1e9 N tool forces it puts never reach the master (not even as dropped messages)."""
    master_config, slave_config, endpoint = _configs()
    with Link(master_config) as master, Link(slave_config) as slave:
        pair(master, slave)
        with zenoh.open(_plain_config(endpoint)) as stranger:
            heard: list[bytes] = []
            tap = stranger.declare_subscriber(master_config.publish_key,
                                              lambda s: heard.append(s.payload.to_bytes()))
            publisher = stranger.declare_publisher(master_config.subscribe_key)
            time.sleep(0.5)
            assert list(stranger.info.peers_zid()) == []
            got = []
            for i in range(200):
                publisher.put(forged_payload(KIND_TOOL, 1000 + i, 0, 1e9,
                                             send_time_ns=time.time_ns() + 10**9))
                master.send_handle((0.5, 0.0), (0.0, 0.0))
                slave.poll()
                slave.send_tool((0.5, 0.0), (0.0, 0.0), (0.0, 0.0), 0.0, 0.0)
                time.sleep(0.001)
                message = master.poll()
                if message is not None:
                    got.append(message)
            tap.undeclare()
        stats = master.stats()
    assert heard == []
    assert got and all(abs(m.tool_force_N[0]) < 1.0 for m in got)
    assert sum(stats.dropped.values()) == 0
    assert stats.peer_restarts == 0


def test_the_same_key_through_open_session_joins() -> None:
    """What the view does with ``--session-key``: a session opened with the key hears the
    master's messages."""
    master_config, _, endpoint = _configs()
    with Link(master_config) as master, \
            open_session(_plain_config(endpoint), PSK) as viewer:
        heard: list[bytes] = []
        tap = viewer.declare_subscriber(master_config.key("pair/master"),
                                        lambda s: heard.append(s.payload.to_bytes()))
        deadline = time.monotonic() + WAIT_S
        while not heard and time.monotonic() < deadline:
            master.poll()  # publishes its hello every 0.1 s
            time.sleep(0.01)
        assert list(viewer.info.peers_zid())
        tap.undeclare()
    assert heard


@pytest.mark.parametrize("slave_key", [bytes(32), None], ids=["another key", "no key"])
def test_a_peer_without_the_same_key_cannot_connect(slave_key) -> None:
    master_config, slave_config, _ = _configs(slave_key=slave_key)
    with Link(master_config) as master, Link(slave_config) as slave:
        deadline = time.monotonic() + 1.5
        while time.monotonic() < deadline:
            master.poll()
            slave.poll()
            time.sleep(0.005)
        assert not master.peer_alive and not slave.peer_alive
        assert not master.wait_for_peer(0.1)
