"""The validated ``[ros2]`` table as :class:`Ros2Settings` (common/config/ros2_schema.py)."""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from haptic.common.config.ros2_schema import ROS2_MAX_DOMAIN_ID
from haptic.common.model.errors import ConfigError


def resolve_domain_id(configured: int, environ: Mapping[str, str] | None = None) -> int:
    """``configured`` when 0..232; for -1, ``ROS_DOMAIN_ID`` (ConfigError naming
    ``ros2.domain_id`` when it is not an id), else 0."""
    if configured >= 0:
        return configured
    text = (os.environ if environ is None else environ).get("ROS_DOMAIN_ID", "").strip()
    if not text:
        return 0
    if not text.isdigit() or int(text) > ROS2_MAX_DOMAIN_ID:
        raise ConfigError("ros2.domain_id", f"is -1 (from ROS_DOMAIN_ID), but ROS_DOMAIN_ID="
                          f"{text!r} is not a domain id 0..{ROS2_MAX_DOMAIN_ID}")
    return int(text)


@dataclass(frozen=True)
class Ros2Settings:
    """Where and what to publish: ``domain_id`` 0..232, the nodes' ``namespace``, the
    router's Zenoh ``endpoint``, the state topics' ``publish_rate_hz`` (Hz) and the topic
    ``groups``."""

    domain_id: int
    namespace: str
    endpoint: str
    publish_rate_hz: float
    groups: frozenset[str]

    @classmethod
    def from_config(cls, config: Mapping[str, Any],
                    environ: Mapping[str, str] | None = None) -> Ros2Settings:
        table = config["ros2"]
        return cls(resolve_domain_id(int(table["domain_id"]), environ),
                   table["namespace"] or "/", table["endpoint"],
                   float(table["publish_rate_hz"]),
                   frozenset(part.strip() for part in table["topics"].split(",")))
