"""MCAP recording of a run, off the control loop.

The loop calls :meth:`McapRecorder.record` with a channel name, a log time (ns, CLOCK_REALTIME)
and a tuple of values (or a dict); the call appends to a bounded deque and returns (a full
queue drops the message and counts it, never blocks). A writer thread drains the queue, encodes
each message as JSON (channels carry a JSON schema, the encoding Foxglove and PlotJuggler open
directly) and writes it into an MCAP file with chunks of ``chunk_size`` bytes. The file is
opened unbuffered, so each finished chunk is on disk at once: a process killed with SIGKILL
leaves a file readable up to its last completed chunk (:func:`haptic.common.records.recording
.read_recording` reads such a file). :meth:`McapRecorder.close` drains the queue and writes the
summary section (SIGINT/SIGTERM end the programs' loops normally and reach it).

Example::

    with McapRecorder("run.mcap", "slave") as recorder:
        recorder.add_channel("/slave/state", ("time_s", "tool_force_x_N"))
        recorder.record("/slave/state", time.time_ns(), (0.0, 1.2))
"""

from __future__ import annotations

import json
import math
import os
import struct
import tempfile
import threading
import time
from collections import deque
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from mcap.data_stream import RecordBuilder
from mcap.records import ChunkIndex, DataEnd, Footer
from mcap.writer import MCAP0_MAGIC, CompressionType, Writer

#: Default queue capacity, messages (about 35 s of one 1850 Hz channel).
DEFAULT_QUEUE_SIZE = 65536
#: Default chunk size, bytes (a chunk about every 0.3 s at the loops' rates: what a SIGKILL
#: may lose).
DEFAULT_CHUNK_SIZE = 256 * 1024
#: Where mcap's ``Writer`` keeps its chunk indexes (a list it appends one ``ChunkIndex`` to
#: per chunk and writes into the summary at ``finish``).
_WRITER_CHUNK_INDEXES = "_Writer__chunk_indices"


def _provisional_trailer() -> bytes:
    """A DataEnd (data section CRC 0: not computed), a Footer without a summary
    (summary_start 0) and the closing magic: a complete MCAP file without a summary section,
    what a reader that seeks to the end (``mcap.reader.make_reader(...).iter_messages()``,
    Foxglove) needs to fall back to reading the records in order, and what a checker of the
    container format (``pymcap-cli doctor``) accepts without an error."""
    builder = RecordBuilder()
    DataEnd(data_section_crc=0).write(builder)
    Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(builder)
    return builder.end() + MCAP0_MAGIC


class _RawRecord:
    """One record already serialised (opcode, length, body), written as it is."""

    __slots__ = ("data",)

    def __init__(self, data: bytes) -> None:
        self.data = data

    def write(self, builder: RecordBuilder) -> None:
        builder.write(self.data)


class SpilledChunkIndexes:
    """The MCAP writer's chunk indexes on disk, not in memory: the writer appends one
    ``ChunkIndex`` per chunk and keeps them all until it writes the summary, which made a
    recording's memory grow with its length (about 1 kB/s, 3.5 MB/h, at the loops' rates).
    Here each index is serialised (about 70 B) into an unnamed temporary file in the
    recording's directory; :meth:`__iter__` reads them back, in order, for the summary."""

    def __init__(self, directory: Path) -> None:
        self._file = tempfile.TemporaryFile(dir=directory, prefix=".chunk-index-")
        self._count = 0

    def append(self, index: ChunkIndex) -> None:
        builder = RecordBuilder()
        index.write(builder)
        self._file.write(builder.end())
        self._count += 1

    def __len__(self) -> int:
        return self._count

    def __iter__(self) -> Iterator[_RawRecord]:
        self._file.flush()
        self._file.seek(0)
        for _ in range(self._count):
            header = self._file.read(9)
            _opcode, length = struct.unpack("<BQ", header)
            yield _RawRecord(header + self._file.read(length))
        self._file.seek(0, os.SEEK_END)

    def close(self) -> None:
        self._file.close()


