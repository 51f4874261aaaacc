"""Receiving a topic (common/ros2/subscriber.py) from an independent ROS 2-over-Zenoh writer
written here: its CDR by hand from the OMG rules, its attachment by zenoh-ext's serializer,
its keys from the design's text. The subscriber's token is visible, malformed samples are
dropped, gaps counted, and the age is what a watchdog reads."""

from __future__ import annotations

import struct
import time

from zenoh import ext

from haptic.common.ros2 import messages
from haptic.common.ros2.publisher import open_client_session
from haptic.common.ros2.rmw_format import NodeName
from haptic.common.ros2.subscriber import Ros2Subscription
from haptic.common.wire.ports import free_port
from tests.common.ros2.zenoh_graph import ros2_listener, zenoh_router

WRENCH_KEY = ("0/robot/wrench/geometry_msgs::msg::dds_::WrenchStamped_/"
              "RIHS01_8dc3deaf06b2ab281f9f9a742a8961c328ca7cec16e3fd6586d3a5c83fa78f77")


def _wrench_cdr(sec: int, nanosec: int, frame: str, force: tuple[float, float, float]) -> bytes:
    """WrenchStamped in little-endian CDR, by hand: header (int32, uint32, string), then six
    doubles aligned to 8 from the end of the encapsulation header."""
    body = struct.pack("<iI", sec, nanosec)
    name = frame.encode() + b"\0"
    body += struct.pack("<I", len(name)) + name
    body += b"\0" * ((-len(body)) % 8)
    body += struct.pack("<6d", *force, 0.0, 0.0, 0.0)
    return b"\x00\x01\x00\x00" + body


def _attachment(sequence: int, gid: bytes) -> bytes:
    return ext.z_serialize((ext.Int64(sequence), ext.Int64(time.time_ns()),
                            [ext.UInt8(byte) for byte in gid])).to_bytes()


def test_a_subscription_takes_the_newest_wrench_from_an_independent_writer() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with zenoh_router(endpoint), ros2_listener(endpoint) as graph:
        reader_session = open_client_session(endpoint)
        writer_session = open_client_session(endpoint)
        try:
            node = NodeName(0, str(reader_session.info.zid()), 0, "/", "haptic_slave")
            subscription = Ros2Subscription(reader_session, node, 1, "/robot/wrench",
                                            messages.WRENCH)
            assert subscription.key == WRENCH_KEY
            assert subscription.age_s() == float("inf") and subscription.newest() is None
            assert graph.wait(lambda g: subscription.token_key in g.alive_tokens(), 5.0)
            assert "/MS/%/%/haptic_slave/%robot%wrench/" in subscription.token_key
            writer = writer_session.declare_publisher(WRENCH_KEY)
            time.sleep(0.3)
            gid = bytes(range(16))
            writer.put(_wrench_cdr(5, 7, "tool", (1.0, 2.0, 3.0)),
                       attachment=_attachment(1, gid))
            writer.put(_wrench_cdr(5, 9, "tool", (9.0, 9.0, 9.0)))  # no attachment: dropped
            writer.put(_wrench_cdr(6, 0, "tool", (3.5, -0.5, 0.0)),
                       attachment=_attachment(4, gid))  # 2 and 3 lost
            deadline = time.monotonic() + 5.0
            while subscription.received < 2 and time.monotonic() < deadline:
                time.sleep(0.02)
            newest = subscription.newest()
            assert newest is not None and newest.sequence == 4 and newest.gid == gid
            force = newest.message.wrench.force
            assert (force.x, force.y, force.z) == (3.5, -0.5, 0.0)
            assert newest.message.header.frame_id == "tool"
            assert newest.message.header.stamp.sec == 6
            assert (subscription.received, subscription.malformed, subscription.lost) == (2, 1, 2)
            age = subscription.age_s()
            time.sleep(0.2)
            assert subscription.age_s() >= age + 0.2  # what a watchdog on the topic reads
            writer.undeclare()
            subscription.close()
            assert graph.wait(lambda g: subscription.token_key not in g.alive_tokens(), 5.0)
        finally:
            writer_session.close()
            reader_session.close()
