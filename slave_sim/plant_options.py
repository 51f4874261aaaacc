"""haptic-slave's plant options (``--plant``, the robot's topics): argparse only, so the
command line answers before the node's modules load (slave_sim/robot_plant.py)."""

from __future__ import annotations

import argparse
from dataclasses import dataclass


@dataclass(frozen=True)
class RobotTopics:
    """The robot's topics (relative to the namespace or absolute) and the watchdog, s."""

    command: str = "robot/cmd_twist"
    force: str = "robot/wrench"
    watchdog_s: float = 0.05


def add_plant_options(parser: argparse.ArgumentParser) -> None:
    """``--plant`` and the robot's topics (haptic-slave)."""
    group = parser.add_argument_group("plant (docs/ros2.md, 'A robot as the plant')")
    group.add_argument("--plant", choices=("virtual", "ros2"), default="virtual",
                       help="virtual (default): the simulated tool and clay; ros2: a robot "
                       "over ROS 2 follows the tool's velocity and reports its contact force")
    defaults = RobotTopics()
    group.add_argument("--plant-command-topic", default=defaults.command, metavar="TOPIC",
                       help="the robot's TwistStamped velocity command (default "
                       f"{defaults.command}, under the [ros2] namespace)")
    group.add_argument("--plant-force-topic", default=defaults.force, metavar="TOPIC",
                       help=f"the robot's WrenchStamped contact force (default {defaults.force})")
    group.add_argument("--plant-watchdog", type=float, default=defaults.watchdog_s,
                       metavar="S", help="hold the robot when its force is older than this, s "
                       f"(default {defaults.watchdog_s:g})")
