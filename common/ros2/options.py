"""The programs' ROS 2 options (``--ros2``, ``--ros2-endpoint``) and the publisher a
program starts from its configuration."""

from __future__ import annotations

import argparse
from collections.abc import Callable, Mapping
from typing import Any

from haptic.common.config import override
from haptic.common.ros2.settings import Ros2Settings


def add_ros2_options(parser: argparse.ArgumentParser) -> None:
    """``--ros2`` and ``--ros2-endpoint`` (docs/ros2.md)."""
    group = parser.add_argument_group("ROS 2 (docs/ros2.md)")
    group.add_argument("--ros2", action="store_true",
                       help="publish the run to ROS 2 through rmw_zenoh's router "
                       "(ros2.enabled = true)")
    group.add_argument("--ros2-endpoint", metavar="ENDPOINT",
                       help="the Zenoh router to join, e.g. tcp/localhost:7447 "
                       "(ros2.endpoint)")


def apply_ros2_options(config: dict[str, Any], args: argparse.Namespace) -> dict[str, Any]:
    """``config`` with the options applied; checks ``[ros2]`` when enabled (ConfigError
    naming the key, e.g. a ROS_DOMAIN_ID that is not a domain id)."""
    if getattr(args, "ros2", False):
        config = override(config, "ros2.enabled", True)
    if getattr(args, "ros2_endpoint", None) is not None:
        config = override(config, "ros2.endpoint", args.ros2_endpoint)
    if config["ros2"]["enabled"]:
        settings = Ros2Settings.from_config(config)
        insecure = bool(config["link"]["security"]["insecure"] or getattr(args, "insecure", None))
        require_ros2_protection(settings.endpoint, insecure)
    return config


#: What to do when the ROS 2 session would reach other hosts: rmw_zenoh's router has no
#: session key of ours, so only the user's word lets it run.
ROS2_WAYS_OUT = ("run rmw_zenohd on this host and join it on loopback (--ros2-endpoint "
                 "tcp/localhost:7447), or say --insecure ([link.security] insecure = true)")


def require_ros2_protection(endpoint: str, insecure: bool) -> None:
    """Protected mode for the ROS 2 session: a router on another host is refused (a
    ConfigError naming ``link.security``, before any session opens) unless ``insecure``:
    whoever reaches that router can read the run and, with ``--plant ros2``, push the tool
    with a forged force."""
    from haptic.common.ros2.publisher import client_config
    from haptic.common.wire.protected_mode import require_protection

    require_protection(client_config(endpoint), session_key=False, insecure=insecure,
                       ways_out=ROS2_WAYS_OUT)


def start_ros2(config: Mapping[str, Any], side: str, period_s: float, *,
               say: Callable[[str], None], loop_counts: Callable[[], tuple[int, int]],
               clay_source: Callable[[], Any] | None = None,
               clay_ranges: tuple[tuple[float, float], tuple[float, float]] | None = None,
               ) -> Any:
    """The started :class:`~haptic.common.ros2.bridge_handle.Ros2Bridge` of ``side`` (the
    ROS 2 session in a process of its own, fed at the loop's ``period_s``, s), or None when
    ``[ros2] enabled`` is false."""
    if not config["ros2"]["enabled"]:
        return None
    from haptic.common.ros2.bridge_handle import Ros2Bridge

    settings = Ros2Settings.from_config(config)
    say(f"ros2: publishing to {settings.endpoint} (domain {settings.domain_id}, namespace "
        f"{settings.namespace})")
    return Ros2Bridge(settings, side, period_s, say=lambda text: say(f"ros2: {text}"),
                      loop_counts=loop_counts, clay_source=clay_source,
                      clay_ranges=clay_ranges, say_prefix=f"haptic-{side}: ros2: ").start()


def forwarded_ros2_args(args: argparse.Namespace) -> list[str]:
    """The ROS 2 options given to ``haptic-session``, for both programs."""
    forwarded = ["--ros2"] if getattr(args, "ros2", False) else []
    if getattr(args, "ros2_endpoint", None) is not None:
        forwarded += ["--ros2-endpoint", args.ros2_endpoint]
    return forwarded
