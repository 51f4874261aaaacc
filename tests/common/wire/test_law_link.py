"""A lane law's link over real Zenoh on loopback: two LawLink objects in this process, with
bad payloads put on the same key beside the good messages. Sessions closed by the context
managers."""

from __future__ import annotations

import math
import time

import msgpack
import pytest

from haptic.common.wire.injection import InjectionConfig
from haptic.common.wire.law_link import LawLink
from haptic.common.wire.law_messages import LawMessage, law_kind
from haptic.common.wire.link import Link
from haptic.common.wire.messages import SCHEMA_VERSION, Flags
from tests.helpers.link_helpers import configs, wait_for_peers


def _drain(link: LawLink, count: int, timeout_s: float = 10.0) -> list[LawMessage]:
    """Poll until ``count`` messages were delivered (or the timeout)."""
    got: list[LawMessage] = []
    deadline = time.monotonic() + timeout_s
    while len(got) < count and time.monotonic() < deadline:
        if link.poll() is not None:
            got.extend(link.delivered)
        time.sleep(0.0005)
    return got


def test_law_messages_arrive_and_bad_ones_are_counted_and_dropped() -> None:
    master_cfg, slave_cfg = configs()
    with LawLink(master_cfg, "mmt") as master, LawLink(slave_cfg, "mmt") as slave:
        wait_for_peers(master, slave)
        sent = [master.send_values((0.01 * i, 0.0, 0.1, -0.2)) for i in range(20)]
        handle_key = master.config.publish_key
        session = master.session
        assert session is not None
        bad = [
            msgpack.packb([SCHEMA_VERSION, law_kind("mmt", "handle"), master.epoch, 100,
                           time.time_ns(), 0, 0.0, math.nan, 0.0, 0.0]),
            msgpack.packb([SCHEMA_VERSION, law_kind("mmt", "handle"), master.epoch, 101,
                           time.time_ns(), 0, 0.0, 0.0, 0.0]),
            msgpack.packb([SCHEMA_VERSION, law_kind("wave", "handle"), master.epoch, 102,
                           time.time_ns(), 0, 0.0, 0.0, 0.0, 0.0]),
            b"junk",
        ]
        for payload in bad:
            session.put(handle_key, payload)
        got = _drain(slave, 20)
        assert [m.values for m in got] == [m.values for m in sent]
        assert [m.seq for m in got] == list(range(20))
        tool = slave.send_values(tuple(float(i) for i in range(8)), Flags.IN_CONTACT)
        assert tool is not None
        back = _drain(master, 1)
        assert back == [tool]
        deadline = time.monotonic() + 5.0
        while sum(slave.stats().dropped.values()) < 4 and time.monotonic() < deadline:
            slave.poll()
            time.sleep(0.001)
        dropped = slave.stats().dropped
        assert dropped["non_finite"] == 1 and dropped["malformed"] == 2  # length, junk
        assert dropped["wrong_kind"] == 1  # another law's message
        assert slave.stats().delivered == 20
        with pytest.raises(ValueError, match="carry 4"):
            master.send_values((0.0,) * 8)
    assert not master.is_open and not slave.is_open


def test_a_non_finite_law_value_is_not_sent_and_the_peer_counts_it_lost() -> None:
    master_cfg, slave_cfg = configs()
    with LawLink(master_cfg, "mmt") as master, LawLink(slave_cfg, "mmt") as slave:
        wait_for_peers(master, slave)
        assert master.send_values((0.0, 0.0, 0.0, 0.0)) is not None
        assert master.send_values((math.inf, 0.0, 0.0, 0.0)) is None
        assert master.send_values((1.0, 0.0, 0.0, 0.0)) is not None
        got = _drain(slave, 2)
        assert [m.seq for m in got] == [0, 2]
        assert master.unsendable == 1 and master.summary()["link_unsendable"] == 1
        assert slave.stats().network_lost == 1


def test_injected_loss_and_delay_act_on_law_messages() -> None:
    master_cfg, slave_cfg = configs(InjectionConfig(delay_s=0.05, loss_probability=0.2))
    with LawLink(master_cfg, "four-channel") as master, \
            LawLink(slave_cfg, "four-channel") as slave:
        wait_for_peers(master, slave)
        for i in range(400):
            master.send_values((float(i),) + (0.0,) * 5)
        deadline = time.monotonic() + 10.0
        while slave.stats().received < 400 and time.monotonic() < deadline:
            slave.poll()  # at most max_samples_per_poll a poll
            time.sleep(0.001)
        time.sleep(0.06)  # the last ones' injected delay
        slave.poll()
        stats = slave.stats()
        lost = stats.dropped["injected_loss"]
        assert stats.delivered + lost == 400 and 40 < lost < 130
        assert stats.one_way_delay_p50_s >= 0.05


def test_a_program_link_and_a_law_link_do_not_understand_each_other() -> None:
    master_cfg, slave_cfg = configs()
    with Link(master_cfg) as master, LawLink(slave_cfg, "wave") as slave:
        wait_for_peers(master, slave)
        master.send_handle((1.0, 0.0), (0.0, 0.0))
        deadline = time.monotonic() + 5.0
        while slave.stats().received < 1 and time.monotonic() < deadline:
            slave.poll()
            time.sleep(0.001)
        assert slave.stats().dropped["wrong_kind"] == 1 and slave.latest is None
