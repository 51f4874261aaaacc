"""An emulated robot on ROS 2 over Zenoh, written for the tests from rmw_zenoh's design
alone (no code of common/ros2): its keys and liveliness tokens are spelled out here, its
CDR read and written by hand (tests/common/ros2/cdr_reader.py reads), its attachments made
by zenoh-ext's serializer.

The robot is a mass on a stiff velocity servo, non-back-drivable like the paper's tool
(m dv/dt = Kv (v_cmd - v) - f, solved exactly over each step), whose tool cuts a clay
workpiece of the scenario (the project's clay model stands for the real workpiece). It
steps once per velocity command it receives, by the slave's period, and answers each with
its contact force on the wrench topic.
"""

from __future__ import annotations

import json
import math
import struct
import threading
import time
from typing import Any

import numpy as np
import zenoh
from zenoh import ext

from tests.common.ros2.cdr_reader import read_twist

TWIST_TYPE = ("geometry_msgs::msg::dds_::TwistStamped_/"
              "RIHS01_5f0fcd4f81d5d06ad9b4c4c63e3ea51b82d6ae4d0558f1d475229b1121db6f64")
WRENCH_TYPE = ("geometry_msgs::msg::dds_::WrenchStamped_/"
               "RIHS01_8dc3deaf06b2ab281f9f9a742a8961c328ca7cec16e3fd6586d3a5c83fa78f77")


def wrench_cdr(stamp_ns: int, frame: str, force_x: float, force_y: float) -> bytes:
    """WrenchStamped, little-endian CDR, by hand."""
    body = struct.pack("<iI", stamp_ns // 1_000_000_000, stamp_ns % 1_000_000_000)
    name = frame.encode() + b"\0"
    body += struct.pack("<I", len(name)) + name
    body += b"\0" * ((-len(body)) % 8)
    return b"\x00\x01\x00\x00" + body + struct.pack("<6d", force_x, force_y, 0.0, 0.0, 0.0,
                                                    0.0)


class EmulatedRobot:
    """Follows ``<domain>/<namespace>/robot/cmd_twist`` and publishes its contact force on
    ``.../robot/wrench``; ``clay``: the project's clay model for the workpiece."""

    def __init__(self, endpoint: str, clay: Any, start_m: tuple[float, float], period_s: float,
                 namespace: str = "haptic", domain: int = 0, mass_kg: float = 2.0,
                 servo_N_s_per_m: float = 20000.0, silent_after: int | None = None) -> None:
        """``silent_after``: stop publishing the force after that many commands counted from
        the first that moves the tool (a robot whose driver hangs mid-cut, however long the
        programs took to start), while still taking commands."""
        config = zenoh.Config()
        config.insert_json5("mode", '"client"')
        config.insert_json5("connect/endpoints", json.dumps([endpoint]))
        config.insert_json5("scouting/multicast/enabled", "false")
        self.session = zenoh.open(config)
        zid = str(self.session.info.zid())
        lv = f"@ros2_lv/{domain}/{zid}/0"
        self.tokens = [self.session.liveliness().declare_token(f"{lv}/0/NN/%/%{namespace}/robot")]
        for entity, kind, topic, type_key in ((1, "MS", "cmd_twist", TWIST_TYPE),
                                              (2, "MP", "wrench", WRENCH_TYPE)):
            self.tokens.append(self.session.liveliness().declare_token(
                f"{lv}/{entity}/{kind}/%/%{namespace}/robot/%{namespace}%robot%{topic}/"
                f"{type_key}/::,10:,:,:,,"))
        self.publisher = self.session.declare_publisher(
            f"{domain}/{namespace}/robot/wrench/{WRENCH_TYPE}")
        self.clay, self.state = clay, clay.initial_state(1)
        self.position = np.array([start_m], float)
        self.velocity = np.zeros((1, 2))
        self.force = np.zeros(2)
        self.period_s, self.mass_kg, self.servo = period_s, mass_kg, servo_N_s_per_m
        self.gid = bytes(range(100, 116))
        self.sequence = 0
        self.commands = 0
        #: commands since the first non-zero one (the tool running)
        self.moving_commands = 0
        self.silent_after = silent_after
        self.bad_attachments = 0
        self.lock = threading.Lock()
        self.closed = False
        self.subscriber = self.session.declare_subscriber(
            f"{domain}/{namespace}/robot/cmd_twist/{TWIST_TYPE}", self._on_command)

    def _on_command(self, sample: Any) -> None:
        attached = sample.attachment
        if attached is None or len(attached.to_bytes()) != 33:
            self.bad_attachments += 1
            return
        linear = read_twist(sample.payload.to_bytes())["linear"]
        with self.lock:
            if self.closed:
                return
            self.commands += 1
            if self.moving_commands or any(value != 0.0 for value in linear[:2]):
                self.moving_commands += 1
            self._step(np.array(linear[:2]))

    def _step(self, command: np.ndarray) -> None:
        """One period: the servo towards ``command`` against the contact force, the cut."""
        decay = math.exp(-self.servo * self.period_s / self.mass_kg)
        target = command - self.force / self.servo
        previous = self.position.copy()
        start = self.velocity[0]
        end = target + (start - target) * decay
        # exact position of the first-order velocity response over the step
        self.position[0] += target * self.period_s + (start - target) * (1 - decay) * (
            self.mass_kg / self.servo)
        self.velocity[0] = end
        result = self.clay.step(self.state, previous, self.position.copy(),
                                self.velocity.copy())
        self.force = np.asarray(result.force_N[0], float)
        if self.silent_after is not None and self.moving_commands > self.silent_after:
            return
        stamp = time.time_ns()
        self.sequence += 1
        self.publisher.put(
            wrench_cdr(stamp, "robot_tool", float(self.force[0]), float(self.force[1])),
            attachment=ext.z_serialize((ext.Int64(self.sequence), ext.Int64(stamp),
                                        [ext.UInt8(b) for b in self.gid])).to_bytes())

    def close(self) -> None:
        """Undeclare everything and close the session (again: nothing). Under the lock, so no
        command's callback is publishing then (an undeclare of a publisher in use raises)."""
        with self.lock:
            if self.closed:
                return
            self.closed = True
        for entity in (self.subscriber, self.publisher, *self.tokens):
            entity.undeclare()
        self.session.close()