class _UnbufferedFile:
    """A write-only file whose every ``write`` reaches the kernel before it returns, followed
    by a provisional trailer (:func:`_provisional_trailer`) in the same ``pwrite``: the MCAP
    writer writes whole records per call, so between two writes the file is complete records
    plus a valid footer, and what a SIGKILL leaves behind opens with the standard readers up
    to its last completed chunk. A reader of the live file reads it in pieces: a write
    landing between two of them gives it the start of one version and the rest of the next,
    and it must read again. A SIGKILL landing inside a ``pwrite`` (microseconds) may cut the
    write short at a page; such a rare file reads with ``read_recording`` (up to its last
    whole chunk), not with the standard readers. The next write starts over the trailer;
    :meth:`final` stops the trailers before the writer's own summary and footer. Not an
    ``io.RawIOBase``, so the MCAP writer does not wrap it in a buffer."""

    _TRAILER = _provisional_trailer()

    def __init__(self, path: Path) -> None:
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        self._position = 0
        self._trailer = self._TRAILER

    def write(self, data: bytes) -> int:
        length = len(data)
        view = memoryview(bytes(data) + self._trailer)  # one syscall: data and trailer
        offset = self._position
        while view:
            written = os.pwrite(self._fd, view, offset)
            view = view[written:]
            offset += written
        self._position += length
        return length

    def final(self) -> None:
        """From now on the writer closes the file itself: no more provisional trailers."""
        self._trailer = b""

    def tell(self) -> int:
        return self._position

    def flush(self) -> None:
        pass

    def close(self) -> None:
        os.ftruncate(self._fd, self._position)  # nothing after the writer's own magic
        os.close(self._fd)


def _compression() -> CompressionType:
    try:
        import lz4.frame  # noqa: F401
    except ImportError:
        return CompressionType.NONE
    return CompressionType.LZ4


