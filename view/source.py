"""The view's Zenoh side: one session that subscribes to the run's keys under the rig's
prefix and a poller thread that moves the newest samples into the :class:`ViewState` at the
display rate.

Keys: ``<prefix>/view/master`` and ``<prefix>/view/slave`` (each side's newest state at
60 Hz, JSON, from the programs' display threads; the view never subscribes to the loops'
1850 Hz keys, so their publishers gain no subscriber), ``<prefix>/status/<side>`` (JSON),
``<prefix>/workpiece`` (JSON) and ``<prefix>/clay`` (the reduced height map). Nothing here
runs in Zenoh's threads: the poller drains the ring channels.
"""

from __future__ import annotations

import json
import threading
import time
from typing import Any

import zenoh

from haptic.common.runtime.display import decode_clay
from haptic.common.wire.errors import LinkOpenError, one_line
from haptic.common.wire.transport_auth import open_session
from haptic.view.state import ViewState


class ZenohSource:
    """Subscribes under ``key_prefix`` on a session opened with ``zenoh_config`` and feeds
    ``state`` at ``rate_hz`` times the state's back-off scale (view/state.py). Use as a
    context manager (the session is always closed). ``transport_key``: the programs' session
    key when they admit only authenticated transports (common/wire/transport_auth.py)."""

    def __init__(self, zenoh_config: zenoh.Config, key_prefix: str, state: ViewState,
                 rate_hz: float = 60.0, transport_key: bytes | None = None) -> None:
        self._config = zenoh_config
        self._transport_key = transport_key
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
        try:
            self._session = open_session(self._config, self._transport_key)
        except zenoh.ZError as error:
            raise LinkOpenError(f"cannot open the Zenoh session: {one_line(error)}") from None
        ring = zenoh.handlers.RingChannel
        p = self._prefix
        for name, key, capacity in (("handle", f"{p}/view/master", 1),
                                    ("tool", f"{p}/view/slave", 1),
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
                parts["handle"] = json.loads(sample.payload.to_bytes())
            sample = subs["tool"].try_recv()
            if sample is not None:
                parts["tool"] = json.loads(sample.payload.to_bytes())
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
            period_s = self._period_s / self._state.scale
            next_time += period_s
            delay = next_time - time.monotonic()
            if delay < -period_s:
                next_time = time.monotonic()
            elif delay > 0:
                self._stop.wait(delay)
