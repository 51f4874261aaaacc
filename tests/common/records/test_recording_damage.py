"""Recordings that are damaged, foreign or crafted: the reader and ``haptic-replay`` end in
one line and a documented exit status, never a traceback or a silent "0 s" success (found by
fuzzing the reader: a flipped length bit raised MemoryError, a damaged chunk passed its
changed values on, files with nothing of a run exited 0)."""

from __future__ import annotations

import json
import math
import struct
import time
from pathlib import Path

import pytest
from mcap.writer import Writer

from haptic.common.records.recorder import McapRecorder
from haptic.common.records.recording import read_recording
from haptic.view.replay import playback
from haptic.view.replay.cli import main

T0_NS = 1_700_000_000_000_000_000


def _recording(path: Path, chunks: int = 6) -> Path:
    """A slave recording of several chunks, written by the programs' recorder."""
    with McapRecorder(path, "slave", chunk_size=4096) as recorder:
        recorder.add_channel("/slave/state", ("time_s", "tool_force_x_N"))
        for i in range(chunks * 100):
            recorder.record("/slave/state", T0_NS + i * 540_000, (i * 0.00054, 0.01 * i))
    return path


def _chunk_offsets(data: bytes) -> list[int]:
    """The file offsets of the chunk records (opcode 0x06) in a recording's data section."""
    offsets, at = [], 8  # after the magic
    while at + 9 <= len(data):
        opcode, length = data[at], struct.unpack_from("<Q", data, at + 1)[0]
        if opcode == 0x06:
            offsets.append(at)
        if opcode == 0x02:  # the footer: done
            break
        at += 9 + length
    return offsets


def _replay(capsys, path: Path, tmp_path: Path) -> tuple[int, str, str]:
    status = main([str(path), "--out", str(tmp_path / "plots")])
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def test_a_chunk_that_claims_a_length_beyond_the_file_is_damage_not_a_traceback(
        tmp_path, capsys) -> None:
    path = _recording(tmp_path / "run.mcap")
    data = bytearray(path.read_bytes())
    second = _chunk_offsets(bytes(data))[1]
    # the chunk record's own length, then the length of the records inside it (after its
    # start and end times, uncompressed size and CRC, and its compression's name)
    compression_length = struct.unpack_from("<I", data, second + 9 + 28)[0]
    records_length_at = second + 9 + 32 + compression_length
    for at, claimed in ((second + 1, 2**56), (records_length_at, 2**56),
                        (records_length_at, 2**63)):
        broken = bytearray(data)
        struct.pack_into("<Q", broken, at, claimed)
        damaged = tmp_path / f"length-{at}-{claimed}.mcap"
        damaged.write_bytes(bytes(broken))
        recording = read_recording(damaged)
        assert recording.damaged and recording.error and not recording.complete
        assert 0 < recording.counts()["/slave/state"] < 600  # the first chunk is kept
        status, out, err = _replay(capsys, damaged, tmp_path)
        assert status == 3 and "damaged" in out and "read error" in out
        assert "damaged" in err and "Traceback" not in err


def test_a_changed_byte_inside_a_chunk_fails_its_checksum(tmp_path, capsys) -> None:
    path = _recording(tmp_path / "run.mcap")
    data = bytearray(path.read_bytes())
    third = _chunk_offsets(bytes(data))[2]
    before = tmp_path / "before.mcap"
    before.write_bytes(bytes(data[:third]))  # the two chunks before it, cut there
    data[third + 200] ^= 0x10  # inside the chunk's records
    path.write_bytes(bytes(data))
    recording = read_recording(path)
    assert recording.damaged and "CRC" in recording.error.upper()
    assert recording.messages == read_recording(before).messages  # those two, unchanged
    status, out, _ = _replay(capsys, path, tmp_path)
    assert status == 3 and "damaged" in out


@pytest.mark.parametrize("past_first_chunk", [-10, 100], ids=["before it", "inside it"])
def test_a_file_cut_before_any_message_is_no_recording(tmp_path, capsys,
                                                        past_first_chunk) -> None:
    path = _recording(tmp_path / "run.mcap")
    data = path.read_bytes()
    path.write_bytes(data[:_chunk_offsets(data)[0] + past_first_chunk])
    status, out, err = _replay(capsys, path, tmp_path)
    assert status == 1 and out == "" and len(err.strip().splitlines()) == 1
    assert str(path) in err and "Traceback" not in err
    if past_first_chunk > 0:  # the header was read: the file ends inside the chunk
        assert not read_recording(path).damaged  # cut short, not damage
        assert "no message of a master's or slave's recording (cut short" in err


def test_a_file_cut_after_some_messages_is_cut_short_and_read(tmp_path, capsys) -> None:
    path = _recording(tmp_path / "run.mcap")
    data = path.read_bytes()
    path.write_bytes(data[:_chunk_offsets(data)[3] + 100])
    recording = read_recording(path)
    assert recording.status == "cut short" and not recording.damaged
    status, out, _ = _replay(capsys, path, tmp_path)
    assert status == 0 and "cut short (no footer)" in out


