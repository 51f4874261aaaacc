"""The control family in the pairing hello, over real Zenoh on loopback: a master and a slave
that run different ``[control] mode`` families (a lane law against the programs' own
messages, or two different laws) are refused at start on both sides with a line naming the
two modes, with or without a session key; the same law pairs and its messages go through; a
stranger's mismatched hello does not keep the real peer from pairing. Every session is closed
by its context manager."""

from __future__ import annotations

import json
import re
import time

import msgpack
import pytest
import zenoh

from haptic.common.wire.auth import KIND_HELLO
from haptic.common.wire.errors import LinkOpenError
from haptic.common.wire.law_link import LawLink
from haptic.common.wire.link import Link
from haptic.common.wire.messages import SCHEMA_VERSION
from tests.helpers.link_helpers import WAIT_S, configs, pair

PSK = bytes(range(32))
PROGRAMS = '"paper" or "tdpa"'


def _refusal(peer: str, peer_mode: str, own_mode: str) -> str:
    """The start refusal's line, as a regular expression."""
    return re.escape(f"the {peer} runs [control] mode = {peer_mode}, this side {own_mode}; "
                     "set the same [control] mode on both sides")


def _both_refuse(master: Link, slave: Link, master_line: str, slave_line: str) -> None:
    """Each side's ``wait_for_peer`` raises :class:`LinkOpenError` with its line (the other
    side polled meanwhile, so its hellos keep coming); neither ever pairs."""
    for link, line in ((slave, slave_line), (master, master_line)):
        with pytest.raises(LinkOpenError, match=line):
            deadline = time.monotonic() + WAIT_S
            while time.monotonic() < deadline:
                master.poll()
                slave.poll()
                link.wait_for_peer(0.01)
    assert not master.paired and not slave.paired
    assert master.peer_hello is None and slave.peer_hello is None


def _deliver_one(master: LawLink, slave: LawLink) -> None:
    """The master's law message reaches the slave (polled for at most WAIT_S)."""
    sent = master.send_values((0.25, -0.5, 1.0, 0.0, 2.0, 3.0))
    assert sent is not None
    deadline = time.monotonic() + WAIT_S
    while slave.latest_law is None and time.monotonic() < deadline:
        slave.poll()
        time.sleep(0.001)
    assert slave.latest_law == sent


@pytest.mark.parametrize("key", [None, PSK], ids=["without a key", "with a key"])
def test_a_law_against_the_programs_messages_is_refused_on_both_sides(key) -> None:
    master_config, slave_config = configs(session_key=key)
    with Link(master_config) as master, LawLink(slave_config, "wave") as slave:
        assert master.hello_control is None and slave.hello_control == "wave"
        _both_refuse(master, slave,
                     master_line=_refusal("slave", '"wave"', PROGRAMS),
                     slave_line=_refusal("master", PROGRAMS, '"wave"'))
        assert master.peer_alive and slave.peer_alive  # they met, and still refused
    assert not master.is_open and not slave.is_open


@pytest.mark.parametrize("key", [None, PSK], ids=["without a key", "with a key"])
def test_two_different_laws_are_refused_on_both_sides(key) -> None:
    master_config, slave_config = configs(session_key=key)
    with LawLink(master_config, "wave") as master, LawLink(slave_config, "mmt") as slave:
        _both_refuse(master, slave,
                     master_line=_refusal("slave", '"mmt"', '"wave"'),
                     slave_line=_refusal("master", '"wave"', '"mmt"'))
        if key is not None:
            assert master.unpaired_sends == 0 and master.auth.pairings == 0
    assert not master.is_open and not slave.is_open


@pytest.mark.parametrize("key", [None, PSK], ids=["without a key", "with a key"])
def test_the_same_law_pairs_and_its_messages_go_through(key) -> None:
    master_config, slave_config = configs(session_key=key)
    with LawLink(master_config, "wave") as master, LawLink(slave_config, "wave") as slave:
        pair(master, slave)
        assert master.wait_for_peer(WAIT_S) and slave.wait_for_peer(WAIT_S)
        assert master.peer_mismatch is None and slave.peer_mismatch is None
        assert master.peer_hello.control == "wave" and slave.peer_hello.control == "wave"
        assert (master.peer_hello.epoch, slave.peer_hello.epoch) == (slave.epoch, master.epoch)
        _deliver_one(master, slave)
    assert not master.is_open and not slave.is_open


def _stranger(endpoint: str) -> zenoh.Session:
    config = zenoh.Config()
    config.insert_json5("connect/endpoints", json.dumps([endpoint]))
    config.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(config)


def test_a_strangers_single_mismatched_hello_does_not_stop_the_real_pairing() -> None:
    master_config, slave_config = configs()
    with LawLink(master_config, "wave") as master, \
            _stranger(master_config.listen[0]) as stranger:
        heard = stranger.declare_subscriber(master_config.key("pair/master"),
                                            zenoh.handlers.FifoChannel(16))
        deadline = time.monotonic() + WAIT_S
        while heard.try_recv() is None:  # the master's declarations reached the stranger
            master.poll()
            assert time.monotonic() < deadline, "the stranger never heard the master"
            time.sleep(0.005)
        hello = msgpack.packb([SCHEMA_VERSION, KIND_HELLO, 2, 99, bytes(16), time.time_ns(),
                               False, "mmt"], use_bin_type=True)
        stranger.put(master_config.key("pair/slave"), hello)  # once
        while master.peer_mismatch is None:
            master.poll()
            assert time.monotonic() < deadline, "the stranger's hello never came"
            time.sleep(0.001)
        assert "mmt" in master.peer_mismatch and master.peer_hello is None
        with LawLink(slave_config, "wave") as slave:
            pair(master, slave)  # a later matching hello of the real slave pairs
            assert master.wait_for_peer(WAIT_S) and slave.wait_for_peer(WAIT_S)
            assert master.peer_hello.epoch == slave.epoch != 99
            _deliver_one(master, slave)
        heard.undeclare()
    assert not master.is_open
