"""The view's latest state of the run, shared by the Zenoh poller and the HTTP handlers.

One writer (the poller, or the replay) calls :meth:`ViewState.update`; any number of readers
(one per browser) wait on :meth:`ViewState.wait_newer` and read the snapshot, a JSON-ready
dict. The clay travels in the snapshot only when it changed since the version the reader saw
(``clay_version``), as base64 of the uint16 micrometre map.

The view backs off as the programs' display threads do (common/runtime/display_backoff.py):
each side's status carries its loop's ticks and overruns (``loop_steps``, ``loop_overruns``);
while either loop overruns, :attr:`ViewState.scale` falls and the server sends frames at that
fraction of its rate, so the page redraws less. Counts that are not non-negative integers
are ignored (and counted in :attr:`ViewState.bad_loop_counts`): they come from the network.
"""

from __future__ import annotations

import base64
import threading
import time
from collections.abc import Callable
from typing import Any

from haptic.common.runtime.display_backoff import DisplayBackoff


class ViewState:
    """The latest frame (handle, tool, status of each side) plus the clay and the layout.
    ``backoff``: follow the loops' overruns (:attr:`scale`); ``clock``: monotonic, s."""

    def __init__(self, backoff: bool = True,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self._condition = threading.Condition()
        self.version = 0
        self.frame: dict[str, Any] = {"handle": None, "tool": None, "status": {}}
        self.layout: dict[str, Any] | None = None
        self.layout_version = 0
        self.clay_b64: str | None = None
        self.clay_header: dict[str, Any] | None = None
        self.clay_version = 0
        self.updates = 0
        self.started = time.monotonic()
        self._clock = clock
        self._backoff = backoff
        self._backoffs: dict[str, DisplayBackoff] = {}
        #: the frame rate's scale (0..1]: the lowest of the sides' back-offs
        self.scale = 1.0
        self.lowest_scale = 1.0
        self.bad_loop_counts = 0

    def update(self, *, handle: dict[str, Any] | None = None,
               tool: dict[str, Any] | None = None,
               status: dict[str, Any] | None = None,
               layout: dict[str, Any] | None = None,
               clay: tuple[dict[str, Any], bytes] | None = None) -> None:
        """Publish a new frame: the given parts replace the old ones."""
        with self._condition:
            if handle is not None:
                self.frame["handle"] = handle
            if tool is not None:
                self.frame["tool"] = tool
            if status is not None:
                side = status.get("side", "?")
                self.frame["status"][side] = status
                if self._backoff and "loop_steps" in status:
                    self._follow_loop(str(side), status.get("loop_steps"),
                                      status.get("loop_overruns"))
            if layout is not None and layout != self.layout:
                self.layout = layout
                self.layout_version += 1
            if clay is not None:
                self.clay_header, data = clay
                self.clay_b64 = base64.b64encode(data).decode("ascii")
                self.clay_version += 1
            self.version += 1
            self.updates += 1
            self._condition.notify_all()

    def _follow_loop(self, side: str, ticks: Any, overruns: Any) -> None:
        """One side's loop counts into its back-off (under the lock)."""
        if not all(type(value) is int and value >= 0 for value in (ticks, overruns)):
            self.bad_loop_counts += 1
            return
        backoff = self._backoffs.get(side)
        if backoff is None:
            if len(self._backoffs) >= 2:  # a master and a slave; a stranger's side is ignored
                self.bad_loop_counts += 1
                return
            backoff = self._backoffs[side] = DisplayBackoff()
        backoff.update(self._clock(), ticks, overruns)
        self.scale = min(item.scale for item in self._backoffs.values())
        self.lowest_scale = min(self.lowest_scale, self.scale)

    def wait_newer(self, version: int, timeout_s: float) -> int:
        """Block until the version passes ``version`` (or the timeout); the current one."""
        with self._condition:
            if self.version <= version:
                self._condition.wait(timeout_s)
            return self.version

    def snapshot(self, clay_seen: int = -1, layout_seen: int = -1) -> dict[str, Any]:
        """The frame as a JSON-ready dict; the clay and the layout only when newer than the
        versions the reader has."""
        with self._condition:
            result: dict[str, Any] = {
                "version": self.version, "time_ns": time.time_ns(),
                "handle": self.frame["handle"], "tool": self.frame["tool"],
                "status": dict(self.frame["status"]),
                "clay_version": self.clay_version, "layout_version": self.layout_version,
                "view_scale": self.scale,
            }
            if self.layout is not None and self.layout_version > layout_seen:
                result["layout"] = self.layout
            if self.clay_b64 is not None and self.clay_version > clay_seen:
                result["clay"] = {"header": self.clay_header, "heights_u16_b64": self.clay_b64}
            return result
