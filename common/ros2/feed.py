"""The shared-memory feed between a program's loop and its ROS 2 bridge process.

The loop must not pay for ROS 2: CDR serialization is Python work that holds the GIL for
hundreds of microseconds a message, and every wake-up of a thread in the loop's process
takes the GIL at a time the loop does not choose. So the ROS 2 session lives in a process of
its own (:mod:`haptic.common.ros2.bridge`), and the loop hands it plain figures through a
file mapped into both processes: no Zenoh session, no thread and no system call in the
loop's process for ROS 2 (the clay, where published, is copied by one thread at 2 Hz).

Each region is a seqlock: the writer makes its sequence number odd, writes, makes it even;
a reader accepts a copy only when the number was even and unchanged around it. One writer
per region: the loop writes the state and the status, the clay copier the clay, the bridge
its counters. Everything read is bounded and checked, as any input: a torn or malformed
record is skipped and counted (``torn_reads``, ``bad_status``).

Layout (little-endian, offsets in bytes):

- state at 0: sequence (u64), then :data:`STATE_FIELDS` as f64 (SI units; NaN: absent);
- status at 128: sequence (u64), length (u64), then at most :data:`STATUS_BYTES` of JSON;
- counters at :data:`COUNTERS_OFFSET`: :data:`COUNTER_FIELDS` as i64 (the bridge's);
- clay at :data:`CLAY_OFFSET`: sequence (u64), then the height map as f64 (m), its shape
  fixed when the feed is made.
"""

from __future__ import annotations

import json
import math
import mmap
import os
import struct
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

#: The state record's fields: the loop's time (s), the device's force (N), position (m),
#: velocity (m/s) and effort (N) in x and y, and the loop's ticks and overruns so far.
STATE_FIELDS = ("time_s", "force_x_N", "force_y_N", "position_x_m", "position_y_m",
                "velocity_x_m_s", "velocity_y_m_s", "effort_x_N", "effort_y_N",
                "loop_ticks", "loop_overruns")
_SEQUENCE = struct.Struct("<Q")
_STATE = struct.Struct(f"<{len(STATE_FIELDS)}d")
STATE_OFFSET = 0
STATUS_OFFSET = 128
#: The largest status JSON, bytes (a longer one is not written: counted in ``status_dropped``).
STATUS_BYTES = 16384
_STATUS_HEADER = struct.Struct("<QQ")
COUNTERS_OFFSET = STATUS_OFFSET + _STATUS_HEADER.size + STATUS_BYTES
#: The bridge's counters, read by the program for its run summary.
COUNTER_FIELDS = ("published", "unwatched_skips", "open_failures", "publish_errors",
                  "connected")
_COUNTERS = struct.Struct(f"<{len(COUNTER_FIELDS)}q")
CLAY_OFFSET = COUNTERS_OFFSET + 64
#: The largest clay height map the feed carries, cells (the clay grids are far smaller).
MAX_CLAY_CELLS = 1 << 20
_NAN = math.nan


def feed_size(clay_shape: tuple[int, int] | None) -> int:
    """Bytes of a feed carrying a clay map of ``clay_shape`` (rows, columns) or none."""
    cells = 0 if clay_shape is None else clay_shape[0] * clay_shape[1]
    return CLAY_OFFSET + _SEQUENCE.size + 8 * cells


def _feed_directory() -> str | None:
    """/dev/shm where there is one (memory, never written to a disk), else the temp dir."""
    return "/dev/shm" if os.path.isdir("/dev/shm") and os.access("/dev/shm", os.W_OK) else None


class _Mapped:
    """A feed file mapped read-write."""

    def __init__(self, path: Path, size: int) -> None:
        self.path = path
        with open(path, "r+b") as handle:
            if os.fstat(handle.fileno()).st_size != size:
                raise ValueError(f"{path}: a ROS 2 feed of {size} bytes was expected")
            self.buffer = mmap.mmap(handle.fileno(), size)

    def close(self) -> None:
        try:
            self.buffer.close()
        except BufferError:  # a numpy view still alive: the mapping goes with it
            pass


