"""Protected mode for the ROS 2 session: rmw_zenoh's router on this host is allowed, one on
another host only with --insecure, refused before any session opens (no traffic leaves)."""

from __future__ import annotations

import subprocess
import sys

import pytest

from haptic.common.model.errors import ConfigError
from haptic.common.ros2.options import require_ros2_protection


@pytest.mark.parametrize("endpoint", ["tcp/localhost:7447", "tcp/127.0.0.1:7447",
                                      "tcp/[::1]:7447"])
def test_a_router_on_this_host_is_allowed(endpoint: str) -> None:
    require_ros2_protection(endpoint, insecure=False)


@pytest.mark.parametrize("endpoint", ["tcp/192.168.1.20:7447", "tcp/0.0.0.0:7447",
                                      "tcp/rosbox.lab:7447"])
def test_a_router_on_another_host_is_refused_unless_insecure(endpoint: str) -> None:
    with pytest.raises(ConfigError, match="link.security.*--insecure"):
        require_ros2_protection(endpoint, insecure=False)
    require_ros2_protection(endpoint, insecure=True)


@pytest.mark.parametrize("program", ["haptic.master.cli", "haptic.slave_sim.cli"])
def test_the_programs_refuse_it_in_one_line_with_status_2(program: str) -> None:
    """The refusal comes at option checking, before Warp, the rig or any Zenoh session."""
    result = subprocess.run(
        [sys.executable, "-m", program, "--ros2", "--ros2-endpoint", "tcp/192.168.1.20:7447",
         "--duration", "0.1"], capture_output=True, text=True, timeout=120)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "protected mode" in lines[0] and "--insecure" in lines[0]


def test_the_robot_plant_is_held_to_it_too() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "haptic.slave_sim.cli", "--plant", "ros2", "--ros2-endpoint",
         "tcp/192.168.1.20:7447", "--duration", "0.1"],
        capture_output=True, text=True, timeout=120)
    assert result.returncode == 2, result.stderr
    assert "protected mode" in result.stderr and "--insecure" in result.stderr
