"""Publishing a side's run to ROS 2 over rmw_zenoh, off the control loop.

A :class:`Ros2Publisher` owns a thread and its own Zenoh session, opened in client mode to
the configured router (rmw_zenohd's, ``tcp/localhost:7447``). The loop hands it plain
figures, as it does to the live view's feed (common/runtime/display.py): :meth:`offer_state`
every :meth:`state_every` ticks and :meth:`offer_status` every :meth:`status_every` ticks,
each a reference swap; no encoding, no I/O and no lock in the loop. The thread declares the
node's and each publisher's liveliness tokens (so ``ros2 node list`` and ``ros2 topic
list`` show them), then publishes the newest state at ``publish_rate_hz``, /diagnostics at
:data:`DIAGNOSTICS_RATE_HZ` and the clay at :data:`CLAY_RATE_HZ`, each sample with
rmw_zenoh's attachment. Nothing is serialized for a topic no subscriber matches.

A router that is not there costs the loop nothing: the thread says so once, counts the
failed attempts (``ros2_open_failures``) and tries again every :data:`RETRY_S`. The session
is closed, and the tokens withdrawn, by :meth:`stop`.

State figures (``offer_state``; SI units): ``time_s`` (the loop's time, s), ``force_N``
and ``position_m`` (x, y of the side's device), optionally ``velocity_m_s`` and, on the
master, ``effort_N`` (the force the drives present, N). Status figures (``offer_status``):
any scalars (link delay and loss, watchdog state and trips, passivity account, events);
``safe_state`` true makes the diagnostic an ERROR, a watchdog state other than ``ok`` a
WARN.
"""

from __future__ import annotations

import json
import math
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from haptic.common.ros2 import messages
from haptic.common.ros2.rmw_format import NodeName, attachment
from haptic.common.ros2.settings import Ros2Settings
from haptic.common.ros2.topics import DEVICES, NODE_NAMES, Topic, declare_names, side_topics

DIAGNOSTICS_RATE_HZ = 1.0
CLAY_RATE_HZ = 2.0
#: Between two attempts to reach the router, s.
RETRY_S = 2.0
#: The clay's point cloud: at most this many cells along x and y (block means).
CLAY_MAX_CELLS = (128, 32)

ClaySource = Callable[[], "np.ndarray | None"]


def client_config(endpoint: str) -> Any:
    """The ``zenoh.Config`` of a client-mode session to ``endpoint``: no listener, no
    scouting, so it reaches that router and nothing else."""
    import zenoh

    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([endpoint]))
    config.insert_json5("listen/endpoints", "[]")
    config.insert_json5("scouting/multicast/enabled", "false")
    return config


def open_client_session(endpoint: str) -> Any:
    """A Zenoh session in client mode to ``endpoint`` (:func:`client_config`); raises if the
    router cannot be reached."""
    import zenoh

    return zenoh.open(client_config(endpoint))


