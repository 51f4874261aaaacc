"""The link over real Zenoh on loopback: two Link objects in this process, or a child process.
Every test uses its own port and key prefix; sessions are closed by the context managers."""

from __future__ import annotations

import json
import math
import signal
import sys
import textwrap
import time
import uuid

import pytest

from haptic.common.wire.injection import InjectionConfig
from haptic.common.wire.link import Link
from haptic.common.wire.messages import Flags, HandleState, ToolState
from haptic.common.wire.ports import free_port
from tests.helpers.link_helpers import configs, wait_for_peers
from tests.helpers.programs import Program

WAIT_S = 10.0


def drain(link: Link, until_s: float) -> list:
    got = []
    deadline = time.monotonic() + until_s
    while time.monotonic() < deadline:
        message = link.poll()
        if message is not None:
            got.append((message, link.receive.last_delivery_ns))
        time.sleep(0.0002)
    return got


def test_messages_flow_both_ways_with_presence():
    master_cfg, slave_cfg = configs()
    with Link(master_cfg) as master, Link(slave_cfg) as slave:
        wait_for_peers(master, slave)
        sent_handle = master.send_handle((1.5, -2.0), (0.01, 0.02), Flags.FORCES_ENABLED)
        sent_tool = slave.send_tool((3.0, 0.5), (0.011, 0.021), (0.04, 0.0), 0.25, 1e-7,
                                    Flags.IN_CONTACT)
        got_handle = [m for m, _ in drain(slave, 0.3)]
        got_tool = [m for m, _ in drain(master, 0.3)]
        assert got_handle == [sent_handle]
        assert got_tool == [sent_tool]
        assert isinstance(got_tool[0], ToolState) and got_tool[0].in_contact
        assert master.latest == sent_tool and master.silence_s() < WAIT_S
        stats = slave.stats()
        assert stats.delivered == 1 and stats.loss_ratio == 0.0
        assert 0.0 <= stats.one_way_delay_p50_s < 1.0
        with pytest.raises(TypeError):
            master.send(sent_tool)
    assert not master.is_open and not slave.is_open


def first_message(link: Link):
    deadline = time.monotonic() + WAIT_S
    while time.monotonic() < deadline:
        message = link.poll()
        if message is not None:
            return message
        time.sleep(0.0002)
    raise AssertionError("no message came")


@pytest.mark.parametrize("stamped", [True, False])
def test_delivery_time_is_a_measurement_only_with_an_arrival_stamp(stamped, monkeypatch):
    import haptic.common.wire.link as link_module

    if not stamped:  # as with a Zenoh without timestamp stacks
        monkeypatch.setattr(link_module, "_RECEIVE_POINT", None)
    elif link_module._RECEIVE_POINT is None:
        pytest.skip("this Zenoh has no timestamp instrumentation")
    master_cfg, slave_cfg = configs()
    with Link(master_cfg) as master, Link(slave_cfg) as slave:
        wait_for_peers(master, slave)
        master.send_handle((1.0, 0.0), (0.0, 0.0), Flags.FORCES_ENABLED)
        first_message(slave)
        assert slave.last_delivery_measured is stamped
        if stamped:  # Zenoh's stamp: before the poll that drained it
            assert slave.receive.last_delivery_ns < slave.last_poll_ns
        else:
            assert slave.receive.last_delivery_ns == slave.last_poll_ns


def test_peer_leaving_is_reported_by_liveliness():
    master_cfg, slave_cfg = configs()
    with Link(master_cfg) as master:
        with Link(slave_cfg) as slave:
            wait_for_peers(master, slave)
        deadline = time.monotonic() + WAIT_S
        while master.peer_alive:
            master.poll()
            assert time.monotonic() < deadline, "the slave's departure was not seen"
            time.sleep(0.001)
        assert [e.alive for e in master.presence_events] == [True, False]


def test_injected_delay_is_delivered_as_configured_over_zenoh():
    delay, jitter = 0.02, 0.005
    master_cfg, slave_cfg = configs(InjectionConfig(delay_s=delay, jitter_s=jitter))
    with Link(master_cfg) as master, Link(slave_cfg) as slave:
        wait_for_peers(master, slave)
        for _ in range(100):
            master.send_handle((0.0, 0.0), (0.0, 0.0))
            slave.poll()
            time.sleep(0.001)
        got = drain(slave, 0.2)
        stats = slave.stats()
    delays = [(delivery - m.send_time_ns) * 1e-9 for m, delivery in got]
    assert stats.delivered == 100 and stats.expected == 100
    # delivery time is max(arrival, send + delay + jitter draw): never early, and late only
    # when the real link took longer than the injected delay (it takes well under 1 ms here)
    assert min(delays) >= delay
    assert delay <= stats.one_way_delay_p50_s <= delay + jitter
    assert stats.one_way_delay_max_s <= delay + jitter + 0.05


def test_injected_loss_is_measured_back_over_zenoh():
    p, n = 0.2, 2000
    master_cfg, slave_cfg = configs(InjectionConfig(loss_probability=p))
    with Link(master_cfg) as master, Link(slave_cfg) as slave:
        wait_for_peers(master, slave)
        for _ in range(n):
            master.send_handle((0.0, 0.0), (0.0, 0.0))
            slave.poll()
            time.sleep(0.0001)
        drain(slave, 0.2)
        stats = slave.stats()
    injected = stats.dropped["injected_loss"]
    reached = stats.received
    tolerance = 4 * math.sqrt(p * (1 - p) / reached)
    assert abs(injected / reached - p) <= tolerance
    assert abs(stats.loss_ratio - p) <= tolerance + stats.network_loss_ratio
    assert stats.delivered + injected == reached


