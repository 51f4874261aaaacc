"""A robot over ROS 2 as the slave's plant (``haptic-slave --plant ros2``, docs/ros2.md).

The slave node still runs Ch2/Ct2 and the tool's actuator plant Gt (the tool is
non-back-drivable, St = 0: the environment's force moves it only through Ct2), so the tool's
velocity each step is what Ch2/Ct2 command. :class:`RobotPlant` stands where the clay
stands (the node calls it as an environment): each step it publishes that velocity on a
TwistStamped topic for the robot to follow, and returns as ft the newest contact force the
robot reports on a WrenchStamped topic (the force the tool applies to the workpiece, N, x-y).

Watchdog: once the robot's force has come, the robot silent for more than ``watchdog_s``
while the slave commands it trips the plant: from then on it commands zero velocity (the
robot holds), reports no force, counts the trip and says so once. Silent while commanded:
no new force both for ``watchdog_s`` of wall time (monotonic clock) since the first command
sent after the newest force, and over more than ``watchdog_s`` of the slave's own commands
(commands left unanswered times the period ``period_s``). A stall of the slave's own process
(no steps, so no commands, its subscriber's thread starved with it) is the slave's lateness,
which its runner counts as skipped ticks, not the robot's silence: timed from the force's
arrival alone, one such stall on a loaded machine held a live robot for the rest of the run.
Before the first force the robot is taken as not touching anything (ft = 0) and is still
commanded.

The command is serialized by rosbags and published from the loop's thread (tens of us a
step); the force is deserialized only when a new sample came.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

from haptic.common.ros2 import messages
from haptic.common.ros2.rmw_format import NodeName, Qos, attachment, data_keyexpr, endpoint_gid
from haptic.common.ros2.rmw_format import full_topic_name as _full_name
from haptic.common.ros2.settings import Ros2Settings
from haptic.common.ros2.subscriber import Ros2Subscription
from haptic.slave_sim.clay.sim import ClayStepResult
from haptic.slave_sim.plant_options import RobotTopics

#: A force above this, N, counts as the tool cutting (the trace's ``cutting`` column).
CUTTING_FORCE_N = 0.05
COMMAND_QOS = Qos(reliability=2, depth=1)  # best effort, keep last 1: only the newest counts


class RobotPlant:
    """See the module docstring; ``session``: an open Zenoh client session (closed by the
    caller after :meth:`close`); ``period_s``: the slave's sample period, s."""

    kind = "ros2"

    def __init__(self, session: Any, settings: Ros2Settings, topics: RobotTopics,
                 period_s: float, say: Callable[[str], None] | None = None) -> None:
        self._say = say or (lambda text: print(f"haptic-slave: {text}", file=sys.stderr))
        self.topics = topics
        node = NodeName(settings.domain_id, str(session.info.zid()), 0, settings.namespace,
                        "haptic_slave_plant")
        command = _full_name(settings.namespace, topics.command)
        self.command_key = data_keyexpr(settings.domain_id, command, messages.TWIST,
                                        messages.type_hash(messages.TWIST))
        token = node.endpoint_token(1, "MP", command, messages.TWIST,
                                    messages.type_hash(messages.TWIST), COMMAND_QOS)
        self._gid = endpoint_gid(token)
        self._tokens = [session.liveliness().declare_token(node.node_token()),
                        session.liveliness().declare_token(token)]
        self._publisher = session.declare_publisher(self.command_key)
        self.force = Ros2Subscription(session, node, 2, _full_name(settings.namespace,
                                                                   topics.force),
                                      messages.WRENCH)
        self._command = messages.twist(0, "haptic_tool", (0.0, 0.0))
        self._sequence = 0
        self._force_N = np.zeros(2)
        self._force_sequence = -1
        #: monotonic time, s, of the first command sent after the newest force (None: none)
        self._unanswered_since_s: float | None = None
        #: commands sent since the newest force
        self._unanswered = 0
        self._watchdog_commands = topics.watchdog_s / period_s
        self.tripped = False
        self.trips = 0
        self.command_errors = 0

    def initial_state(self, lanes: int = 1) -> None:
        """The robot keeps its own state."""
        return None

    def step(self, state: Any, previous_xy: np.ndarray, position_xy: np.ndarray,
             velocity_xy: np.ndarray, acceleration_xy: np.ndarray) -> ClayStepResult:
        """Command the step's tool velocity (lane 0), return the robot's newest force."""
        now_s = time.monotonic()
        self._take_newest_force()
        self._check_watchdog(now_s)
        velocity = (0.0, 0.0) if self.tripped else (float(velocity_xy[0, 0]),
                                                    float(velocity_xy[0, 1]))
        self._send(velocity)
        self._unanswered += 1
        if self._unanswered_since_s is None:
            self._unanswered_since_s = now_s
        force_N = np.zeros((1, 2)) if self.tripped else self._force_N[None, :].copy()
        cutting = np.array([bool(np.hypot(*force_N[0]) > CUTTING_FORCE_N)])
        return ClayStepResult(force_N, cutting, cutting.astype(float), np.zeros(1),
                              np.zeros(1))

    def _take_newest_force(self) -> None:
        """A force newer than the last one taken: deserialized, kept, the robot answered."""
        if self.force.received == self._force_sequence:
            return
        newest = self.force.newest()
        if newest is None:
            return
        self._force_sequence = self.force.received
        force = newest.message.wrench.force
        self._force_N = np.array([force.x, force.y])
        self._unanswered_since_s, self._unanswered = None, 0

    def _check_watchdog(self, now_s: float) -> None:
        """Trip when, once a force has come, commands went unanswered for ``watchdog_s`` of
        wall time and of the slave's commands."""
        if self.tripped or self.force.received == 0 or self._unanswered_since_s is None:
            return
        silent_s = now_s - self._unanswered_since_s
        if silent_s > self.topics.watchdog_s and self._unanswered > self._watchdog_commands:
            self.tripped = True
            self.trips += 1
            self._say(f"robot watchdog: no force on {self.topics.force} for "
                      f"{silent_s * 1e3:.0f} ms ({self._unanswered} commands); the robot is "
                      "commanded to hold")

    def _send(self, velocity: tuple[float, float]) -> None:
        stamp_ns = time.time_ns()
        command = self._command
        command.header.stamp.sec, command.header.stamp.nanosec = divmod(stamp_ns,
                                                                        1_000_000_000)
        command.twist.linear.x, command.twist.linear.y = velocity
        self._sequence += 1
        try:
            self._publisher.put(messages.serialize(command, messages.TWIST),
                                attachment=attachment(self._sequence, stamp_ns, self._gid))
        except Exception:  # noqa: BLE001 - counted; the watchdog answers a lost robot
            self.command_errors += 1

    @property
    def figures(self) -> dict[str, Any]:
        """For the run summary."""
        return {"robot_watchdog_trips": self.trips, "robot_commands": self._sequence,
                "robot_forces_received": self.force.received,
                "robot_forces_lost": self.force.lost, "robot_command_errors":
                self.command_errors}

    def close(self) -> None:
        """A last zero-velocity command, then the tokens and the declarations go."""
        self._send((0.0, 0.0))
        self.force.close()
        for entity in (self._publisher, *self._tokens):
            try:
                entity.undeclare()
            except Exception:  # noqa: BLE001 - best effort while stopping
                pass


