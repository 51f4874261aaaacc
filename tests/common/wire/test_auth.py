"""Authenticated sessions (issue 17, common/wire/auth.py) over real Zenoh on loopback: a forged
peer, a replaying peer, an explicit re-pairing, mismatched peers refused at start. The
message layer alone; the transport authentication on top of it: test_transport_auth.py."""

from __future__ import annotations

import os
import time
import uuid

import msgpack
import pytest
import zenoh

from haptic.common.config import ConfigError, load_config, override
from haptic.common.wire.auth import (
    KIND_HELLO,
    SessionAuth,
    decode_hello,
    encode_hello,
    load_key_file,
    write_key_file,
)
from haptic.common.wire.errors import LinkOpenError
from haptic.common.wire.link import Link
from haptic.common.wire.link_config import LinkConfig, link_config_from
from haptic.common.wire.messages import KIND_TOOL, SCHEMA_VERSION, ToolState
from haptic.common.wire.ports import free_port
from tests.helpers.attacks import forged_payload
from tests.helpers.link_helpers import WAIT_S, pair

PSK = bytes(range(32))


def _configs(master_key: bytes | None = PSK, slave_key: bytes | None = PSK):
    """Two links with the message layer alone: their Zenoh transports admit anyone
    (``transport_auth`` off, as where a router relays the link), so a stranger's messages
    reach the message checks (tests/common/wire/test_transport_auth.py: with it on, they never
    arrive)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    prefix = f"test/{uuid.uuid4().hex[:8]}"
    common = {"key_prefix": prefix, "congestion_control": "block", "stale_after_s": 10.0,
              "transport_auth": False}
    master = LinkConfig(side="master", listen=(endpoint,), session_key=master_key, **common)
    slave = LinkConfig(side="slave", connect=(endpoint,), session_key=slave_key, **common)
    return master, slave, endpoint


def _raw_session(endpoint: str) -> zenoh.Session:
    config = zenoh.Config()
    config.insert_json5("connect/endpoints", f'["{endpoint}"]')
    config.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(config)


def _exchange(master: Link, slave: Link, n: int, force_N: float = 0.5) -> list[ToolState]:
    got = []
    for _ in range(n):
        slave.poll()
        slave.send_tool((force_N, 0.0), (0.0, 0.0), (0.0, 0.0), 0.0, 0.0)
        time.sleep(0.001)
        message = master.poll()
        if message is not None:
            got.append(message)
    return got


def _drain(link: Link, seconds: float) -> list:
    got = []
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        message = link.poll()
        if message is not None:
            got.append(message)
        time.sleep(0.0005)
    return got


def test_key_file_rules(tmp_path) -> None:
    path = write_key_file(tmp_path / "k")
    assert len(load_key_file(path)) == 32
    assert os.stat(path).st_mode & 0o777 == 0o600
    os.chmod(path, 0o644)
    with pytest.raises(ConfigError, match="readable by others"):
        load_key_file(path)
    bad = tmp_path / "bad"
    bad.write_text("abc")
    os.chmod(bad, 0o600)
    with pytest.raises(ConfigError, match="64 hex digits"):
        load_key_file(bad)
    config = override(load_config(), "link.security.session_key_file", str(bad))
    with pytest.raises(ConfigError) as error:
        link_config_from(config, "master")
    assert error.value.key == "link.security.session_key_file"
    config = override(load_config(), "link.security.session_key_file", str(path.with_name("x")))
    with pytest.raises(ConfigError, match="cannot read"):
        link_config_from(config, "master")


def test_hello_tags_and_replays() -> None:
    master, slave = SessionAuth(PSK, "master", 1), SessionAuth(PSK, "slave", 2)
    now = time.time_ns()
    hello = master.hello(now)
    assert slave.accept_hello(decode_hello(hello, PSK), now)
    assert not slave.accept_hello(decode_hello(hello, PSK), now)  # the same hello again
    with pytest.raises(ValueError):
        decode_hello(hello[:-1] + bytes([hello[-1] ^ 1]), PSK)  # a forged tag
    with pytest.raises(ValueError):
        decode_hello(encode_hello("master", 9, bytes(16), now, bytes(32)), PSK)  # wrong key
    restarted = SessionAuth(PSK, "master", 3)
    assert slave.accept_hello(decode_hello(restarted.hello(now + 10), PSK), now + 10)
    # the old run's hello, replayed after the restart, changes nothing
    assert not slave.accept_hello(decode_hello(hello, PSK), now + 20)
    assert slave.peer_epoch == 3
    too_old = decode_hello(SessionAuth(PSK, "master", 4).hello(now - 10**10), PSK)
    assert not slave.accept_hello(too_old, now)


def test_forged_peer_is_dropped_and_never_delivered() -> None:
    """A stranger (no key) sends ToolStates with 1e9 N, new epochs and newer send times, as in
    the issue's attack: every one is dropped, no peer restart is counted."""
    master_config, slave_config, endpoint = _configs()
    with Link(master_config) as master, Link(slave_config) as slave:
        pair(master, slave)
        assert _exchange(master, slave, 30)
        with _raw_session(endpoint) as stranger:
            publisher = stranger.declare_publisher(master_config.subscribe_key)
            time.sleep(0.3)
            for i in range(300):
                publisher.put(forged_payload(KIND_TOOL, 1000 + i, 0, 1e9,
                                             send_time_ns=time.time_ns() + 10**9))
                if i % 10 == 0:
                    _exchange(master, slave, 1)
            got = _drain(master, 0.5)
        stats = master.stats()
    assert all(abs(m.tool_force_N[0]) < 1.0 for m in got)
    assert abs(master.latest.tool_force_N[0]) < 1.0
    assert stats.dropped["unauthenticated"] >= 250
    assert stats.peer_restarts == 0


