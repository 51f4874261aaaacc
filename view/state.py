"""The view's latest state of the run, shared by the Zenoh poller and the HTTP handlers.

One writer (the poller, or the replay) calls :meth:`ViewState.update`; any number of readers
(one per browser) wait on :meth:`ViewState.wait_newer` and read the snapshot, a JSON-ready
dict. The clay travels in the snapshot only when it changed since the version the reader saw
(``clay_version``), as base64 of the uint16 micrometre map.
"""

from __future__ import annotations

import base64
import threading
import time
from typing import Any


class ViewState:
    """The latest frame (handle, tool, status of each side) plus the clay and the layout."""

    def __init__(self) -> None:
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
                self.frame["status"][status.get("side", "?")] = status
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
            }
            if self.layout is not None and self.layout_version > layout_seen:
                result["layout"] = self.layout
            if self.clay_b64 is not None and self.clay_version > clay_seen:
                result["clay"] = {"header": self.clay_header, "heights_u16_b64": self.clay_b64}
            return result
