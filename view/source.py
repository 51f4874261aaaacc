"""The view's Zenoh side: one session that subscribes to the run's keys under the rig's
prefix and a poller thread that moves the newest samples into the :class:`ViewState` at the
display rate.

Keys: ``<prefix>/handle`` and ``<prefix>/tool`` (the loops' messages, msgpack; ring channels
of one sample, so only the newest is ever decoded), ``<prefix>/status/<side>`` (JSON),
``<prefix>/workpiece`` (JSON) and ``<prefix>/clay`` (the reduced height map). Nothing here
runs in Zenoh's threads: the poller drains the ring channels.
"""

from __future__ import annotations

import json
import threading
import time
from typing import Any

import zenoh

from haptic.common.display import decode_clay
from haptic.common.messages import KIND_HANDLE, KIND_TOOL, decode
from haptic.view.state import ViewState


def handle_dict(message: Any) -> dict[str, Any]:
    """A ``HandleState`` for the page (SI units in the names)."""
    return {"seq": message.seq, "send_time_ns": message.send_time_ns,
            "forces_enabled": bool(message.forces_enabled),
            "safe_state": bool(message.safe_state),
            "handle_force_N": list(message.handle_force_N),
            "handle_position_m": list(message.handle_position_m)}


def tool_dict(message: Any) -> dict[str, Any]:
    """A ``ToolState`` for the page (SI units in the names)."""
    return {"seq": message.seq, "send_time_ns": message.send_time_ns,
            "forces_enabled": bool(message.forces_enabled),
            "safe_state": bool(message.safe_state), "in_contact": bool(message.in_contact),
            "tool_force_N": list(message.tool_force_N),
            "tool_position_m": list(message.tool_position_m),
            "tool_velocity_m_s": list(message.tool_velocity_m_s),
            "clay_engagement": message.clay_engagement,
            "removed_volume_m3": message.removed_volume_m3}


class ZenohSource:
    """Subscribes under ``key_prefix`` on a session opened with ``zenoh_config`` and feeds
    ``state`` at ``rate_hz``. Use as a context manager (the session is always closed)."""

    def __init__(self, zenoh_config: zenoh.Config, key_prefix: str, state: ViewState,
                 rate_hz: float = 60.0) -> None:
        self._config = zenoh_config
        self._prefix = key_prefix
        self._state = state
        self._period_s = 1.0 / rate_hz
        self._session: zenoh.Session | None = None
        self._subscribers: dict[str, Any] = {}
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.polls = 0
        self.decode_errors = 0

    def __enter__(self) -> ZenohSource:
        self._session = zenoh.open(self._config)
        ring = zenoh.handlers.RingChannel
        p = self._prefix
        for name, key, capacity in (("handle", f"{p}/handle", 1), ("tool", f"{p}/tool", 1),
                                    ("status", f"{p}/status/*", 8),
                                    ("workpiece", f"{p}/workpiece", 1),
                                    ("clay", f"{p}/clay", 1)):
            self._subscribers[name] = self._session.declare_subscriber(key, ring(capacity))
        self._thread = threading.Thread(target=self._run, name="view-poller", daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *_exc: object) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        for subscriber in self._subscribers.values():
            try:
                subscriber.undeclare()
            except Exception:  # noqa: BLE001 - best effort while closing
                pass
        self._subscribers.clear()
        if self._session is not None:
            self._session.close()
            self._session = None

    def poll_once(self) -> bool:
        """Move the newest samples into the state; True when anything arrived."""
        subs = self._subscribers
        parts: dict[str, Any] = {}
        try:
            sample = subs["handle"].try_recv()
            if sample is not None:
                parts["handle"] = handle_dict(decode(sample.payload.to_bytes(), KIND_HANDLE))
            sample = subs["tool"].try_recv()
            if sample is not None:
                parts["tool"] = tool_dict(decode(sample.payload.to_bytes(), KIND_TOOL))
            sample = subs["workpiece"].try_recv()
            if sample is not None:
                parts["layout"] = json.loads(sample.payload.to_bytes())
            sample = subs["clay"].try_recv()
            if sample is not None:
                parts["clay"] = decode_clay(sample.payload.to_bytes())
        except Exception:  # noqa: BLE001 - a bad sample is counted, the view goes on
            self.decode_errors += 1
        statuses = []
        while True:
            sample = subs["status"].try_recv()
            if sample is None:
                break
            try:
                statuses.append(json.loads(sample.payload.to_bytes()))
            except ValueError:
                self.decode_errors += 1
        if not parts and not statuses:
            return False
        for status in statuses[:-1]:
            self._state.update(status=status)
        self._state.update(status=statuses[-1] if statuses else None, **parts)
        return True

    def _run(self) -> None:
        next_time = time.monotonic()
        while not self._stop.is_set():
            self.poll_once()
            self.polls += 1
            next_time += self._period_s
            delay = next_time - time.monotonic()
            if delay < -self._period_s:
                next_time = time.monotonic()
            elif delay > 0:
                self._stop.wait(delay)
