"""End to end: ``haptic-session --ros2`` publishes both programs' topics to a Zenoh router on
loopback (what rmw_zenohd is to ROS 2); a client session receives every topic, decodes each
sample with the independent CDR reader, and sees both nodes' tokens come and go."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import pytest

from tests.common.ros2.cdr_reader import (
    read_diagnostics,
    read_joint_state,
    read_point_cloud,
    read_pose,
    read_tf,
    read_wrench,
)
from tests.common.ros2.zenoh_graph import free_port, ros2_listener, zenoh_router

READERS = {"WrenchStamped_": read_wrench, "PoseStamped_": read_pose,
           "JointState_": read_joint_state, "TFMessage_": read_tf,
           "DiagnosticArray_": read_diagnostics, "PointCloud2_": read_point_cloud}
TOPICS = {"haptic/handle/wrench", "haptic/handle/pose", "haptic/handle/joint_states",
          "haptic/tool/wrench", "haptic/tool/pose", "tf", "diagnostics", "haptic/clay/points"}


def _finite(value: object) -> bool:
    if isinstance(value, dict):
        return all(_finite(item) for item in value.values())
    if isinstance(value, (list, tuple)):
        return all(_finite(item) for item in value)
    return not isinstance(value, float) or math.isfinite(value)


@pytest.mark.slow
def test_a_session_with_ros2_publishes_every_topic(tmp_path: Path) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with zenoh_router(endpoint), ros2_listener(endpoint) as graph:
        process = subprocess.Popen(
            [sys.executable, "-m", "haptic.common.launch.cli", "--duration", "1.5",
             "--out", str(tmp_path), "--cpu-layout", "free", "--ros2", "--ros2-endpoint",
             endpoint], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            output, _ = process.communicate(timeout=400)
        finally:
            if process.poll() is None:
                process.kill()  # by its own PID; reaped below
            process.wait()
        assert process.returncode == 0, output[-3000:]
        assert graph.wait(lambda g: not g.alive_tokens(), 10.0), "tokens withdrawn at exit"
    assert {"/".join(key.split("/")[1:-2]) for key in graph.samples} == TOPICS
    for key, samples in graph.samples.items():
        reader = READERS[key.split("/")[-2].split("::")[-1]]
        assert all(attached is not None and len(attached) == 33 for _, attached in samples)
        assert all(_finite(reader(payload)) for payload, _ in samples), key
    handle = [read_wrench(payload)["force"] for payload, _ in
              next(v for k, v in graph.samples.items() if "/handle/wrench/" in k)]
    assert max(abs(force[0]) for force in handle) > 1.0  # the operator pushed the handle
    nodes = {token.split("/")[-1] for token, _ in graph.tokens if "/NN/" in token}
    assert nodes == {"haptic_master", "haptic_slave"}
    assert "ros2_published" in (tmp_path / "report.md").read_text()
