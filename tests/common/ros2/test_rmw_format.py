"""rmw_zenoh's wire format (common/ros2/rmw_format.py) against ros2/rmw_zenoh's design and
source, and the RIHS01 hashes against the values ROS 2 itself prints."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from haptic.common.ros2 import messages
from haptic.common.ros2.rmw_format import (
    ATTACHMENT_SIZE,
    NodeName,
    Qos,
    attachment,
    data_keyexpr,
    dds_type_name,
    endpoint_gid,
    full_topic_name,
    mangle,
    parse_attachment,
    qos_keyexpr,
)
from tests.common.ros2.cdr_reader import (
    read_diagnostics,
    read_joint_state,
    read_point_cloud,
    read_pose,
    read_tf,
    read_twist,
    read_wrench,
)

#: The hashes ROS 2 prints for these types (``ros2 topic info --verbose``, "Topic type
#: hash"; the same in the type description files of Jazzy, Kilted and Rolling).
PUBLISHED_HASHES = {
    messages.WRENCH: "RIHS01_8dc3deaf06b2ab281f9f9a742a8961c328ca7cec16e3fd6586d3a5c83fa78f77",
    messages.POSE: "RIHS01_10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8",
    messages.JOINT_STATE:
        "RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e",
    messages.TF: "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087",
    messages.DIAGNOSTICS:
        "RIHS01_5a8a36efb05fb25070fa0fb3810290c0e6cd4862b54a8fb975a1ee8dc55a333e",
    messages.POINT_CLOUD:
        "RIHS01_9198cabf7da3796ae6fe19c4cb3bdd3525492988c70522628af5daa124bae2b5",
    messages.TWIST: "RIHS01_5f0fcd4f81d5d06ad9b4c4c63e3ea51b82d6ae4d0558f1d475229b1121db6f64",
}


@pytest.mark.parametrize("type_name", sorted(PUBLISHED_HASHES))
def test_each_type_hash_is_the_published_one(type_name: str) -> None:
    assert messages.type_hash(type_name) == PUBLISHED_HASHES[type_name]


def test_the_data_key_follows_the_design() -> None:
    key = data_keyexpr(0, "/haptic/handle/wrench", messages.WRENCH,
                       PUBLISHED_HASHES[messages.WRENCH])
    assert key == ("0/haptic/handle/wrench/geometry_msgs::msg::dds_::WrenchStamped_/"
                   + PUBLISHED_HASHES[messages.WRENCH])
    assert data_keyexpr(7, "/tf", messages.TF, PUBLISHED_HASHES[messages.TF]).startswith(
        "7/tf/tf2_msgs::msg::dds_::TFMessage_/RIHS01_")
    assert dds_type_name("sensor_msgs/msg/PointCloud2") == "sensor_msgs::msg::dds_::PointCloud2_"
    with pytest.raises(ValueError):
        data_keyexpr(0, "/tf", messages.TF, "TypeHashNotSupported")


def test_the_attachment_is_what_the_zenoh_serializer_makes_of_int64_int64_array16() -> None:
    gid = bytes(range(16))
    data = attachment(1, 1_700_000_000_123_456_789, gid)
    assert len(data) == ATTACHMENT_SIZE == 33
    # by hand: little-endian int64, int64, LEB128 length 16, the 16 bytes
    assert data == (struct.pack("<q", 1) + struct.pack("<q", 1_700_000_000_123_456_789)
                    + b"\x10" + gid)
    # and as zenoh-ext serializes the C++ AttachmentData (int64, int64, array<uint8, 16>)
    from zenoh import ext

    expected = ext.z_serialize((ext.Int64(1), ext.Int64(1_700_000_000_123_456_789),
                                [ext.UInt8(byte) for byte in gid])).to_bytes()
    assert data == expected
    assert parse_attachment(data) == (1, 1_700_000_000_123_456_789, gid)
    with pytest.raises(ValueError):
        parse_attachment(data[:-1])


def test_names_are_mangled_and_qos_strings_leave_defaults_empty() -> None:
    assert mangle("/haptic/handle/wrench") == "%haptic%handle%wrench"
    assert mangle("/") == "%" and mangle("") == "%"
    assert qos_keyexpr(Qos(reliability=2, depth=1)) == "2::,1:,:,:,,"  # best effort, last 1
    assert qos_keyexpr(Qos(depth=10)) == "::,10:,:,:,,"  # reliable, volatile, keep last 10
    assert qos_keyexpr(Qos(depth=42)) == "::,:,:,:,,"  # every field rmw_zenoh's default
    assert qos_keyexpr(Qos(durability=1, history=2, depth=42)) == ":1:2,:,:,:,,"
    assert full_topic_name("/haptic", "handle/pose") == "/haptic/handle/pose"
    assert full_topic_name("/", "handle/pose") == "/handle/pose"
    assert full_topic_name("/haptic", "/tf") == "/tf"


def test_liveliness_tokens_follow_the_design() -> None:
    node = NodeName(3, "4f3c2a1b", 0, "/haptic", "haptic_master")
    assert node.node_token() == "@ros2_lv/3/4f3c2a1b/0/0/NN/%/%haptic/haptic_master"
    token = node.endpoint_token(2, "MP", "/haptic/handle/wrench", messages.WRENCH,
                                PUBLISHED_HASHES[messages.WRENCH], Qos(depth=10))
    assert token == ("@ros2_lv/3/4f3c2a1b/0/2/MP/%/%haptic/haptic_master/%haptic%handle%wrench/"
                     "geometry_msgs::msg::dds_::WrenchStamped_/"
                     + PUBLISHED_HASHES[messages.WRENCH] + "/::,10:,:,:,,")
    parts = token.split("/")
    assert len(parts) == 13 and all(parts)  # rmw_zenoh rejects empty chunks
    root = NodeName(0, "ab", 0, "/", "n")
    assert root.node_token() == "@ros2_lv/0/ab/0/0/NN/%/%/n"
    assert root.endpoint_token(1, "MS", "/tf", messages.TF, PUBLISHED_HASHES[messages.TF],
                               Qos(depth=100)).split("/")[5] == "MS"
    with pytest.raises(ValueError):
        root.endpoint_token(1, "XX", "/tf", messages.TF, PUBLISHED_HASHES[messages.TF], Qos())
    assert endpoint_gid(token) == endpoint_gid(token) and len(endpoint_gid(token)) == 16
    assert endpoint_gid(token) != endpoint_gid(token.replace("/2/MP", "/3/MP"))


STAMP_NS = 1_765_000_000_250_000_001


def test_each_message_decodes_with_an_independent_cdr_reader() -> None:
    def cdr(message, type_name: str) -> bytes:
        payload = messages.serialize(message, type_name)
        assert payload[:4] == b"\x00\x01\x00\x00"
        return payload

    wrench = read_wrench(cdr(messages.wrench(STAMP_NS, "haptic_handle", (3.6, -0.5)),
                             messages.WRENCH))
    assert wrench == {"header": (1_765_000_000, 250_000_001, "haptic_handle"),
                      "force": (3.6, -0.5, 0.0), "torque": (0.0, 0.0, 0.0)}
    pose = read_pose(cdr(messages.pose(STAMP_NS, (0.01, 0.02)), messages.POSE))
    assert pose["position"] == (0.01, 0.02, 0.0) and pose["orientation"] == (0, 0, 0, 1.0)
    assert pose["header"][2] == "world"
    joints = read_joint_state(cdr(messages.joint_state(
        STAMP_NS, ("handle_x", "handle_y"), (0.1, 0.2), (0.3, 0.4), (0.5, 0.6)),
        messages.JOINT_STATE))
    assert joints["name"] == ["handle_x", "handle_y"]
    assert (joints["position"], joints["velocity"], joints["effort"]) == (
        [0.1, 0.2], [0.3, 0.4], [0.5, 0.6])
    tf = read_tf(cdr(messages.tf(STAMP_NS, {"haptic_handle": (0.1, 0.2),
                                             "haptic_tool": (0.3, 0.4)}), messages.TF))
    assert [(t["child"], t["translation"]) for t in tf] == [
        ("haptic_handle", (0.1, 0.2, 0.0)), ("haptic_tool", (0.3, 0.4, 0.0))]
    diag = read_diagnostics(cdr(messages.diagnostics(
        STAMP_NS, "haptic/master", "haptic-master", 1, "watchdog tripped",
        {"loop_rate_hz": 1851.25, "watchdog_state": "tripped", "trips": 2}),
        messages.DIAGNOSTICS))
    assert diag["status"] == [{"level": 1, "name": "haptic/master",
                               "message": "watchdog tripped", "hardware_id": "haptic-master",
                               "values": {"loop_rate_hz": "1851.25",
                                          "watchdog_state": "tripped", "trips": "2"}}]
    twist = read_twist(cdr(messages.twist(STAMP_NS, "tool", (0.038, 0.0)), messages.TWIST))
    assert twist["linear"] == (0.038, 0.0, 0.0)


def test_the_clay_point_cloud_decodes_to_the_height_map() -> None:
    heights = np.zeros((2, 4))
    heights[0, 1], heights[1, 3] = 0.01, 0.02  # two cells with clay
    points = messages.height_points(heights, (0.0, 0.04), (0.0, 0.02))
    cloud = read_point_cloud(messages.serialize(messages.point_cloud(STAMP_NS, points),
                                                messages.POINT_CLOUD))
    assert cloud["fields"] == [("x", 0, 7, 1), ("y", 4, 7, 1), ("z", 8, 7, 1)]  # FLOAT32
    assert (cloud["height"], cloud["width"], cloud["point_step"]) == (1, 2, 12)
    assert not cloud["is_bigendian"] and cloud["row_step"] == 24
    xyz = np.frombuffer(cloud["data"], dtype="<f4").reshape(-1, 3)
    np.testing.assert_allclose(xyz, [[0.015, 0.005, 0.01], [0.035, 0.015, 0.02]], rtol=1e-6)
