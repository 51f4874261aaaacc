"""End to end: ``haptic-session --ros2`` publishes both programs' topics to a Zenoh router on
loopback (what rmw_zenohd is to ROS 2); a client session receives every topic, decodes each
sample with the independent CDR reader, and sees both nodes' tokens come and go."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from haptic.common.wire.ports import free_port
from tests.common.ros2.cdr_reader import (
    read_diagnostics,
    read_joint_state,
    read_point_cloud,
    read_pose,
    read_tf,
    read_wrench,
)
from tests.common.ros2.zenoh_graph import ros2_listener, zenoh_router
from tests.helpers.programs import Program, python_module

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
        with Program(python_module(
                "haptic.common.launch.cli", "--duration", "1.5", "--out", str(tmp_path),
                "--cpu-layout", "free", "--ros2", "--ros2-endpoint", endpoint)) as session:
            assert session.wait(timeout_s=400) == 0, session.output()[-3000:]
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