class FeedWriter:
    """The program's side: made before the bridge starts (it names the file), written by
    the loop (:meth:`write_state`, :meth:`write_status`) and the clay copier
    (:meth:`write_clay`), read for the bridge's counters (:meth:`counters`)."""

    def __init__(self, clay_shape: tuple[int, int] | None = None) -> None:
        if clay_shape is not None and not (0 < clay_shape[0] * clay_shape[1] <= MAX_CLAY_CELLS):
            raise ValueError(f"clay map {clay_shape} is not 1..{MAX_CLAY_CELLS} cells")
        self.clay_shape = clay_shape
        self.size = feed_size(clay_shape)
        descriptor, name = tempfile.mkstemp(prefix="haptic-ros2-feed-", dir=_feed_directory())
        try:
            os.ftruncate(descriptor, self.size)
        finally:
            os.close(descriptor)
        self.path = Path(name)
        self._mapped = _Mapped(self.path, self.size)
        self._buffer = self._mapped.buffer
        self._state_sequence = 0
        self._status_sequence = 0
        self._clay_sequence = 0
        self.status_dropped = 0
        self._clay = (None if clay_shape is None else np.ndarray(
            clay_shape, np.float64, self._buffer, CLAY_OFFSET + _SEQUENCE.size))

    def write_state(self, values: tuple[float, ...]) -> None:
        """The newest state: :data:`STATE_FIELDS` in order (a few us, no allocation)."""
        buffer = self._buffer
        sequence = self._state_sequence + 1
        _SEQUENCE.pack_into(buffer, STATE_OFFSET, sequence)
        _STATE.pack_into(buffer, STATE_OFFSET + 8, *values)
        self._state_sequence = sequence + 1
        _SEQUENCE.pack_into(buffer, STATE_OFFSET, sequence + 1)

    def write_status(self, figures: Mapping[str, Any]) -> None:
        """The newest status figures: the scalars of ``figures`` as JSON (others dropped)."""
        scalars = {key: value for key, value in figures.items()
                   if isinstance(value, (bool, int, float, str))}
        data = json.dumps(scalars, allow_nan=True).encode()
        if len(data) > STATUS_BYTES:
            self.status_dropped += 1
            return
        buffer = self._buffer
        sequence = self._status_sequence + 1
        _STATUS_HEADER.pack_into(buffer, STATUS_OFFSET, sequence, len(data))
        start = STATUS_OFFSET + _STATUS_HEADER.size
        buffer[start:start + len(data)] = data
        self._status_sequence = sequence + 1
        _SEQUENCE.pack_into(buffer, STATUS_OFFSET, sequence + 1)

    def write_clay(self, heights_m: np.ndarray) -> None:
        """The newest clay height map, m, of the feed's ``clay_shape``."""
        if self._clay is None:
            raise ValueError("this feed carries no clay")
        sequence = self._clay_sequence + 1
        _SEQUENCE.pack_into(self._buffer, CLAY_OFFSET, sequence)
        np.copyto(self._clay, heights_m, casting="same_kind")
        self._clay_sequence = sequence + 1
        _SEQUENCE.pack_into(self._buffer, CLAY_OFFSET, sequence + 1)

    def counters(self) -> dict[str, int]:
        """The bridge's counters as it last wrote them."""
        return dict(zip(COUNTER_FIELDS, _COUNTERS.unpack_from(self._buffer, COUNTERS_OFFSET),
                        strict=True))

    def close(self) -> None:
        """Unmap and remove the file (the bridge has ended)."""
        self._clay = None
        self._mapped.close()
        self.path.unlink(missing_ok=True)