def test_replaying_peer_is_refused() -> None:
    """Captured authenticated messages replayed in the same session (old sequence numbers)
    and after the peer restarted (another session key) are dropped."""
    master_config, slave_config, endpoint = _configs()
    with Link(master_config) as master, _raw_session(endpoint) as eavesdropper:
        captured: list[bytes] = []
        tap = eavesdropper.declare_subscriber(master_config.subscribe_key,
                                              lambda s: captured.append(s.payload.to_bytes()))
        replayer = eavesdropper.declare_publisher(master_config.subscribe_key)
        with Link(slave_config) as slave:
            pair(master, slave)
            time.sleep(0.2)
            _exchange(master, slave, 50, force_N=0.25)
            _drain(master, 0.2)
            assert len(captured) >= 20
            before = master.stats().dropped["out_of_order"]
            for payload in captured[:20]:
                replayer.put(payload)
            _drain(master, 0.5)
            assert master.stats().dropped["out_of_order"] - before >= 15
        # the slave restarts: a new epoch, a new session key through the pairing
        with Link(slave_config) as slave2:
            pair(master, slave2)
            assert master.auth.pairings == 2 and master.stats().peer_restarts == 1
            got = _exchange(master, slave2, 30, force_N=0.75)
            assert got
            unauthenticated = master.stats().dropped["unauthenticated"]
            unpaired = master.stats().dropped["unpaired"]
            for payload in captured[:20]:
                replayer.put(payload)
            _drain(master, 0.5)
            stats = master.stats()
            assert (stats.dropped["unauthenticated"] - unauthenticated
                    + stats.dropped["unpaired"] - unpaired) >= 15
            assert master.latest.tool_force_N[0] == pytest.approx(0.75)
        tap.undeclare()


def test_data_with_a_new_epoch_is_not_a_restart() -> None:
    """Without the pairing, a new epoch is 'unpaired', never a restart."""
    master_config, slave_config, _ = _configs()
    with Link(master_config) as master, Link(slave_config) as slave:
        pair(master, slave)
        _exchange(master, slave, 10)
        slave.epoch += 1  # messages of another epoch, with valid tags of this session
        _exchange(master, slave, 20)
        stats = master.stats()
    assert stats.dropped["unpaired"] >= 15 and stats.peer_restarts == 0


def test_authentication_on_one_side_only_is_refused_at_start() -> None:
    master_config, slave_config, _ = _configs(slave_key=None)
    with Link(master_config) as master, Link(slave_config) as slave:
        for link in (slave, master):
            with pytest.raises(LinkOpenError, match="authenticat"):
                deadline = time.monotonic() + WAIT_S
                while time.monotonic() < deadline:
                    master.poll()
                    slave.poll()
                    link.wait_for_peer(0.01)


def test_another_schema_version_is_refused_at_start() -> None:
    master_config, _, endpoint = _configs(master_key=None)
    with Link(master_config) as master, _raw_session(endpoint) as old:
        token = old.liveliness().declare_token(master_config.liveliness_key("slave"))
        publisher = old.declare_publisher(master_config.key("pair/slave"))
        old_version = SCHEMA_VERSION - 1  # e.g. a peer from before the energy fields (#16)
        hello = msgpack.packb([old_version, KIND_HELLO, 2, 5, bytes(16), time.time_ns(),
                               False])
        deadline = time.monotonic() + WAIT_S
        with pytest.raises(LinkOpenError, match=f"schema version {old_version}, this program "
                           f"{SCHEMA_VERSION}"):
            while time.monotonic() < deadline:
                publisher.put(hello)
                master.wait_for_peer(0.05)
        token.undeclare()


@pytest.mark.parametrize("key", [PSK, None], ids=["with a key", "without a key"])
def test_malformed_hellos_are_counted_and_never_stop_the_poll(key) -> None:
    """A hello whose side code is a list once made ``Link.poll()`` raise (a dict lookup of
    an unhashable value): any process that could publish on the pairing key could stop the
    loop. Now every undecodable hello is counted, with a key or without."""
    master_config, _, endpoint = _configs(master_key=key)
    junk = [msgpack.packb([SCHEMA_VERSION, KIND_HELLO, [1], 11, bytes(16), time.time_ns(),
                           False]),
            msgpack.packb([SCHEMA_VERSION, KIND_HELLO, {"x": 1}, 11, bytes(16), 1, False]),
            msgpack.packb([SCHEMA_VERSION, KIND_HELLO, 2, True, bytes(16), True, False]),
            b"\xc1not msgpack"]
    with Link(master_config) as master, _raw_session(endpoint) as stranger:
        publisher = stranger.declare_publisher(master_config.key("pair/slave"))
        deadline = time.monotonic() + WAIT_S
        while master.undecodable_hellos < 2 * len(junk) and time.monotonic() < deadline:
            for payload in junk:
                publisher.put(payload)
            _drain(master, 0.05)  # poll() must not raise
        assert master.undecodable_hellos >= 2 * len(junk)
        assert master.summary()["link_rejected_hellos"] >= 2 * len(junk)
        assert master.peer_hello is None
