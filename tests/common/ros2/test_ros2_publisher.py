"""The ROS 2 publisher (common/ros2/publisher.py) through a Zenoh router on loopback: every
topic's samples decode with the independent CDR reader, keys, attachments and liveliness
tokens follow rmw_zenoh's format, the tokens go when it stops; a router that is not there
costs the loop nothing and is said once."""

from __future__ import annotations

import math
import time

import numpy as np

from haptic.common.ros2 import messages
from haptic.common.ros2.publisher import Ros2Publisher
from haptic.common.ros2.rmw_format import parse_attachment
from haptic.common.ros2.settings import Ros2Settings
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

ALL = frozenset({"wrench", "pose", "joint_states", "tf", "diagnostics", "clay"})
READERS = {"WrenchStamped_": read_wrench, "PoseStamped_": read_pose,
           "JointState_": read_joint_state, "TFMessage_": read_tf,
           "DiagnosticArray_": read_diagnostics, "PointCloud2_": read_point_cloud}


def _settings(endpoint: str, domain_id: int = 0) -> Ros2Settings:
    return Ros2Settings(domain_id, "/haptic", endpoint, 200.0, ALL)


def _feed(publisher: Ros2Publisher, seconds: float, side: str) -> float:
    """Offer states and statuses for ``seconds``; the largest time one offer took, s."""
    publisher.pace(1e-3)
    longest = 0.0
    start = time.monotonic()
    tick = 0
    while time.monotonic() - start < seconds:
        now_s = tick * 1e-3
        began = time.perf_counter()
        publisher.offer(tick, lambda now_s=now_s: {
            "time_s": now_s, "force_N": (3.6, -0.1), "position_m": (0.02 * now_s, 0.001),
            "effort_N": (3.5, 0.0)}, lambda: {
            "watchdog_state": "ok", "watchdog_trips": 0, "link_loss_ratio": 0.0,
            "safe_state": False, "side": side})
        longest = max(longest, time.perf_counter() - began)
        tick += 1
        time.sleep(1e-3)
    return longest


def _check_samples(samples: list[tuple[bytes, bytes | None]], key: str) -> None:
    reader = READERS[key.split("/")[-2].split("::")[-1]]
    sequences, gids = [], set()
    for payload, attached in samples:
        assert attached is not None
        sequence, stamp_ns, gid = parse_attachment(attached)
        assert abs(stamp_ns - time.time_ns()) < 60e9
        sequences.append(sequence)
        gids.add(gid)
        decoded = reader(payload)
        numbers = [value for value in _numbers(decoded)]
        assert numbers and all(math.isfinite(value) for value in numbers), key
    assert sequences == sorted(sequences) and len(set(sequences)) == len(sequences)
    assert sequences[0] >= 1 and len(gids) == 1


def _numbers(value: object) -> list[float]:
    if isinstance(value, dict):
        return [n for item in value.values() for n in _numbers(item)]
    if isinstance(value, (list, tuple)):
        return [n for item in value for n in _numbers(item)]
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return [float(value)]
    return []


def test_both_sides_publish_every_topic_in_rmw_zenohs_format() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    heights = np.full((64, 256), 0.01)
    with zenoh_router(endpoint), ros2_listener(endpoint, domain_id=3) as graph:
        master = Ros2Publisher(_settings(endpoint, 3), "master",
                               loop_counts=lambda: (1000, 0)).start()
        slave = Ros2Publisher(_settings(endpoint, 3), "slave", loop_counts=lambda: (1000, 1),
                              clay_source=lambda: heights,
                              clay_ranges=((0.0, 0.1), (0.0, 0.025))).start()
        try:
            assert master.connected.wait(10.0) and slave.connected.wait(10.0)
            assert graph.wait(lambda g: len(g.alive_tokens()) == 2 + 5 + 5, 10.0)
            _feed(master, 1.6, "master")  # the slave's state comes second: its own feed
            _feed(slave, 1.6, "slave")
        finally:
            master.stop()
            slave.stop()
        assert graph.wait(lambda g: not g.alive_tokens(), 10.0), "tokens withdrawn on stop"
    topics = {"/".join(key.split("/")[1:-2]) for key in graph.samples}
    assert topics == {"haptic/handle/wrench", "haptic/handle/pose", "haptic/handle/joint_states",
                      "haptic/tool/wrench", "haptic/tool/pose", "tf", "diagnostics",
                      "haptic/clay/points"}
    for key, samples in graph.samples.items():
        parts = key.split("/")
        assert parts[0] == "3" and parts[-1] == messages.type_hash(
            parts[-2].replace("::msg::dds_::", "/msg/").rstrip("_"))
        tf_or_diag = parts[1] in ("tf", "diagnostics")
        if not tf_or_diag:  # both sides publish /tf and /diagnostics: one GID each
            _check_samples(samples, key)
    nodes = {token.split("/")[-1] for token, _ in graph.tokens if "/NN/" in token}
    assert nodes == {"haptic_master", "haptic_slave"}
    diag_key = next(key for key in graph.samples if key.startswith("3/diagnostics/"))
    names = {read_diagnostics(payload)["status"][0]["name"]
             for payload, _ in graph.samples[diag_key]}
    assert names == {"haptic/master", "haptic/slave"}


def test_no_router_costs_the_loop_nothing_is_said_once_and_is_retried() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    said: list[str] = []
    publisher = Ros2Publisher(_settings(endpoint), "master", say=said.append).start()
    try:
        longest = _feed(publisher, 2.5, "master")  # more than one retry period
        assert publisher.open_failures >= 2 and len(said) == 1
        assert endpoint in said[0] and not publisher.connected.is_set()
        assert longest < 0.01
        with zenoh_router(endpoint), ros2_listener(endpoint) as graph:
            assert publisher.connected.wait(10.0), "the router came: the publisher joins it"
            _feed(publisher, 0.5, "master")
            assert graph.wait(lambda g: any("handle/wrench" in key for key in g.samples), 5.0)
            assert len(said) == 2 and "reached" in said[1]
    finally:
        began = time.monotonic()
        publisher.stop()
        assert time.monotonic() - began < 5.0
    assert publisher.figures["ros2_open_failures"] == publisher.open_failures
