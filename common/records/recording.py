"""Reading a run's MCAP recording back (complete, or cut short by SIGKILL).

:func:`read_recording` streams the file record by record (it never needs the summary section
at the end), decoding every JSON message; a file that ends in the middle of a record (the
writer was killed) yields everything up to its last complete chunk and ``complete = False``.
"""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from mcap.exceptions import McapError
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
            result[name] = np.array(
                [np.nan if (v := m.get(name)) is None else v for _, m in items], float)
        return result

    def last(self, topic: str) -> dict[str, Any] | None:
        """The newest message of a topic (None when there is none)."""
        items = self.messages.get(topic)
        return items[-1][1] if items else None


def read_recording(path: str | Path) -> Recording:
    """Decode the MCAP file at ``path`` (see the module docstring). Raises ``ValueError`` for a
    file that does not start as MCAP (no magic or no header record) and ``OSError`` for one
    that cannot be opened."""
    recording = Recording(Path(path))
    channels: dict[int, Channel] = {}
    schemas: dict[int, Schema] = {}
    header = data_end = False
    with open(path, "rb") as stream:
        reader = StreamReader(stream, skip_magic=False)
        try:
            for record in reader.records:
                if isinstance(record, Header):
                    header = True
                elif isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    if record.id not in channels:
                        channels[record.id] = record
                        recording.messages.setdefault(record.topic, [])
                        schema = schemas.get(record.schema_id)
                        if schema is not None and schema.data:
                            recording.schemas[record.topic] = json.loads(schema.data)
                elif isinstance(record, Message):
                    channel = channels.get(record.channel_id)
                    if channel is None:
                        continue
                    recording.messages[channel.topic].append(
                        (record.log_time, json.loads(record.data)))
                elif isinstance(record, Metadata):
                    recording.metadata[record.name] = dict(record.metadata)
                elif isinstance(record, Footer):
                    # closed properly: DataEnd, the summary section, then the footer; a
                    # killed recorder's file ends in a provisional DataEnd and a footer
                    # without a summary (summary_start 0, common/records/recorder.py)
                    recording.complete = data_end and record.summary_start != 0
                    break
                elif isinstance(record, DataEnd):
                    data_end = True
        except (McapError, EOFError, ValueError, RuntimeError, struct.error) as error:
            recording.error = f"{type(error).__name__}: {error}"
    if not header:
        raise ValueError(f"not an MCAP recording ({recording.error or 'no header record'})")
    for items in recording.messages.values():
        items.sort(key=lambda item: item[0])
    return recording
