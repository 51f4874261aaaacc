"""``haptic-replay FILE ... --view``: a recorded run played back into the live view.

The recordings' messages (``/slave/state`` as the tool, ``/master/state`` as the handle, the
links' statistics and events as each side's status, the workpiece and the clay maps) are
merged in log-time order and fed to a :class:`~haptic.view.state.ViewState` at ``speed``
times real time, at most ``rate_hz`` frames a second; the page is the live view's, served on
``http://127.0.0.1:PORT/``. The replay ends with the recording (the last frame stays up until
SIGINT or SIGTERM). A pause in the recording longer than :data:`MAX_PAUSE_S` of replay time
is shortened to that (a log time far from the others, in a damaged or foreign file, must not
hold the replay for days), every wait ends at once on SIGINT or SIGTERM, and a message the view
cannot show (a field missing or of another type) is skipped.
"""

from __future__ import annotations

import heapq
import sys
import time
from collections.abc import Iterator, Sequence
from typing import Any

from haptic.common.records.recording import Recording
from haptic.common.runtime.runner import StopSignals
from haptic.view.server import ViewServer
from haptic.view.state import ViewState


def _pair(message: dict[str, Any], x: str, y: str) -> list[Any]:
    return [message.get(x), message.get(y)]


def frame_parts(topic: str, message: dict[str, Any]) -> dict[str, Any]:
    """The :meth:`ViewState.update` arguments of one recorded message (empty: not shown)."""
    if topic == "/slave/state":
        return {"tool": {
            "forces_enabled": bool(message.get("running")), "safe_state":
            not message.get("running"), "in_contact": bool(message.get("cutting")),
            "tool_force_N": _pair(message, "tool_force_x_N", "tool_force_y_N"),
            "tool_position_m": _pair(message, "tool_position_x_m", "tool_position_y_m"),
            "tool_velocity_m_s": _pair(message, "tool_velocity_x_m_s", "tool_velocity_y_m_s"),
            "clay_engagement": message.get("engagement") or 0.0,
            "removed_volume_m3": message.get("removed_volume_m3") or 0.0}}
    if topic == "/master/state":
        return {"handle": {
            "forces_enabled": bool(message.get("forces_enabled")),
            "safe_state": not message.get("forces_enabled"),
            "handle_force_N": _pair(message, "handle_force_x_N", "handle_force_y_N"),
            "handle_position_m": _pair(message, "handle_position_x_m", "handle_position_y_m")}}
    if topic == "/slave/workpiece":
        return {"layout": message}
    if topic == "/slave/clay":
        import numpy as np

        from haptic.common.records.heightmap_codec import heights_to_bytes

        heights = np.array(message["heights_mm"], float) * 1e-3
        header = {"cells_x": message["cells_x"], "cells_y": message["cells_y"]}
        return {"clay": (header, heights_to_bytes(heights))}
    return {}


#: The longest wait between two frames, s of wall time (longer pauses are shortened).
MAX_PAUSE_S = 1.0
#: The longest single sleep, s: a stop request is seen within this.
_SLEEP_SLICE_S = 0.05


def merged(recordings: Sequence[Recording]) -> Iterator[tuple[int, str, dict[str, Any]]]:
    """Every message of the recordings as ``(log_time_ns, topic, message)`` in time order."""
    streams = [[(t, topic, m) for t, m in items]
               for r in recordings for topic, items in r.messages.items()]
    return heapq.merge(*streams, key=lambda item: item[0])


def play(recordings: Sequence[Recording], state: ViewState, speed: float = 1.0,
         rate_hz: float = 60.0, stop: Any = None) -> int:
    """Feed the recordings into ``state`` at ``speed`` x real time; returns the frames
    published. ``stop()`` (optional) ends it early."""
    events: dict[str, list[dict[str, Any]]] = {}
    pending: dict[str, Any] = {}
    statuses: dict[str, dict[str, Any]] = {}
    frame_period_ns = int(1e9 / rate_hz)
    start_wall = time.monotonic_ns()
    start_log = None
    next_frame = None
    frames = 0
    for log_time, topic, message in merged(recordings):
        if start_log is None:
            start_log = next_frame = log_time
        if stop is not None and stop():
            break
        side = topic.strip("/").split("/")[0]
        if topic.endswith("/events"):
            events.setdefault(side, []).append(message)
        elif topic.endswith("/link"):
            statuses[side] = {"side": side, "time_ns": log_time, "link": message,
                              "events": events.get(side, [])[-50:]}
        else:
            try:
                pending.update(frame_parts(topic, message))
            except (KeyError, TypeError, ValueError, IndexError):
                pass  # a message the view cannot show: the frame goes on without it
        if log_time >= next_frame:
            due = start_wall + (log_time - start_log) / speed
            delay = (due - time.monotonic_ns()) * 1e-9
            if delay > MAX_PAUSE_S:  # a long pause (or a wild log time): shortened
                start_wall -= int((delay - MAX_PAUSE_S) * 1e9)
                delay = MAX_PAUSE_S
            if _wait(delay, stop):
                break
            for status in statuses.values():
                state.update(status=status)
            statuses.clear()
            state.update(**pending)
            pending = {}
            frames += 1
            next_frame = log_time + frame_period_ns * speed
    if pending:
        state.update(**pending)
    return frames


def _wait(seconds: float, stop: Any) -> bool:
    """Sleep ``seconds`` (s) in short slices; True as soon as ``stop()`` asks to stop."""
    end = time.monotonic() + seconds
    while (left := end - time.monotonic()) > 0:
        if stop is not None and stop():
            return True
        time.sleep(min(left, _SLEEP_SLICE_S))
    return stop is not None and bool(stop())


def replay_into_view(recordings: Sequence[Recording], port: int = 8765,
                     speed: float = 1.0) -> int:
    """Serve the live view on ``port`` and play the recordings into it; exit status 0."""
    state = ViewState(backoff=False)  # no loop runs: nothing to give way to
    with StopSignals() as signals, ViewServer(state, port) as server:
        print(f"haptic-replay: {server.url} (speed x{speed:g}); Ctrl-C to stop",
              file=sys.stderr, flush=True)
        time.sleep(1.0)  # time for a browser already open to reconnect
        frames = play(recordings, state, speed, stop=lambda: signals.requested)
        print(f"haptic-replay: {frames} frames played", file=sys.stderr, flush=True)
        while not signals.requested:
            time.sleep(0.2)
    return 0