def test_restarted_peer_is_followed_by_its_new_epoch():
    master_cfg, slave_cfg = configs()
    with Link(slave_cfg) as slave:
        for epoch in (11, 12):
            with Link(master_cfg, epoch=epoch) as master:
                wait_for_peers(master, slave)
                for _ in range(5):
                    master.send_handle((0.0, 0.0), (0.0, 0.0))
                    time.sleep(0.001)
                got = drain(slave, 0.2)
                assert got and got[-1][0].epoch == epoch
            deadline = time.monotonic() + WAIT_S
            while slave.peer_alive:
                slave.poll()
                assert time.monotonic() < deadline
                time.sleep(0.001)
        stats = slave.stats()
    assert stats.peer_restarts == 1
    assert stats.delivered == 10 and stats.dropped["out_of_order"] == 0


def test_closed_link_refuses_io():
    master_cfg, _ = configs()
    link = Link(master_cfg)
    with link:
        pass
    link.close()  # idempotent
    with pytest.raises(RuntimeError):
        link.poll()
    with pytest.raises(RuntimeError):
        link.send(HandleState(0, 0, 0, Flags(0), (0.0, 0.0), (0.0, 0.0)))


CHILD = textwrap.dedent(
    """
    import json, sys
    from haptic.common.wire.link import Link
    from haptic.common.wire.link_config import LinkConfig
    from haptic.common.runtime.runner import RealTimeRunner
    config = LinkConfig(side="master", key_prefix=sys.argv[2], listen=(sys.argv[3],))
    with Link(config) as link:
        def step(tick, now):
            link.poll()
            link.send_handle((0.0, 0.0), (0.0, 0.0))
            if tick == 0:
                print("ready", flush=True)
        stats = RealTimeRunner(0.00054, step, show_status=False).run()
    summary = {**stats.as_summary(), "closed": not link.is_open}
    with open(sys.argv[1], "w") as f:
        json.dump(summary, f)
    """
)


def test_sigterm_ends_a_linked_node_cleanly(tmp_path):
    out = tmp_path / "summary.json"
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with Program([sys.executable, "-c", CHILD, str(out), f"test/{uuid.uuid4().hex[:10]}",
                  endpoint], env={"PYTHONUNBUFFERED": "1"}) as child:
        child.wait_for(r"^ready$", timeout_s=120.0)
        time.sleep(0.1)
        assert child.stop(signal.SIGTERM, grace_s=10.0) == 0, child.output()
    summary = json.loads(out.read_text())
    assert summary["stop_reason"] == "SIGTERM" and summary["closed"]


def test_slave_started_before_master_finds_it():
    master_cfg, slave_cfg = configs()
    with Link(slave_cfg) as slave:
        slave.poll()
        assert not slave.peer_alive
        time.sleep(0.2)
        with Link(master_cfg) as master:
            wait_for_peers(master, slave)  # zenoh retries the slave's connect endpoint
            sent = master.send_handle((0.5, 0.5), (0.0, 0.0))
            assert [m for m, _ in drain(slave, 0.2)] == [sent]


def test_the_peers_last_messages_come_before_its_leaving():
    """A backlog in the ring (polls capped at 8 samples) when the peer leaves: its token's
    going waits until what it sent before is taken, so its last message (an orderly end's
    STOPPING) is delivered at the latest with the poll that reports the leaving."""
    master_cfg, slave_cfg = configs(max_samples_per_poll=8)
    with Link(master_cfg) as master:
        with Link(slave_cfg) as slave:
            wait_for_peers(master, slave)
            for _ in range(60):
                slave.send_tool((0.5, 0.0), (0.0, 0.0), (0.0, 0.0), 0.0, 0.0)
            slave.send_tool((0.0, 0.0), (0.0, 0.0), (0.0, 0.0), 0.0, 0.0,
                            Flags.SAFE_STATE | Flags.STOPPING)
            time.sleep(0.2)  # everything is in the master's ring before the slave leaves
        time.sleep(0.5)  # and its token's going is too
        seen = []
        deadline = time.monotonic() + WAIT_S
        while master.peer_alive:
            message = master.poll()
            if message is not None:
                seen.append(message.flags)
            assert time.monotonic() < deadline, "the slave's departure was not seen"
        assert master.capped_polls >= 7  # 61 samples, 8 a poll
        assert seen and seen[-1] == Flags.SAFE_STATE | Flags.STOPPING
        assert [e.alive for e in master.presence_events] == [True, False]


def test_what_came_before_the_first_tick_is_discarded_undecoded():
    """The peer's messages from before this side's loop (its start-up backlog) are dropped
    without decoding; the next message is delivered as usual and the peer stays present."""
    master_cfg, slave_cfg = configs()
    with Link(master_cfg) as master, Link(slave_cfg) as slave:
        wait_for_peers(master, slave)
        for index in range(40):
            slave.send_tool((float(index), 0.0), (0.0, 0.0), (0.0, 0.0), 0.0, 0.0)
        deadline = time.monotonic() + WAIT_S
        discarded = 0
        while discarded < 40:  # the samples arrive in the ring over a few ms
            discarded += master.discard_received()
            assert time.monotonic() < deadline, f"only {discarded} of 40 arrived"
            time.sleep(0.001)
        assert discarded == 40 and master.discarded_before_start == 40
        assert master.receive.stats().delivered == 0  # none was decoded or counted
        assert master.discard_received() == 0
        sent = slave.send_tool((99.0, 0.0), (0.0, 0.0), (0.0, 0.0), 0.0, 0.0)
        assert first_message(master) == sent
        assert master.peer_alive
        assert master.summary()["link_discarded_before_start"] == 40
    with pytest.raises(RuntimeError, match="not open"):
        master.discard_received()
