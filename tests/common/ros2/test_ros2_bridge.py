"""The ROS 2 bridge process (common/ros2/bridge.py, bridge_handle.py) through a Zenoh router
on loopback: a loop's offers reach ROS 2 as every topic, decoded by the independent CDR
reader, with the clay's point cloud; stopping it withdraws the tokens and keeps its counters;
no router is said once by the bridge and costs the offering loop nothing; a bridge whose
program is gone ends by itself."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from haptic.common.ros2.bridge_handle import Ros2Bridge
from haptic.common.ros2.settings import Ros2Settings
from tests.common.ros2.cdr_reader import read_point_cloud, read_wrench
from tests.common.ros2.zenoh_graph import free_port, ros2_listener, zenoh_router

ALL = frozenset({"wrench", "pose", "joint_states", "tf", "diagnostics", "clay"})
PERIOD_S = 1e-3


def _settings(endpoint: str) -> Ros2Settings:
    return Ros2Settings(0, "/haptic", endpoint, 200.0, ALL)


def _offer(bridge: Ros2Bridge, seconds: float) -> float:
    """Offer a loop's figures every PERIOD_S for ``seconds``; the longest offer, s."""
    longest = 0.0
    tick = 0
    start = time.monotonic()
    while time.monotonic() - start < seconds:
        now_s = tick * PERIOD_S
        began = time.perf_counter()
        bridge.offer(tick, lambda now_s=now_s: {
            "time_s": now_s, "force_N": (3.6, -0.1), "position_m": (0.02 * now_s, 0.001),
            "velocity_m_s": (0.02, 0.0)}, lambda: {
            "watchdog_state": "ok", "link_loss_ratio": 0.0, "safe_state": False})
        longest = max(longest, time.perf_counter() - began)
        tick += 1
        time.sleep(PERIOD_S)
    return longest


def test_a_bridge_publishes_the_offers_and_withdraws_its_tokens_on_stop() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    heights = np.full((16, 64), 0.01)
    heights[:, :8] = 0.004  # a cut at the left end
    said: list[str] = []
    with zenoh_router(endpoint), ros2_listener(endpoint) as graph:
        bridge = Ros2Bridge(_settings(endpoint), "slave", PERIOD_S, say=said.append,
                            loop_counts=lambda: (500, 0), clay_source=lambda: heights,
                            clay_ranges=((0.0, 0.1), (0.0, 0.025))).start()
        feed_path = bridge.feed.path
        try:
            assert graph.wait(lambda g: len(g.alive_tokens()) == 1 + 5, 60.0), "node and topics"
            _offer(bridge, 1.5)
            assert graph.wait(lambda g: any("clay/points" in key for key in g.samples), 10.0)
        finally:
            bridge.stop()
        assert graph.wait(lambda g: not g.alive_tokens(), 10.0), "tokens withdrawn on stop"
    figures = bridge.figures
    assert figures["ros2_connected"] and figures["ros2_published"] > 10
    assert figures["ros2_bridge_exit"] == 0 and not feed_path.exists()
    wrench_key = next(key for key in graph.samples if "/tool/wrench/" in key)
    assert {tuple(read_wrench(payload)["force"][:2]) for payload, _ in
            graph.samples[wrench_key]} == {(3.6, -0.1)}
    cloud_key = next(key for key in graph.samples if "/clay/points/" in key)
    cloud = read_point_cloud(graph.samples[cloud_key][-1][0])
    xyz = np.frombuffer(cloud["data"], dtype="<f4").reshape(-1, 3)
    assert len(xyz) > 0, "the clay's points"
    np.testing.assert_allclose(sorted(set(np.round(xyz[:, 2], 5))), [0.004, 0.01], rtol=1e-5)
    assert said == []


def test_no_router_is_said_by_the_bridge_and_costs_the_offers_nothing() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    bridge = Ros2Bridge(_settings(endpoint), "master", PERIOD_S, say=lambda _text: None,
                        loop_counts=lambda: (0, 0)).start()
    try:
        longest = _offer(bridge, 3.0)
    finally:
        bridge.stop()
    figures = bridge.figures
    assert figures["ros2_open_failures"] >= 1 and not figures["ros2_connected"]
    assert figures["ros2_bridge_exit"] == 0
    assert longest < 0.01  # struct writes; generous for a loaded machine


ORPHANING_PARENT = """
import sys, time
from haptic.common.ros2.bridge_handle import Ros2Bridge
from haptic.common.ros2.settings import Ros2Settings
bridge = Ros2Bridge(Ros2Settings(0, "/", sys.argv[1], 100.0, frozenset({"wrench"})),
                    "master", 1e-3, say=print, loop_counts=lambda: (0, 0)).start()
print(bridge._process.pid, bridge.feed.path, flush=True)
time.sleep(1.0)
import os
os._exit(0)  # gone without stopping its bridge
"""


def test_a_bridge_whose_program_is_gone_ends_by_itself() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    parent = subprocess.run([sys.executable, "-c", ORPHANING_PARENT, endpoint],
                            capture_output=True, text=True, timeout=120)
    bridge_pid, feed_path = int(parent.stdout.split()[0]), Path(parent.stdout.split()[1])
    deadline = time.monotonic() + 30.0
    while time.monotonic() < deadline and _alive(bridge_pid):
        time.sleep(0.1)
    assert not _alive(bridge_pid), "the orphaned bridge ended"
    assert not feed_path.exists(), "and removed the feed its program left"


def _alive(pid: int) -> bool:
    """Whether ``pid`` runs (the orphan is reaped by init, not by us)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    with open(f"/proc/{pid}/stat") as stat:
        return stat.read().split(") ")[1][0] != "Z"
