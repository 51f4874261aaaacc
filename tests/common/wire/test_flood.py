"""Flood resistance (issue 17): junk and valid-looking floods on a link's key are counted, and
one poll never takes more than ``max_samples_per_poll`` samples, so the loop is not starved.
Behaviour only; the loop rate under a flood is bench/flood_bench.py's figure."""

from __future__ import annotations

import threading
import time
import uuid

import zenoh

from haptic.common.wire.link import Link
from haptic.common.wire.link_config import LinkConfig
from haptic.common.wire.messages import KIND_TOOL
from haptic.common.wire.ports import free_port as _free_port
from tests.helpers.attacks import flood, forged_payload


def _pair(max_samples: int):
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    prefix = f"test/{uuid.uuid4().hex[:8]}"
    master = LinkConfig(side="master", key_prefix=prefix, listen=(endpoint,),
                        congestion_control="block", stale_after_s=10.0,
                        max_samples_per_poll=max_samples)
    slave = LinkConfig(side="slave", key_prefix=prefix, connect=(endpoint,),
                       congestion_control="block", stale_after_s=10.0)
    return master, slave, endpoint


def _flooder(endpoint: str, key: str, payload, rate_hz: float, duration_s: float,
             sent: list[int]) -> threading.Thread:
    def run() -> None:
        config = zenoh.Config()
        config.insert_json5("connect/endpoints", f'["{endpoint}"]')
        config.insert_json5("scouting/multicast/enabled", "false")
        with zenoh.open(config) as session:
            time.sleep(0.3)  # let the subscription reach the flooder
            sent.append(flood(session, key, rate_hz, duration_s, payload))

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread


def test_junk_flood_is_counted_and_each_poll_is_bounded() -> None:
    master_config, slave_config, endpoint = _pair(max_samples=8)
    sent: list[int] = []
    with Link(master_config) as master, Link(slave_config) as slave:
        thread = _flooder(endpoint, master_config.subscribe_key, lambda i: bytes(50), 20000.0,
                          1.0, sent)
        largest_batch = 0
        delivered_tool = 0
        deadline = time.monotonic() + 20.0
        while thread.is_alive() and time.monotonic() < deadline:
            before = master.receive.stats().received
            if master.poll() is not None:
                delivered_tool += 1
            largest_batch = max(largest_batch, master.receive.stats().received - before)
            slave.poll()
            slave.send_tool((0.5, 0.0), (0.0, 0.0), (0.0, 0.0), 0.0, 0.0)
            time.sleep(0.0005)
        thread.join(timeout=10.0)
        for _ in range(2000):  # drain the rest
            master.poll()
        stats = master.stats()
    assert sent and sent[0] > 5000
    assert largest_batch <= 8
    assert master.capped_polls > 0
    assert stats.dropped["malformed"] > 1000  # junk counted, never a crash
    assert stats.dropped["malformed"] <= sent[0]
    assert delivered_tool > 0  # the real peer's messages still come through


def test_valid_looking_flood_is_counted_as_dropped() -> None:
    """Well-formed ToolStates from a stranger with ever new epochs and old send times: each
    is counted (out of order / stale), none replaces the real peer's data."""
    master_config, slave_config, endpoint = _pair(max_samples=64)
    sent: list[int] = []
    with Link(master_config) as master, Link(slave_config) as slave:
        start = time.monotonic()
        while not master.peer_alive and time.monotonic() - start < 10:
            master.poll()
            slave.poll()
            time.sleep(0.001)
        for _ in range(50):
            slave.send_tool((0.5, 0.0), (0.0, 0.0), (0.0, 0.0), 0.0, 0.0)
            time.sleep(0.001)
            master.poll()
        old_ns = time.time_ns() - 10**9
        thread = _flooder(endpoint, master_config.subscribe_key,
                          lambda i: forged_payload(KIND_TOOL, 99, i, 1e9, send_time_ns=old_ns),
                          5000.0, 0.5, sent)
        while thread.is_alive():
            master.poll()
            time.sleep(0.0005)
        thread.join(timeout=10.0)
        for _ in range(200):
            master.poll()
        stats = master.stats()
    assert sent and sent[0] > 500
    dropped = stats.dropped["out_of_order"] + stats.dropped["stale"]
    assert dropped > 100
    assert abs(master.latest.tool_force_N[0]) < 1.0  # the stranger's 1e9 N never delivered
