"""Display-rate publications for the live view (``haptic-view``), off the control loop.

A :class:`DisplayPublisher` owns a thread on the program's Zenoh session that publishes, at
display rates:

- ``<prefix>/view/<side>`` (JSON, ``state_rate_hz``): the side's newest state (master: handle
  force and position, the felt force; slave: tool force, position, velocity, engagement,
  removed volume), which the loop hands over with :meth:`offer_state` every
  :meth:`state_every` ticks. The view never subscribes to the loops' own 1850 Hz keys, so
  the loops' publishers gain no subscriber;
- ``<prefix>/status/<side>`` (JSON, ``status_rate_hz``): the side's link statistics, watchdog
  state and safety events. The loop hands the latest figures over with :meth:`offer_status`
  at its own status rate (a reference swap, no copy, no I/O in the loop);
- ``<prefix>/clay`` (slave only, ``clay_rate_hz``): the clay's height map reduced to at most
  256 x 64 cells as uint16 micrometres (:mod:`haptic.slave_sim.clay.clay_view`), after a JSON
  header line with the layout's size. The heights are read through ``clay_source``, a
  callable the thread calls (on a CPU clay it returns a view of the live array; the thread
  reduces it with numpy, which releases the GIL). A publication is skipped while the
  previous one is still running, so the thread never queues work.

Nothing is encoded or sent for a key no subscriber matches (each key has a declared Zenoh
publisher whose matching status costs about 1 us to read): with no viewer the thread only
reads the loop's counts and, on a recording slave, reduces the clay for the recording; a
viewer that appears gets the workpiece layout at its next wake-up.

The thread wakes only when a publication is due, and an unwatched key is looked at again
after :data:`UNWATCHED_CHECK_S` instead of at its rate: every wake-up takes the process's GIL
at a time the loop does not choose, and where the loop hands it over (each Warp launch, a
ctypes call) the thread keeps it for as long as it runs. On 2 CPUs with both loops under
SCHED_FIFO a display thread woken in the middle of the slave's tick was preempted by the
master's loop while it held the slave's GIL: at 4 kHz (Ts = 0.25 ms) a thread waking 200
times a second more than doubled the slave's node stage p99 and multiplied its overruns
tenfold against one waking about 9 times a second with no viewer (the runs:
docs/measurements/programs_loops.md).

The thread measures its own cost (:attr:`figures`): publications made and the mean and
largest time one took, s, and the publications skipped because nobody watched.

Told the loop's ticks and overruns so far (:meth:`DisplayPublisher.follow_loop`) with a
back-off (:class:`~haptic.common.runtime.display_backoff.DisplayBackoff`), the state and clay rates
scale down while the loop overruns and back up when it holds its period: the display loses
frames before the loop loses ticks. The status publications keep their rate (they are few
and carry the counts: ``loop_steps``, ``loop_overruns`` and ``display_scale``, which the view
uses to back off too).
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from haptic.common.runtime.display_backoff import DisplayBackoff
from haptic.common.runtime.summary import json_safe

#: Default rates, Hz.
DEFAULT_STATE_RATE_HZ = 60.0
DEFAULT_STATUS_RATE_HZ = 5.0
DEFAULT_CLAY_RATE_HZ = 10.0
#: How often a publication nobody watches looks again for a viewer, s (a viewer that
#: subscribes gets its first frame within this).
UNWATCHED_CHECK_S = 0.25


class _Publication:
    """One display key's Zenoh publisher: ``put`` never raises (a display publication may
    fail; the loop goes on) and ``matching()`` says whether any subscriber matches the key
    (about 1 us): nothing is encoded for a key nobody watches."""

    def __init__(self, session: Any, key: str) -> None:
        self.key = key
        self._session = session
        try:
            self._publisher = session.declare_publisher(key)
        except Exception:  # noqa: BLE001 - fall back to the session's put, always watched
            self._publisher = None

    def matching(self) -> bool:
        if self._publisher is None:
            return True
        try:
            return bool(self._publisher.matching_status.matching)
        except Exception:  # noqa: BLE001 - unknown: publish
            return True

    def put(self, payload: bytes) -> None:
        try:
            if self._publisher is not None:
                self._publisher.put(payload)
            else:
                self._session.put(self.key, payload)
        except Exception:  # noqa: BLE001 - a display publication may fail; the loop goes on
            pass

    def close(self) -> None:
        if self._publisher is not None:
            try:
                self._publisher.undeclare()
            except Exception:  # noqa: BLE001 - best effort while stopping
                pass


def encode_clay(layout: dict[str, Any], heights_bytes: bytes, sequence: int) -> bytes:
    """The ``<prefix>/clay`` payload: a JSON header line then the uint16 heights."""
    header = {"cells_x": layout["cells_x"], "cells_y": layout["cells_y"], "seq": sequence}
    return json.dumps(header).encode() + b"\n" + heights_bytes


def decode_clay(payload: bytes) -> tuple[dict[str, Any], bytes]:
    """Inverse of :func:`encode_clay`: ``(header, heights bytes)``."""
    newline = payload.index(b"\n")
    return json.loads(payload[:newline]), payload[newline + 1:]


class EventCursor:
    """The events each source list gained since the last call (items with ``as_dict()`` or
    dicts)."""

    def __init__(self) -> None:
        self._seen: dict[int, int] = {}

    def new(self, sources: Any) -> list[dict[str, Any]]:
        result: list[dict[str, Any]] = []
        for source in sources:
            key = id(source)
            seen = self._seen.get(key, 0)
            if len(source) > seen:
                result.extend(item.as_dict() if hasattr(item, "as_dict") else dict(item)
                              for item in source[seen:])
                self._seen[key] = len(source)
        return result


class DisplayPublisher:
    """Publishes a side's status (and the slave's clay) for the live view; see the module
    docstring. ``session``: the program's open Zenoh session; ``key_prefix``: the rig's
    prefix; ``clay_source``: returns the (cells_y, cells_x) height map in m, or None;
    ``layout``: the workpiece layout of :func:`haptic.slave_sim.clay.clay_view.workpiece_layout`
    (published once as ``<prefix>/workpiece`` and again every second for late viewers);
    ``on_clay(time_ns, reduced heights m)``: called in the thread after each clay
    publication (the slave records the map from it)."""

    def __init__(self, session: Any, key_prefix: str, side: str, *,
                 status_rate_hz: float = DEFAULT_STATUS_RATE_HZ,
                 clay_rate_hz: float = DEFAULT_CLAY_RATE_HZ,
                 clay_source: Callable[[], np.ndarray] | None = None,
                 layout: dict[str, Any] | None = None,
                 factors: tuple[int, int] = (1, 1),
                 on_clay: Callable[[int, np.ndarray], None] | None = None) -> None:
        self._session = session
        self._prefix = key_prefix
        self.side = side
        self._status_period_s = 1.0 / status_rate_hz
        self._clay_period_s = 1.0 / clay_rate_hz
        self._clay_source = clay_source
        self._layout = layout
        # encoded once: the layout lists every reduced cell, and json.dumps of it holds the
        # GIL for about 1.5 ms, which stalled the slave's loop once a second
        self._layout_bytes = json.dumps(layout).encode() if layout is not None else b""
        self._factors = factors
        self._on_clay = on_clay
        self._loop_counts: Callable[[], tuple[int, int]] | None = None
        self.backoff: DisplayBackoff | None = None
        #: the state and clay rates' current scale (0..1], from the back-off
        self.scale = 1.0
        self.lowest_scale = 1.0
        self._status: dict[str, Any] | None = None
        self._state: dict[str, Any] | None = None
        self._state_period_s = 1.0 / DEFAULT_STATE_RATE_HZ
        self._events: list[dict[str, Any]] = []
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.publications = 0
        self.clay_publications = 0
        #: publications not made because no subscriber matched their key
        self.unwatched_skips = 0
        #: whether a viewer subscribed to the status at the last status period (the loop
        #: builds no status figures for the display while none does)
        self.status_watched = True
        #: the same for the state (the loop builds no state for the display while False)
        self.state_watched = True
        self.busy_s = 0.0
        self.max_busy_s = 0.0

    def state_every(self, period_s: float) -> int:
        """Ticks of ``period_s`` between two :meth:`offer_state` calls."""
        return max(1, round(self._state_period_s / period_s))

    def offer_state(self, state: dict[str, Any]) -> None:
        """From the loop: the side's newest state (a reference swap)."""
        self._state = state

    def offer_status(self, figures: dict[str, Any], new_events: list[dict[str, Any]]) -> None:
        """From the loop: the newest link figures and any new events (kept for the next
        publication)."""
        self._status = figures
        if new_events:
            self._events = (self._events + new_events)[-50:]

    def follow_loop(self, loop_counts: Callable[[], tuple[int, int]],
                    backoff: DisplayBackoff | None = None) -> None:
        """Publish the loop's counts (``loop_counts()``: ticks stepped and overruns so far,
        read at the status rate) and, with ``backoff``, scale the state and clay rates by
        it."""
        self.backoff = backoff
        self._loop_counts = loop_counts

    def start(self) -> DisplayPublisher:
        self._thread = threading.Thread(target=self._run, name=f"display-{self.side}",
                                        daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None

    def __enter__(self) -> DisplayPublisher:
        return self.start()

    def __exit__(self, *_exc: object) -> None:
        self.stop()

    @property
    def figures(self) -> dict[str, Any]:
        """The publisher's cost: publications, mean and largest time one took (s)."""
        count = self.publications
        return {"display_publications": count, "display_clay_publications":
                self.clay_publications,
                "display_mean_cost_s": self.busy_s / count if count else 0.0,
                "display_max_cost_s": self.max_busy_s,
                "display_backoffs": self.backoff.backoffs if self.backoff is not None else 0,
                "display_lowest_scale": self.lowest_scale,
                "display_unwatched_skips": self.unwatched_skips}

    def _run(self) -> None:
        prefix = self._prefix
        keys = {"state": f"{prefix}/view/{self.side}", "status": f"{prefix}/status/{self.side}"}
        has_clay = self._clay_source is not None and self._layout is not None
        if has_clay:
            keys.update(clay=f"{prefix}/clay", layout=f"{prefix}/workpiece")
        publishers = {name: _Publication(self._session, key) for name, key in keys.items()}
        try:
            self._publish(publishers, has_clay)
        finally:
            for publication in publishers.values():
                publication.close()

    def _publish(self, publishers: dict[str, _Publication], has_clay: bool) -> None:
        """The thread's loop: each publication at its rate, made only while a subscriber
        matches its key (the clay is still reduced for ``on_clay``)."""
        state_pub, status_pub = publishers["state"], publishers["status"]
        sent_state: dict[str, Any] | None = None
        next_state = next_status = next_clay = next_layout = time.monotonic()
        layout_watched = False
        sequence = 0
        while not self._stop.is_set():
            now = time.monotonic()
            if now >= next_state:
                state = self._state
                self.state_watched = state_pub.matching()
                next_state = now + (self._state_period_s / self.scale if self.state_watched
                                    else max(self._state_period_s, UNWATCHED_CHECK_S))
                if state is not None and state is not sent_state:
                    sent_state = state
                    if self._counted(self.state_watched):
                        started = time.perf_counter()
                        state["time_ns"] = time.time_ns()
                        state_pub.put(json.dumps(json_safe(state)).encode())
                        self._account(time.perf_counter() - started)
            if now >= next_status:
                next_status = now + self._status_period_s
                loop = self._loop_scale(now)
                status = self._status
                self.status_watched = status_pub.matching()
                if status is not None and self._counted(self.status_watched):
                    started = time.perf_counter()
                    payload = {"side": self.side, "time_ns": time.time_ns(),
                               "link": status, "events": self._events, **loop}
                    status_pub.put(json.dumps(json_safe(payload)).encode())
                    self._account(time.perf_counter() - started)
            next_wake = min(next_state, next_status)
            if has_clay:
                watched = publishers["layout"].matching()
                if watched and (now >= next_layout or not layout_watched):
                    # a new viewer gets the workpiece at once; then backed off too, but at
                    # least every 4 s
                    next_layout = now + min(1.0 / self.scale, 4.0)
                    publishers["layout"].put(self._layout_bytes)
                layout_watched = watched
                if now >= next_clay:
                    sequence, clay_watched = self._clay(publishers["clay"], sequence)
                    next_clay = now + (self._clay_period_s / self.scale
                                       if clay_watched or self._on_clay is not None
                                       else max(self._clay_period_s, UNWATCHED_CHECK_S))
                next_wake = min(next_wake, next_clay)
                if watched:
                    next_wake = min(next_wake, next_layout)
            # asleep until the next publication is due (stop() wakes it at once)
            self._stop.wait(max(next_wake - time.monotonic(), 0.0))

    def _counted(self, watched: bool) -> bool:
        """``watched`` (a subscriber matches the key); a skipped publication is counted."""
        if not watched:
            self.unwatched_skips += 1
        return watched

    def _clay(self, publication: _Publication, sequence: int) -> tuple[int, bool]:
        """Reduce the clay map; publish it where watched and hand it to ``on_clay``.
        Returns the publication's sequence number and whether a viewer watched."""
        watched = self._counted(publication.matching())
        if not watched and self._on_clay is None:
            return sequence, watched
        started = time.perf_counter()
        from haptic.common.records.heightmap_codec import downsample_heights, heights_to_bytes

        assert self._clay_source is not None  # has_clay
        heights = self._clay_source()
        if heights is None:
            return sequence, watched
        reduced = downsample_heights(heights, self._factors)
        if watched:
            sequence += 1
            publication.put(encode_clay(self._layout, heights_to_bytes(reduced), sequence))
            self.clay_publications += 1
            self._account(time.perf_counter() - started)
        if self._on_clay is not None:
            self._on_clay(time.time_ns(), reduced)
        return sequence, watched

    def _loop_scale(self, now_s: float) -> dict[str, Any]:
        """Read the loop's counts and update the back-off's scale; the status's loop keys."""
        loop_counts = self._loop_counts
        if loop_counts is None:
            return {}
        ticks, overruns = loop_counts()
        if self.backoff is not None:
            self.scale = self.backoff.update(now_s, ticks, overruns)
            self.lowest_scale = min(self.lowest_scale, self.scale)
        return {"loop_steps": ticks, "loop_overruns": overruns, "display_scale": self.scale}

    def _account(self, cost_s: float) -> None:
        self.publications += 1
        self.busy_s += cost_s
        if cost_s > self.max_busy_s:
            self.max_busy_s = cost_s