def _foreign(path: Path, encoding: str, payloads: list[bytes], topic: str = "/chatter",
             schema: bytes = b"string data") -> Path:
    with open(path, "wb") as stream:
        writer = Writer(stream)
        writer.start("ros2", "test")
        schema_id = writer.register_schema("std_msgs/String", "ros2msg", schema)
        channel = writer.register_channel(topic, encoding, schema_id)
        for i, payload in enumerate(payloads):
            writer.add_message(channel, T0_NS + i, payload, T0_NS + i)
        writer.finish()
    return path


def test_a_foreign_recording_is_refused_and_its_messages_skipped(tmp_path, capsys) -> None:
    path = _foreign(tmp_path / "ros.mcap", "cdr", [b"\x00\x01\x00\x00hello"] * 5)
    recording = read_recording(path)
    assert recording.complete and recording.skipped == 5 and recording.counts() == {
        "/chatter": 0}
    status, out, err = _replay(capsys, path, tmp_path)
    assert status == 1 and "topics: /chatter" in err
    # JSON on our topic, but not objects, or not JSON at all: skipped and counted
    path = _foreign(tmp_path / "junk.mcap", "json", [b"[1, 2]", b"\xff\xfe", b"{\"a\": 1"],
                    topic="/slave/state", schema=b"not json")
    recording = read_recording(path)
    assert recording.skipped == 3 and recording.schemas == {}


def test_crafted_contents_give_figures_or_nothing_never_a_traceback(tmp_path, capsys) -> None:
    """A valid MCAP whose JSON has other shapes than the recorder writes."""
    path = tmp_path / "crafted.mcap"
    messages = [("/slave/state", {"tool_force_x_N": "x" if i == 3 else 0.1 * i, "running": 1.0})
                for i in range(50)]  # no time_s, one value a string
    messages += [
        ("/slave/link", {"link_one_way_delay_p50_s": "fast", "link_one_way_delay_p99_s": 0.1,
                         "loss_ratio": 0.0}),
        ("/slave/events", {"time_s": "soon", "kind": "x"}),
        ("/slave/workpiece", {"x_range_m": [0.1, 0.1], "y_range_m": [0.0, 0.02],
                              "block_id": [[0, 0], [0, 0]], "block_names": ["a"],
                              "block_damping_N_s_per_m": [10.0]}),
        ("/slave/clay", {"heights_mm": [[1.0, 1.0], [1.0, 1.0]]}),
    ]
    with open(path, "wb") as stream:
        writer = Writer(stream)
        writer.start("haptic-teleop", "test")
        schema_id = writer.register_schema("any", "jsonschema", b"{}")
        channels = {topic: writer.register_channel(topic, "json", schema_id)
                    for topic in dict(messages)}
        for i, (topic, message) in enumerate(messages):
            writer.add_message(channels[topic], T0_NS + i, json.dumps(message).encode(),
                               T0_NS + i)
        writer.add_metadata("recorder", {"side": "slave", "written": "abc"})
        writer.finish()
    recording = read_recording(path)
    assert math.isnan(recording.columns("/slave/state")["tool_force_x_N"][3])
    status, out, err = _replay(capsys, path, tmp_path)
    assert status == 0 and "Traceback" not in err
    assert "event        ?  x" in out
    assert not (tmp_path / "plots" / "clay.png").exists()  # a zero-width workpiece
    status = main([str(path), "--json", "--no-plots"])
    summary = json.loads(capsys.readouterr().out)["recordings"][0]
    assert status == 0 and summary["status"] == "complete"


def test_a_log_time_days_away_does_not_hold_the_replay(tmp_path) -> None:
    """A message logged 11.6 days after the others: the view's replay shortens the pause to
    MAX_PAUSE_S instead of sleeping for days, and a stop request ends any wait at once."""
    path = tmp_path / "gap.mcap"
    with McapRecorder(path, "slave", chunk_size=4096) as recorder:
        recorder.add_channel("/slave/state", ("time_s", "tool_force_x_N"))
        recorder.record("/slave/state", T0_NS, (0.0, 0.0))
        recorder.record("/slave/state", T0_NS + 10**15, (1e6, 1.0))
    recording = read_recording(path)

    class Frames:
        updates = 0

        def update(self, **parts) -> None:
            self.updates += 1

    started = time.monotonic()
    frames = playback.play([recording], Frames(), speed=1.0)
    assert frames == 2 and time.monotonic() - started < playback.MAX_PAUSE_S + 30.0
    started = time.monotonic()
    asked = iter([False, False, True])
    playback.play([recording], Frames(), speed=1.0, stop=lambda: next(asked, True))
    assert time.monotonic() - started < playback.MAX_PAUSE_S