class FeedReader:
    """The bridge's side: the newest state, status and clay, each once per change, and the
    bridge's counters (:meth:`write_counters`)."""

    def __init__(self, path: Path, clay_shape: tuple[int, int] | None = None) -> None:
        self._mapped = _Mapped(path, feed_size(clay_shape))
        self._buffer = self._mapped.buffer
        self.clay_shape = clay_shape
        self._seen = {"state": 0, "status": 0, "clay": 0}
        self.torn_reads = 0
        self.bad_status = 0
        self._newest_clay: np.ndarray | None = None
        self._clay = (None if clay_shape is None else np.ndarray(
            clay_shape, np.float64, self._buffer, CLAY_OFFSET + _SEQUENCE.size))

    def _stable(self, offset: int, copy: Any, name: str) -> Any:
        """``copy()`` of a region when its sequence is even, new and unchanged around it;
        None when nothing new came or the writer was mid-write (counted in ``torn_reads``)."""
        before = _SEQUENCE.unpack_from(self._buffer, offset)[0]
        if before == self._seen[name]:
            return None
        if before & 1:
            self.torn_reads += 1
            return None
        value = copy()
        if _SEQUENCE.unpack_from(self._buffer, offset)[0] != before:
            self.torn_reads += 1
            return None
        self._seen[name] = before
        return value

    def state(self) -> dict[str, Any] | None:
        """The newest state as the publisher's figures (``time_s``, ``force_N``,
        ``position_m``, and ``velocity_m_s``/``effort_N`` where given), the loop's counts
        (``loop_ticks``, ``loop_overruns``); None when nothing new came."""
        values = self._stable(STATE_OFFSET,
                              lambda: _STATE.unpack_from(self._buffer, STATE_OFFSET + 8),
                              "state")
        if values is None:
            return None
        record = dict(zip(STATE_FIELDS, values, strict=True))
        state: dict[str, Any] = {
            "time_s": record["time_s"],
            "force_N": (record["force_x_N"], record["force_y_N"]),
            "position_m": (record["position_x_m"], record["position_y_m"]),
            "loop_ticks": record["loop_ticks"], "loop_overruns": record["loop_overruns"]}
        velocity = (record["velocity_x_m_s"], record["velocity_y_m_s"])
        if not any(math.isnan(value) for value in velocity):
            state["velocity_m_s"] = velocity
        effort = (record["effort_x_N"], record["effort_y_N"])
        if not any(math.isnan(value) for value in effort):
            state["effort_N"] = effort
        return state

    def _status_bytes(self) -> bytes | None:
        _sequence, length = _STATUS_HEADER.unpack_from(self._buffer, STATUS_OFFSET)
        if length > STATUS_BYTES:
            return None
        start = STATUS_OFFSET + _STATUS_HEADER.size
        return bytes(self._buffer[start:start + length])

    def status(self) -> dict[str, Any] | None:
        """The newest status figures (scalars only); None when nothing new came or the
        record is malformed (counted in ``bad_status``)."""
        data = self._stable(STATUS_OFFSET, self._status_bytes, "status")
        if data is None:
            return None
        try:
            figures = json.loads(data)
        except ValueError:
            self.bad_status += 1
            return None
        if not isinstance(figures, dict):
            self.bad_status += 1
            return None
        return {key: value for key, value in figures.items()
                if isinstance(value, (bool, int, float, str))}

    def clay(self) -> np.ndarray | None:
        """A copy of the newest clay height map (m), or None when none came yet."""
        if self._clay is None:
            return None
        clay = self._clay
        copy = self._stable(CLAY_OFFSET, clay.copy, "clay")
        if copy is not None:
            self._newest_clay = copy
        return self._newest_clay

    def write_counters(self, counters: Mapping[str, Any]) -> None:
        """The bridge's counters for the program's summary (missing ones are 0)."""
        _COUNTERS.pack_into(self._buffer, COUNTERS_OFFSET,
                            *(int(counters.get(name, 0)) for name in COUNTER_FIELDS))

    def close(self) -> None:
        self._clay = None
        self._mapped.close()


def state_values(time_s: float, force_N: Any, position_m: Any, velocity_m_s: Any | None,
                 effort_N: Any | None, counts: tuple[int, int]) -> tuple[float, ...]:
    """A state record in :data:`STATE_FIELDS` order (NaN for an absent velocity or
    effort)."""
    velocity = velocity_m_s if velocity_m_s is not None else (_NAN, _NAN)
    effort = effort_N if effort_N is not None else (_NAN, _NAN)
    return (float(time_s), float(force_N[0]), float(force_N[1]), float(position_m[0]),
            float(position_m[1]), float(velocity[0]), float(velocity[1]), float(effort[0]),
            float(effort[1]), float(counts[0]), float(counts[1]))
