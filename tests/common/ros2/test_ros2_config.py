"""The ``[ros2]`` table: defaults, every key's checks, the domain from ROS_DOMAIN_ID, and a
bad value as a one-line error naming the key with exit status 2."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from haptic.common.config import ConfigError, load_config, override
from haptic.common.ros2.settings import Ros2Settings, resolve_domain_id


def test_the_defaults_are_off_on_the_local_router() -> None:
    table = load_config()["ros2"]
    assert table == {"enabled": False, "domain_id": -1, "namespace": "/haptic",
                     "endpoint": "tcp/localhost:7447", "publish_rate_hz": 100.0,
                     "topics": "wrench,pose,joint_states,tf,diagnostics,clay"}
    settings = Ros2Settings.from_config(load_config(), environ={})
    assert settings.domain_id == 0 and settings.groups == {
        "wrench", "pose", "joint_states", "tf", "diagnostics", "clay"}


@pytest.mark.parametrize(("key", "value"), [
    ("ros2.domain_id", 233), ("ros2.domain_id", -2), ("ros2.publish_rate_hz", 0.5),
    ("ros2.publish_rate_hz", 5000.0), ("ros2.namespace", "haptic"),
    ("ros2.namespace", "/ha ptic"), ("ros2.namespace", "//x"), ("ros2.endpoint", "localhost"),
    ("ros2.topics", "wrench,velocity"), ("ros2.topics", ""), ("ros2.enabled", "yes"),
])
def test_each_bad_value_names_its_key(key: str, value: object) -> None:
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        override(load_config(), key, value)


def test_good_values_pass() -> None:
    config = override(load_config(), "ros2.namespace", "/")
    config = override(config, "ros2.namespace", "/lab/rig_2")
    config = override(config, "ros2.topics", "tf, clay")
    config = override(config, "ros2.domain_id", 232)
    settings = Ros2Settings.from_config(config)
    assert settings.groups == {"tf", "clay"} and settings.domain_id == 232


def test_the_domain_comes_from_ros_domain_id_when_not_set() -> None:
    assert resolve_domain_id(-1, {"ROS_DOMAIN_ID": "42"}) == 42
    assert resolve_domain_id(-1, {"ROS_DOMAIN_ID": " "}) == 0
    assert resolve_domain_id(5, {"ROS_DOMAIN_ID": "42"}) == 5
    for bad in ("233", "x", "-1"):
        with pytest.raises(ConfigError, match=r"ros2\.domain_id"):
            resolve_domain_id(-1, {"ROS_DOMAIN_ID": bad})


def test_a_bad_value_in_a_file_is_one_line_and_exit_status_2(tmp_path: Path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text("[ros2]\npublish_rate_hz = 0.0\n")
    result = subprocess.run([sys.executable, "-m", "haptic.common.analysis.cli",
                             "--print-config", "--config", str(path)],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "ros2.publish_rate_hz" in lines[0]


def test_ros2_with_a_bad_ros_domain_id_is_one_line_and_exit_status_2() -> None:
    import os

    for program in ("haptic.slave_sim.cli", "haptic.master.cli"):
        result = subprocess.run([sys.executable, "-m", program, "--ros2"],
                                capture_output=True, text=True, timeout=120,
                                env={**os.environ, "ROS_DOMAIN_ID": "999"})
        assert result.returncode == 2, (program, result.stderr[-2000:])
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and "ros2.domain_id" in lines[0] and "999" in lines[0]