def _json_number(value: Any) -> Any:
    """JSON has no NaN or infinity: those become null."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def json_safe(value: Any) -> Any:
    """``value`` with NaN/inf floats as None and numpy scalars/arrays as Python values."""
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if hasattr(value, "tolist"):
        return json_safe(value.tolist())
    return _json_number(value)


def object_schema(title: str, fields: Sequence[str] | None) -> dict[str, Any]:
    """The JSON schema of a channel: an object of numbers named ``fields`` (units in the
    names), or any object when ``fields`` is None."""
    schema: dict[str, Any] = {"$schema": "https://json-schema.org/draft/2020-12/schema",
                              "title": title, "type": "object"}
    if fields is not None:
        schema["properties"] = {name: {"type": ["number", "null"]} for name in fields}
    return schema


class McapRecorder:
    """Records one program's run into ``path`` (MCAP, JSON-encoded channels).

    ``side``: the program (``master``/``slave``), written into the file's metadata;
    ``queue_size``: messages the queue holds before it drops; ``chunk_size``: bytes per chunk.
    Figures: :attr:`written`, :attr:`dropped` (per channel in :attr:`dropped_by_channel`).
    """

    def __init__(self, path: str | Path, side: str, *, queue_size: int = DEFAULT_QUEUE_SIZE,
                 chunk_size: int = DEFAULT_CHUNK_SIZE) -> None:
        if queue_size < 1:
            raise ValueError(f"queue_size must be >= 1 (got {queue_size})")
        self.path = Path(path)
        self.side = side
        self._capacity = queue_size
        self._chunk_size = chunk_size
        self._queue: deque[tuple[str, int, Any]] = deque()
        self._fields: dict[str, tuple[str, ...] | None] = {}
        self._pending_channels: deque[tuple[str, tuple[str, ...] | None]] = deque()
        self._channel_ids: dict[str, int] = {}
        self._sequence: dict[str, int] = {}
        self.written = 0
        self.dropped = 0
        self.dropped_by_channel: dict[str, int] = {}
        self.encode_errors = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._file: Any = None
        self._writer: Writer | None = None
        #: the writer's chunk indexes, on disk (None where this mcap version keeps them
        #: elsewhere: then in its memory, as before)
        self._chunk_indexes: SpilledChunkIndexes | None = None
        self.max_queue_depth = 0

    # -- lifecycle -------------------------------------------------------------------------
    def open(self) -> McapRecorder:
        """Create the file, write the header and start the writer thread."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = _UnbufferedFile(self.path)
        self._writer = Writer(self._file, chunk_size=self._chunk_size,
                              compression=_compression())
        if isinstance(getattr(self._writer, _WRITER_CHUNK_INDEXES, None), list):
            self._chunk_indexes = SpilledChunkIndexes(self.path.parent)
            setattr(self._writer, _WRITER_CHUNK_INDEXES, self._chunk_indexes)
        self._writer.start(profile="", library="haptic-teleop")
        self._thread = threading.Thread(target=self._drain, name=f"mcap-{self.side}",
                                         daemon=True)
        self._thread.start()
        return self

    def __enter__(self) -> McapRecorder:
        return self.open()

    def __exit__(self, *_exc: object) -> None:
        self.close()

    def close(self, metadata: dict[str, str] | None = None) -> None:
        """Drain the queue, write the statistics and the summary section, close the file."""
        if self._thread is None:
            return
        self._stop.set()
        self._thread.join()
        self._thread = None
        writer = self._writer
        assert writer is not None
        meta = {"side": self.side, "written": str(self.written), "dropped": str(self.dropped),
                "dropped_by_channel": json.dumps(self.dropped_by_channel),
                "max_queue_depth": str(self.max_queue_depth)}
        meta.update(metadata or {})
        writer.add_metadata("recorder", meta)
        self._file.final()
        writer.finish()
        self._file.close()
        if self._chunk_indexes is not None:
            self._chunk_indexes.close()

    # -- loop side -------------------------------------------------------------------------
    def add_channel(self, topic: str, fields: Sequence[str] | None = None) -> None:
        """Declare a channel: ``fields`` names the values of :meth:`record`'s tuples (units
        in the names); None: the channel takes dicts."""
        names = None if fields is None else tuple(fields)
        self._fields[topic] = names
        self._pending_channels.append((topic, names))

    def record(self, topic: str, log_time_ns: int, values: Any) -> bool:
        """Queue one message (a tuple matching the channel's fields, or a dict); returns
        False when the queue was full (the message is dropped and counted)."""
        queue = self._queue
        if len(queue) >= self._capacity:
            self.dropped += 1
            self.dropped_by_channel[topic] = self.dropped_by_channel.get(topic, 0) + 1
            return False
        queue.append((topic, log_time_ns, values))
        return True

    # -- writer thread ---------------------------------------------------------------------
    def _register_pending(self) -> None:
        writer = self._writer
        assert writer is not None
        while self._pending_channels:
            topic, fields = self._pending_channels.popleft()
            schema_id = writer.register_schema(
                name=topic.strip("/").replace("/", "."), encoding="jsonschema",
                data=json.dumps(object_schema(topic, fields)).encode())
            self._channel_ids[topic] = writer.register_channel(
                topic=topic, message_encoding="json", schema_id=schema_id)
            self._sequence[topic] = 0

    def _drain(self) -> None:
        queue = self._queue
        while True:
            stopping = self._stop.is_set()
            self._register_pending()
            depth = len(queue)
            if depth > self.max_queue_depth:
                self.max_queue_depth = depth
            while queue:
                topic, log_time_ns, values = queue.popleft()
                self._write(topic, log_time_ns, values)
            if stopping:
                break
            time.sleep(0.005)

    def _write(self, topic: str, log_time_ns: int, values: Any) -> None:
        writer = self._writer
        assert writer is not None
        if topic not in self._channel_ids:
            self._register_pending()
        fields = self._fields.get(topic)
        if isinstance(values, dict):
            payload = json_safe(values)
        elif fields is not None:
            payload = {name: _json_number(float(v)) for name, v in zip(fields, values,
                                                                         strict=False)}
        else:
            payload = json_safe(values)
        try:
            data = json.dumps(payload, separators=(",", ":")).encode()
        except (TypeError, ValueError):
            self.encode_errors += 1
            return
        sequence = self._sequence[topic] = self._sequence[topic] + 1
        writer.add_message(channel_id=self._channel_ids[topic], log_time=log_time_ns,
                           data=data, publish_time=log_time_ns, sequence=sequence)
        self.written += 1

    def figures(self) -> dict[str, Any]:
        """The recorder's keys of the run summary."""
        return {"record_path": str(self.path), "record_written": self.written,
                "record_dropped": self.dropped, "record_max_queue_depth": self.max_queue_depth}
