"""Reading a run's MCAP recording back (complete, or cut short by SIGKILL).

:func:`read_recording` streams the file record by record (it never needs the summary section
at the end), decoding every JSON message; a file that ends in the middle of a record (the
writer was killed) yields everything up to its last complete chunk and ``complete = False``.

A file is input like any other: the chunks' checksums are verified, and whatever the ``mcap``
package raises on a damaged record (a record longer than its 4 GiB limit, a length nothing can
hold, a checksum that fails, data that does not decompress) ends the reading there with
:attr:`Recording.error` set and :attr:`Recording.damaged`; a file that ends inside a record is
``cut short`` (a killed writer), not damaged. A message that is not JSON, not a JSON object, or on a
channel of another encoding is skipped and counted (``skipped``), never decoded by guess.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from mcap.exceptions import EndOfFile
from mcap.records import Channel, DataEnd, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader


@dataclass
class Recording:
    """A decoded recording: ``messages[topic]`` is a list of ``(log_time_ns, dict)`` in file
    order; ``schemas[topic]`` the channel's JSON schema; ``metadata[name]`` the metadata
    records; ``complete``: the file ended with its data-end record, a summary section and its
    footer (closed properly)."""

    path: Path
    messages: dict[str, list[tuple[int, dict[str, Any]]]] = field(default_factory=dict)
    schemas: dict[str, dict[str, Any]] = field(default_factory=dict)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    complete: bool = False
    error: str = ""
    damaged: bool = False
    """Reading stopped at a damaged record inside the file (not at its end): ``error`` says
    which; what came before it is kept."""
    skipped: int = 0
    """Messages not decoded: not a JSON object, or on a channel of another encoding."""

    @property
    def status(self) -> str:
        """``complete``, ``cut short`` (ends mid-record: the writer was killed) or
        ``damaged``."""
        return "damaged" if self.damaged else "complete" if self.complete else "cut short"

    def counts(self) -> dict[str, int]:
        """Messages per topic."""
        return {topic: len(items) for topic, items in self.messages.items()}

    def columns(self, topic: str) -> dict[str, np.ndarray]:
        """A numeric channel as arrays by field (null -> NaN), plus ``log_time_s``."""
        items = self.messages.get(topic, [])
        if not items:
            return {}
        names = list(items[0][1].keys())
        result = {"log_time_s": np.array([t for t, _ in items], float) * 1e-9}
        for name in names:
            result[name] = np.array([_number(m.get(name)) for _, m in items], float)
        return result

    def last(self, topic: str) -> dict[str, Any] | None:
        """The newest message of a topic (None when there is none)."""
        items = self.messages.get(topic)
        return items[-1][1] if items else None


def _number(value: Any) -> float:
    """A recorded value as a float column entry: NaN for null and anything not a number."""
    if type(value) is float or type(value) is int:
        return float(value)
    return math.nan


def read_recording(path: str | Path) -> Recording:
    """Decode the MCAP file at ``path`` (see the module docstring). Raises ``ValueError`` for a
    file that does not start as MCAP (no magic or no header record) and ``OSError`` for one
    that cannot be opened."""
    recording = Recording(Path(path))
    channels: dict[int, Channel] = {}
    schemas: dict[int, Schema] = {}
    header = data_end = False
    with open(path, "rb") as stream:
        reader = StreamReader(stream, skip_magic=False, validate_crcs=True)
        try:
            for record in reader.records:
                if isinstance(record, Header):
                    header = True
                elif isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    _add_channel(recording, channels, schemas, record)
                elif isinstance(record, Message):
                    channel = channels.get(record.channel_id)
                    if channel is None:
                        continue
                    message = _decoded(channel, record.data)
                    if message is None:
                        recording.skipped += 1
                    else:
                        recording.messages[channel.topic].append((record.log_time, message))
                elif isinstance(record, Metadata):
                    recording.metadata[str(record.name)] = {
                        str(k): str(v) for k, v in dict(record.metadata).items()}
                elif isinstance(record, Footer):
                    # closed properly: DataEnd, the summary section, then the footer; a
                    # killed recorder's file ends in a provisional DataEnd and a footer
                    # without a summary (summary_start 0, common/records/recorder.py)
                    recording.complete = data_end and record.summary_start != 0
                    break
                elif isinstance(record, DataEnd):
                    data_end = True
        except Exception as error:  # noqa: BLE001 - a damaged file makes the mcap package
            # raise almost anything (McapError, EOFError, struct.error, MemoryError for a
            # length it believes, zlib and lz4 errors): reading stops here, what came is kept
            recording.error = f"{type(error).__name__}: {error}"[:300]
            recording.damaged = not isinstance(error, EndOfFile)  # else: the file's end
    if not header:
        raise ValueError(f"not an MCAP recording ({recording.error or 'no header record'})")
    for items in recording.messages.values():
        items.sort(key=lambda item: item[0])
    return recording


def _add_channel(recording: Recording, channels: dict[int, Channel],
                 schemas: dict[int, Schema], channel: Channel) -> None:
    """Take a channel record (the first of each id); its schema when it is JSON."""
    if channel.id in channels:
        return
    channels[channel.id] = channel
    recording.messages.setdefault(channel.topic, [])
    schema = schemas.get(channel.schema_id)
    if schema is not None and schema.data and schema.encoding == "jsonschema":
        try:
            recording.schemas[channel.topic] = json.loads(schema.data)
        except ValueError:
            pass  # a schema that is not JSON describes nothing this reader uses


def _decoded(channel: Channel, data: bytes) -> dict[str, Any] | None:
    """A message's JSON object, or None for one that is not (another encoding, not JSON,
    not an object)."""
    if channel.message_encoding != "json":
        return None
    try:
        message = json.loads(data)
    except (ValueError, RecursionError):  # not UTF-8, not JSON, nested beyond reason
        return None
    return message if isinstance(message, dict) else None
