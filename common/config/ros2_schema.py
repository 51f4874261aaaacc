"""The ``[ros2]`` table's schema: publishing the run to a ROS 2 graph over rmw_zenoh
(plain data; docs/ros2.md, :mod:`haptic.common.ros2.settings` turns it into settings)."""

from __future__ import annotations

import re

from haptic.common.config.fields import Field, Schema

#: The topic groups ``topics`` may list (docs/ros2.md has the topics each one publishes).
ROS2_TOPIC_GROUPS = ("wrench", "pose", "joint_states", "tf", "diagnostics", "clay")
#: The highest ROS 2 domain id.
ROS2_MAX_DOMAIN_ID = 232

_NAME_PART = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")
_ENDPOINT = re.compile(r"^(tcp|udp|tls|quic|ws)/\S+:\d+$")


def _topics_check(text: str) -> str | None:
    names = [part.strip() for part in text.split(",")]
    unknown = [name for name in names if name not in ROS2_TOPIC_GROUPS]
    if not text.strip() or unknown:
        return (f"must list some of {', '.join(ROS2_TOPIC_GROUPS)}, comma-separated"
                f"{' (unknown: ' + ', '.join(repr(n) for n in unknown) + ')' if unknown else ''}")
    return None


def _namespace_check(text: str) -> str | None:
    parts = [part for part in text.strip("/").split("/") if part] if text.strip("/") else []
    if (text and not text.startswith("/")) or "//" in text or not all(
            _NAME_PART.match(part) for part in parts):
        return ("must be a ROS namespace: \"/\" or \"/name[/name...]\" of letters, digits "
                "and underscores, each name starting with a letter")
    return None


def _endpoint_check(text: str) -> str | None:
    if not _ENDPOINT.match(text):
        return "must be a Zenoh endpoint like \"tcp/localhost:7447\""
    return None


ROS2_SCHEMA: Schema = {
    "enabled": Field("bool", "Publish the run to ROS 2 (the programs' --ros2 turns it on)."),
    "domain_id": Field(
        "int", "ROS 2 domain id, 0..232; -1: the ROS_DOMAIN_ID environment variable, else 0.",
        minimum=-1, maximum=ROS2_MAX_DOMAIN_ID,
    ),
    "namespace": Field("str", "The nodes' ROS namespace; the relative topics go under it.",
                       check=_namespace_check),
    "endpoint": Field(
        "str", "The Zenoh router to join in client mode (rmw_zenohd's, tcp/localhost:7447).",
        check=_endpoint_check,
    ),
    "publish_rate_hz": Field(
        "float", "Rate of the state topics (wrench, pose, joint_states, tf), Hz; diagnostics "
        "go at 1 Hz and the clay at 2 Hz.", minimum=1.0, maximum=1000.0,
    ),
    "topics": Field("str", "The topic groups published, comma-separated: "
                    + ", ".join(ROS2_TOPIC_GROUPS) + ".", check=_topics_check),
}
