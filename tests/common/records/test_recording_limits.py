"""The recording reader at its edges (common/records/recording.py): a file without a header
record, a footer without a data-end record, a message on a channel never announced, schemas
that are absent, foreign or not JSON, messages out of time order, the columns of messages
whose fields differ, and an error message kept to 300 characters."""

from __future__ import annotations

import io
import math
import struct
from pathlib import Path

import pytest
from mcap.writer import Writer

from haptic.common.records import recording as recording_module
from haptic.common.records.recording import read_recording

MAGIC = b"\x89MCAP0\r\n"


def write(path: Path, messages: list[tuple[int, int, bytes]],
          schema: tuple[str, bytes] | None = None) -> Path:
    """An unchunked MCAP file with channel 1 ("/a", JSON) and ``messages`` (channel id, log
    time ns, data); ``schema``: channel 1's schema (encoding, data)."""
    stream = io.BytesIO()
    writer = Writer(stream, use_chunking=False)
    writer.start()
    schema_id = 0 if schema is None else writer.register_schema(
        name="s", encoding=schema[0], data=schema[1])
    writer.register_channel(topic="/a", message_encoding="json", schema_id=schema_id)
    for channel, log_time, data in messages:
        writer.add_message(channel_id=channel, log_time=log_time, data=data,
                           publish_time=log_time)
    writer.finish()
    path.write_bytes(stream.getvalue())
    return path


def test_a_file_without_a_header_record_is_not_a_recording(tmp_path: Path) -> None:
    footer = struct.pack("<BQQQI", 0x02, 20, 0, 0, 0)
    path = tmp_path / "no-header.mcap"
    path.write_bytes(MAGIC + footer + MAGIC)
    with pytest.raises(ValueError, match=r"not an MCAP recording \(no header record\)"):
        read_recording(path)


def test_a_footer_after_no_data_end_record_is_not_complete(tmp_path: Path) -> None:
    path = write(tmp_path / "run.mcap", [(1, 1, b'{"x": 1}')])
    assert read_recording(path).complete
    data = path.read_bytes()
    data_end = data.index(bytes([0x0F]) + struct.pack("<Q", 4))  # opcode, length: a u32 CRC
    path.write_bytes(data[:data_end] + data[data_end + 13:])
    recording = read_recording(path)
    assert not recording.complete and recording.status == "cut short"
    assert recording.counts() == {"/a": 1}


def test_a_message_on_a_channel_never_announced_is_passed_over(tmp_path: Path) -> None:
    path = write(tmp_path / "run.mcap", [(1, 1, b'{"x": 1}'), (9, 2, b'{"x": 2}'),
                                         (1, 3, b'{"x": 3}')])
    recording = read_recording(path)
    assert [m["x"] for _, m in recording.messages["/a"]] == [1, 3]
    assert recording.skipped == 0 and recording.complete and not recording.error


def test_only_a_json_schema_that_is_json_is_kept(tmp_path: Path) -> None:
    good = write(tmp_path / "good.mcap", [], ("jsonschema", b'{"type": "object"}'))
    assert read_recording(good).schemas == {"/a": {"type": "object"}}
    for name, schema in (("none", None), ("foreign", ("protobuf", b'{"type": "object"}')),
                         ("broken", ("jsonschema", b'{"type": ')),
                         ("empty", ("jsonschema", b""))):
        recording = read_recording(write(tmp_path / f"{name}.mcap", [(1, 1, b"{}")], schema))
        assert recording.schemas == {} and recording.complete, name


def test_messages_come_back_in_time_order_with_their_columns(tmp_path: Path) -> None:
    path = write(tmp_path / "run.mcap", [(1, 3_000_000_000, b'{"x": 3, "z": 1}'),
                                         (1, 1_000_000_000, b'{"x": 1, "y": 2.5}'),
                                         (1, 2_000_000_000, b'{"x": 2, "w": "no"}')])
    recording = read_recording(path)
    assert [t for t, _ in recording.messages["/a"]] == [1_000_000_000, 2_000_000_000,
                                                          3_000_000_000]
    columns = recording.columns("/a")
    assert set(columns) == {"log_time_s", "x", "y"}  # the first message's fields
    assert columns["log_time_s"].tolist() == [1.0, 2.0, 3.0]
    assert columns["x"].tolist() == [1.0, 2.0, 3.0]
    assert columns["y"][0] == 2.5 and math.isnan(columns["y"][1]) and math.isnan(
        columns["y"][2])
    assert recording.last("/a") == {"x": 3, "z": 1} and recording.last("/b") is None
    assert recording.columns("/b") == {}


def test_an_error_is_kept_to_300_characters(tmp_path: Path, monkeypatch) -> None:
    path = write(tmp_path / "run.mcap", [(1, 1, b'{"x": 1}')])

    class Failing:
        def __init__(self, *args: object, **kwargs: object) -> None:
            pass

        @property
        def records(self):
            from mcap.records import Header

            yield Header(profile="", library="")
            raise RuntimeError("x" * 1000)

    monkeypatch.setattr(recording_module, "StreamReader", Failing)
    recording = read_recording(path)
    assert recording.error == ("RuntimeError: " + "x" * 1000)[:300]
    assert recording.damaged and recording.status == "damaged"
