"""A program's handle on its ROS 2 bridge process (:mod:`haptic.common.ros2.bridge`).

The loop calls :meth:`Ros2Bridge.offer` each tick: every :meth:`state_every` ticks it
writes the state into the shared-memory feed (:mod:`haptic.common.ros2.feed`: a few
``struct`` writes, no allocation beyond the loop's own figures, no system call), every
:meth:`status_every` ticks the status figures as JSON. Where the clay is published, one
thread copies its height map into the feed at :data:`~haptic.common.ros2.publisher.
CLAY_RATE_HZ`. Everything ROS 2 costs (Zenoh, CDR, the router's retries) is the bridge
process's, which :meth:`start` starts on the CPUs of the calling thread and :meth:`stop`
ends by its own PID (SIGTERM, then SIGKILL after :data:`STOP_TIMEOUT_S`), always reaped.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
from collections.abc import Callable
from typing import Any

import numpy as np

from haptic.common.ros2.feed import COUNTER_FIELDS, FeedWriter, state_values
from haptic.common.ros2.publisher import CLAY_RATE_HZ, DIAGNOSTICS_RATE_HZ
from haptic.common.ros2.settings import Ros2Settings

#: How long the bridge has to withdraw its tokens and close its session, s.
STOP_TIMEOUT_S = 5.0

ClaySource = Callable[[], "np.ndarray | None"]


class Ros2Bridge:
    """See the module docstring. ``side``: ``master`` or ``slave``; ``period_s``: the
    loop's period, s; ``say``: one line for the user; ``loop_counts()``: the loop's ticks
    and overruns so far; ``clay_source()``: the clay's (rows, columns) height map in m over
    ``clay_ranges`` ((x0, x1), (y0, y1)) in m, or None."""

    def __init__(self, settings: Ros2Settings, side: str, period_s: float, *,
                 say: Callable[[str], None], loop_counts: Callable[[], tuple[int, int]],
                 clay_source: ClaySource | None = None,
                 clay_ranges: tuple[tuple[float, float], tuple[float, float]] | None = None,
                 say_prefix: str = "ros2: ") -> None:
        self.settings = settings
        self.side = side
        self._say = say
        self._say_prefix = say_prefix
        self._loop_counts = loop_counts
        self._every = (self.state_every(settings, period_s),
                       max(1, round(1.0 / (DIAGNOSTICS_RATE_HZ * period_s))))
        first_clay = clay_source() if clay_source is not None else None
        self._clay_source = (clay_source if first_clay is not None and clay_ranges is not None
                             and "clay" in settings.groups else None)
        self._clay_ranges = clay_ranges
        shape = tuple(first_clay.shape) if self._clay_source is not None else None
        self.feed = FeedWriter(shape)  # type: ignore[arg-type]
        self._process: subprocess.Popen[bytes] | None = None
        self._stop = threading.Event()
        self._clay_thread: threading.Thread | None = None
        self.exit_status: int | None = None
        self._counters = dict.fromkeys(COUNTER_FIELDS, 0)

    @staticmethod
    def state_every(settings: Ros2Settings, period_s: float) -> int:
        """Ticks of ``period_s`` between two state writes (the publish rate)."""
        return max(1, round(1.0 / (settings.publish_rate_hz * period_s)))

    def command(self) -> list[str]:
        """The bridge process's command line."""
        settings = self.settings
        command = [sys.executable, "-m", "haptic.common.ros2.bridge", "--feed",
                   str(self.feed.path), "--side", self.side, "--domain-id",
                   str(settings.domain_id), "--namespace", settings.namespace, "--endpoint",
                   settings.endpoint, "--rate", repr(settings.publish_rate_hz), "--topics",
                   ",".join(sorted(settings.groups)), "--parent-pid",
                   str(os.getpid()), "--say-prefix", self._say_prefix]
        if self._clay_source is not None and self.feed.clay_shape is not None:
            (x0, x1), (y0, y1) = self._clay_ranges  # type: ignore[misc]
            command += ["--clay-shape", *map(str, self.feed.clay_shape),
                        "--clay-ranges", *map(repr, (x0, x1, y0, y1))]
        return command

    def start(self) -> Ros2Bridge:
        """Start the bridge process (its own session: a terminal's Ctrl-C reaches the
        program, which ends it) and the clay copier."""
        self._process = subprocess.Popen(self.command(), stdin=subprocess.DEVNULL,
                                         stdout=subprocess.DEVNULL, start_new_session=True)
        if self._clay_source is not None:
            self._clay_thread = threading.Thread(target=self._copy_clay, daemon=True,
                                                 name=f"ros2-clay-{self.side}")
            self._clay_thread.start()
        return self

    def offer(self, tick: int, state: Callable[[], dict[str, Any]],
              status: Callable[[], dict[str, Any]]) -> None:
        """From the loop, each tick: ``state()`` every state period, ``status()`` every
        status period, each into the feed (neither built on the other ticks)."""
        state_every, status_every = self._every
        if tick % state_every == 0:
            figures = state()
            self.feed.write_state(state_values(
                figures["time_s"], figures["force_N"], figures["position_m"],
                figures.get("velocity_m_s"), figures.get("effort_N"), self._loop_counts()))
        if tick % status_every == 0:
            self.feed.write_status(status())

    def _copy_clay(self) -> None:
        source = self._clay_source
        while not self._stop.wait(1.0 / CLAY_RATE_HZ):
            heights = source() if source is not None else None
            if heights is not None and heights.shape == self.feed.clay_shape:
                self.feed.write_clay(heights)

    def stop(self) -> None:
        """End the bridge (tokens withdrawn, session closed) and keep its counters."""
        self._stop.set()
        if self._clay_thread is not None:
            self._clay_thread.join(timeout=2.0)
            self._clay_thread = None
        process, self._process = self._process, None
        if process is not None:
            try:
                process.send_signal(signal.SIGTERM)
                self.exit_status = process.wait(timeout=STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                self._say(f"the ROS 2 bridge (PID {process.pid}) did not end within "
                          f"{STOP_TIMEOUT_S:g} s; killed")
                process.kill()
                self.exit_status = process.wait()
            if self.exit_status not in (0, None):
                self._say(f"the ROS 2 bridge (PID {process.pid}) ended with status "
                          f"{self.exit_status}: its topics stopped then")
            self._counters = self.feed.counters()
            self.feed.close()

    def __enter__(self) -> Ros2Bridge:
        return self.start()

    def __exit__(self, *_exc: object) -> None:
        self.stop()

    @property
    def figures(self) -> dict[str, Any]:
        """For the run summary: the bridge's samples published, topics skipped unwatched,
        failures, and whether it reached the router."""
        counters = self._counters if self._process is None else self.feed.counters()
        return {"ros2_published": counters["published"],
                "ros2_unwatched_skips": counters["unwatched_skips"],
                "ros2_open_failures": counters["open_failures"],
                "ros2_publish_errors": counters["publish_errors"],
                "ros2_connected": bool(counters["connected"]),
                "ros2_bridge_exit": self.exit_status,
                "ros2_status_dropped": self.feed.status_dropped}
