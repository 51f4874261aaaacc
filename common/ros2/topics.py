"""Which ROS 2 topics a side publishes, and their keys and liveliness tokens.

The master publishes what it measures (the handle), the slave what it computes (the tool
and the clay); both publish /tf for their own frame and /diagnostics. Relative names go
under the configured namespace (``/haptic/handle/wrench``); ``/tf`` and ``/diagnostics``
are absolute, as ROS tools expect.
"""

from __future__ import annotations

from dataclasses import dataclass

from haptic.common.ros2 import messages
from haptic.common.ros2.rmw_format import (
    NodeName,
    Qos,
    data_keyexpr,
    endpoint_gid,
    full_topic_name,
)

#: The ROS node of each side.
NODE_NAMES = {"master": "haptic_master", "slave": "haptic_slave"}
#: The device each side publishes: the handle (master) or the tool (slave).
DEVICES = {"master": "handle", "slave": "tool"}
#: /tf's QoS as tf2's broadcaster declares it (reliable, volatile, keep last 100).
TF_QOS = Qos(depth=100)
STATE_QOS = Qos(depth=10)


@dataclass(frozen=True)
class TopicSpec:
    """One publication: its ``group`` (``[ros2] topics``), ROS name relative to the
    namespace or absolute, message type and QoS."""

    group: str
    name: str
    type_name: str
    qos: Qos = STATE_QOS


@dataclass(frozen=True)
class Topic:
    """A declared publication: its spec, full ROS name, data key, liveliness key and GID."""

    spec: TopicSpec
    full_name: str
    key: str
    token: str
    gid: bytes


def side_topics(side: str, groups: frozenset[str], has_clay: bool) -> list[TopicSpec]:
    """The topics ``side`` (``master`` or ``slave``) publishes among ``groups``."""
    device = DEVICES[side]
    specs = [TopicSpec("wrench", f"{device}/wrench", messages.WRENCH),
             TopicSpec("pose", f"{device}/pose", messages.POSE),
             TopicSpec("tf", "/tf", messages.TF, TF_QOS),
             TopicSpec("diagnostics", "/diagnostics", messages.DIAGNOSTICS)]
    if side == "master":
        specs.append(TopicSpec("joint_states", "handle/joint_states", messages.JOINT_STATE))
    if has_clay:
        specs.append(TopicSpec("clay", "clay/points", messages.POINT_CLOUD, Qos(depth=1)))
    return [spec for spec in specs if spec.group in groups]


def declare_names(node: NodeName, specs: list[TopicSpec]) -> list[Topic]:
    """Each spec's full name, data key and publisher token (entity ids from node id + 1)."""
    topics = []
    for index, spec in enumerate(specs):
        full = full_topic_name(node.namespace, spec.name)
        type_hash = messages.type_hash(spec.type_name)
        token = node.endpoint_token(node.node_id + 1 + index, "MP", full, spec.type_name,
                                    type_hash, spec.qos)
        topics.append(Topic(spec, full, data_keyexpr(node.domain_id, full, spec.type_name,
                                                     type_hash), token, endpoint_gid(token)))
    return topics