@contextmanager
def plant_for(args: Any, config: Any, node: Any) -> Iterator[RobotPlant | None]:
    """With ``--plant ros2``: the robot plant in ``node``'s environment's place, on a client
    session to the [ros2] endpoint, closed on exit (exit status 4 with one line when the
    router cannot be reached); otherwise nothing."""
    if getattr(args, "plant", "virtual") != "ros2":
        yield None
        return
    if not args.plant_watchdog > 0.0:
        print("haptic-slave: --plant-watchdog must be > 0 s", file=sys.stderr)
        raise SystemExit(2)
    from haptic.common.ros2.publisher import open_client_session

    settings = Ros2Settings.from_config(config)  # its protection was checked at start
    try:
        session = open_client_session(settings.endpoint)
    except Exception as error:  # noqa: BLE001 - one line, exit 4 (a link that cannot open)
        print(f"haptic-slave: --plant ros2: no Zenoh router at {settings.endpoint}: {error}",
              file=sys.stderr)
        raise SystemExit(4) from None
    try:
        plant = RobotPlant(session, settings, RobotTopics(
            args.plant_command_topic, args.plant_force_topic, args.plant_watchdog),
            node.sample_period_s)
        node.environment, node.environment_kind = plant, plant.kind
        try:
            yield plant
        finally:
            plant.close()
            print(f"haptic-slave: robot plant: {plant.figures}", file=sys.stderr)
    finally:
        session.close()