class Ros2Publisher:
    """See the module docstring. ``side``: ``master`` or ``slave``; ``say``: one line for
    the user (stderr by default); ``loop_counts()``: the loop's ticks and overruns so far
    (any thread); ``clay_source()``: the (cells_y, cells_x) height map in m over
    ``clay_ranges`` ((x0, x1), (y0, y1)) in m, or None."""

    def __init__(self, settings: Ros2Settings, side: str, *,
                 say: Callable[[str], None] | None = None,
                 loop_counts: Callable[[], tuple[int, int]] | None = None,
                 clay_source: ClaySource | None = None,
                 clay_ranges: tuple[tuple[float, float], tuple[float, float]] | None = None,
                 open_session: Callable[[str], Any] = open_client_session) -> None:
        self.settings = settings
        self.side = side
        self._say = say or (lambda text: print(f"ros2: {text}", file=sys.stderr))
        self._loop_counts = loop_counts
        self._clay_source = clay_source
        self._clay_ranges = clay_ranges
        self._open_session = open_session
        self._state: dict[str, Any] | None = None
        self._status: dict[str, Any] = {}
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.connected = threading.Event()
        self.open_failures = 0
        self.published: dict[str, int] = {}
        self.unwatched_skips = 0
        self.publish_errors = 0
        self._sequence: dict[str, int] = {}
        self._last_counts: tuple[float, int] | None = None
        self._every = (1, 1)

    def state_every(self, period_s: float) -> int:
        """Ticks of ``period_s`` between two :meth:`offer_state` calls."""
        return max(1, round(1.0 / (self.settings.publish_rate_hz * period_s)))

    def status_every(self, period_s: float) -> int:
        """Ticks of ``period_s`` between two :meth:`offer_status` calls."""
        return max(1, round(1.0 / (DIAGNOSTICS_RATE_HZ * period_s)))

    def pace(self, period_s: float) -> Ros2Publisher:
        """Set the loop's period, s, for :meth:`offer`."""
        self._every = (self.state_every(period_s), self.status_every(period_s))
        return self

    def offer(self, tick: int, state: Callable[[], dict[str, Any]],
              status: Callable[[], dict[str, Any]]) -> None:
        """From the loop, each tick: ``state()`` every :meth:`state_every` ticks and
        ``status()`` every :meth:`status_every` ticks (neither built on the others)."""
        state_every, status_every = self._every
        if tick % state_every == 0:
            self._state = state()
        if tick % status_every == 0:
            self._status = status()

    def offer_state(self, state: dict[str, Any]) -> None:
        """From the loop: the newest state figures (a reference swap)."""
        self._state = state

    def offer_status(self, figures: dict[str, Any]) -> None:
        """From the loop: the newest status figures (a reference swap)."""
        self._status = figures

    def start(self) -> Ros2Publisher:
        self._thread = threading.Thread(target=self._run, name=f"ros2-{self.side}",
                                        daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Withdraw the tokens, close the session and end the thread (within 5 s)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None

    def __enter__(self) -> Ros2Publisher:
        return self.start()

    def __exit__(self, *_exc: object) -> None:
        self.stop()

    @property
    def figures(self) -> dict[str, Any]:
        """For the run summary: samples published, topics skipped unwatched, failures."""
        return {"ros2_published": sum(self.published.values()),
                "ros2_unwatched_skips": self.unwatched_skips,
                "ros2_open_failures": self.open_failures,
                "ros2_publish_errors": self.publish_errors,
                "ros2_connected": self.connected.is_set()}

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                session = self._open_session(self.settings.endpoint)
            except Exception as error:  # noqa: BLE001 - no router: said once, retried
                self.open_failures += 1
                if self.open_failures == 1:
                    self._say(f"no Zenoh router at {self.settings.endpoint} ({error}); "
                              f"retrying every {RETRY_S:g} s (ros2 run rmw_zenoh_cpp "
                              "rmw_zenohd starts one)")
                self._stop.wait(RETRY_S)
                continue
            try:
                self._serve(session)
            finally:
                try:
                    session.close()
                except Exception:  # noqa: BLE001 - best effort while stopping
                    pass
            return

    def _serve(self, session: Any) -> None:
        """Declare the node, its publishers and tokens, then publish until stopped."""
        node = NodeName(self.settings.domain_id, str(session.info.zid()), 0,
                        self.settings.namespace, NODE_NAMES[self.side])
        has_clay = self._clay_source is not None and self._clay_ranges is not None
        topics = declare_names(node, side_topics(self.side, self.settings.groups, has_clay))
        tokens = [session.liveliness().declare_token(node.node_token())]
        publishers: dict[str, tuple[Topic, Any]] = {}
        try:
            for topic in topics:
                publishers[topic.spec.group] = (topic, session.declare_publisher(topic.key))
                tokens.append(session.liveliness().declare_token(topic.token))
            self.connected.set()
            if self.open_failures:
                self._say(f"reached the router at {self.settings.endpoint}")
            self._publish_loop(publishers)
        finally:
            for _topic, publisher in publishers.values():
                _quietly(publisher.undeclare)
            for token in tokens:
                _quietly(token.undeclare)

    def _publish_loop(self, publishers: dict[str, tuple[Topic, Any]]) -> None:
        state_period = 1.0 / self.settings.publish_rate_hz
        next_state = next_status = next_clay = time.monotonic()
        sent: dict[str, Any] | None = None
        previous: dict[str, Any] | None = None
        while not self._stop.is_set():
            now = time.monotonic()
            if now >= next_state:
                next_state = now + state_period
                state = self._state
                if state is not None and state is not sent:
                    self._publish_state(publishers, state, previous)
                    sent, previous = state, state
            if now >= next_status:
                next_status = now + 1.0 / DIAGNOSTICS_RATE_HZ
                self._publish_diagnostics(publishers, now)
            if now >= next_clay:
                next_clay = now + 1.0 / CLAY_RATE_HZ
                self._publish_clay(publishers)
            self._stop.wait(max(min(next_state, next_status, next_clay) - time.monotonic(),
                                0.0))

    def _put(self, publishers: dict[str, tuple[Topic, Any]], group: str,
             build: Callable[[int], Any]) -> None:
        """Serialize ``build(stamp_ns)`` and publish it on ``group``'s topic with its
        attachment, when the group is published and a subscriber matches it."""
        entry = publishers.get(group)
        if entry is None:
            return
        topic, publisher = entry
        try:
            if not publisher.matching_status.matching:
                self.unwatched_skips += 1
                return
        except Exception:  # noqa: BLE001 - unknown: publish
            pass
        stamp_ns = time.time_ns()
        try:
            payload = messages.serialize(build(stamp_ns), topic.spec.type_name)
            sequence = self._sequence.get(group, 0) + 1
            publisher.put(payload, attachment=attachment(sequence, stamp_ns, topic.gid))
        except Exception:  # noqa: BLE001 - a publication may fail; the loop goes on
            self.publish_errors += 1
            return
        self._sequence[group] = sequence
        self.published[group] = self.published.get(group, 0) + 1

    def _publish_state(self, publishers: dict[str, tuple[Topic, Any]], state: dict[str, Any],
                       previous: dict[str, Any] | None) -> None:
        device = DEVICES[self.side]
        force, position = state["force_N"], state["position_m"]
        self._put(publishers, "wrench", lambda ns: messages.wrench(ns, f"haptic_{device}",
                                                                   force))
        self._put(publishers, "pose", lambda ns: messages.pose(ns, position))
        if all(math.isfinite(value) for value in position):
            self._put(publishers, "tf", lambda ns: messages.tf(ns, {f"haptic_{device}":
                                                                    position}))
        velocity = state.get("velocity_m_s") or _velocity(state, previous)
        effort = state.get("effort_N", force)
        self._put(publishers, "joint_states", lambda ns: messages.joint_state(
            ns, (f"{device}_x", f"{device}_y"), position, velocity, effort))

    def _publish_diagnostics(self, publishers: dict[str, tuple[Topic, Any]],
                             now_s: float) -> None:
        values = {key: value for key, value in self._status.items()
                  if isinstance(value, (bool, int, float, str))}
        values.update(self._loop_figures(now_s))
        level, summary = diagnostic_level(values)
        name = f"{self.settings.namespace.strip('/') or 'haptic'}/{self.side}"
        self._put(publishers, "diagnostics", lambda ns: messages.diagnostics(
            ns, name, f"haptic-{self.side}", level, summary, values))

    def _loop_figures(self, now_s: float) -> dict[str, Any]:
        """The loop's rate over the last period (Hz), ticks and overruns so far."""
        if self._loop_counts is None:
            return {}
        ticks, overruns = self._loop_counts()
        last, self._last_counts = self._last_counts, (now_s, ticks)
        rate = ((ticks - last[1]) / (now_s - last[0]) if last is not None and now_s > last[0]
                else 0.0)
        return {"loop_rate_hz": rate, "loop_ticks": ticks, "loop_overruns": overruns}

    def _publish_clay(self, publishers: dict[str, tuple[Topic, Any]]) -> None:
        if "clay" not in publishers or self._clay_source is None or self._clay_ranges is None:
            return
        heights = self._clay_source()
        if heights is None:
            return
        from haptic.common.records.heightmap_codec import downsample_heights, reduction_factors

        factors = reduction_factors(heights.shape[1], heights.shape[0], *CLAY_MAX_CELLS)
        reduced = downsample_heights(heights, factors)
        x_range, y_range = self._clay_ranges
        span_x = (x_range[1] - x_range[0]) * reduced.shape[1] * factors[0] / heights.shape[1]
        span_y = (y_range[1] - y_range[0]) * reduced.shape[0] * factors[1] / heights.shape[0]
        points = messages.height_points(reduced, (x_range[0], x_range[0] + span_x),
                                        (y_range[0], y_range[0] + span_y))
        self._put(publishers, "clay", lambda ns: messages.point_cloud(ns, points))


def diagnostic_level(values: dict[str, Any]) -> tuple[int, str]:
    """(level, message) of a side's status: ERROR in the safe state, WARN while the
    watchdog is not ``ok``, else OK."""
    if values.get("safe_state"):
        return 2, "safe state: forces off"
    watchdog = values.get("watchdog_state", "ok")
    if watchdog != "ok":
        return 1, f"watchdog {watchdog}"
    return 0, "running"


def _velocity(state: dict[str, Any], previous: dict[str, Any] | None) -> tuple[float, float]:
    """The device's velocity between two states, m/s (0 without a previous one)."""
    if previous is None or state.get("time_s") is None or previous.get("time_s") is None:
        return (0.0, 0.0)
    dt = state["time_s"] - previous["time_s"]
    if dt <= 0.0:
        return (0.0, 0.0)
    return tuple((a - b) / dt for a, b in zip(state["position_m"], previous["position_m"],
                                              strict=True))  # type: ignore[return-value]


def _quietly(action: Callable[[], Any]) -> None:
    try:
        action()
    except Exception:  # noqa: BLE001 - best effort while stopping
        pass
