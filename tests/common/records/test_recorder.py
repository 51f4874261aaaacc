"""The MCAP recorder and reader: round trip, drops on a full queue, a SIGKILLed writer."""

from __future__ import annotations

import json
import math
import signal
import sys
import textwrap
import time
from pathlib import Path

from mcap.reader import make_reader

from haptic.common.records.recorder import _WRITER_CHUNK_INDEXES, McapRecorder
from haptic.common.records.recording import read_recording
from tests.helpers.programs import Program


def test_round_trip_every_channel_and_count(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    with McapRecorder(path, "slave", chunk_size=2048) as recorder:
        recorder.add_channel("/slave/state", ("time_s", "tool_force_x_N"))
        recorder.add_channel("/slave/events")
        for i in range(500):
            force = math.nan if i == 7 else 0.5 * i
            recorder.record("/slave/state", 1_000_000_000 + i * 540_000, (i * 0.00054, force))
        recorder.record("/slave/events", 2_000_000_000, {"kind": "tool_stopped", "time_s": 1.0})
    assert recorder.written == 501 and recorder.dropped == 0
    recording = read_recording(path)
    assert recording.complete and not recording.error
    assert recording.counts() == {"/slave/state": 500, "/slave/events": 1}
    state = recording.columns("/slave/state")
    assert state["tool_force_x_N"][3] == 1.5
    assert math.isnan(state["tool_force_x_N"][7])  # NaN is written as null
    assert recording.schemas["/slave/state"]["properties"].keys() == {"time_s", "tool_force_x_N"}
    assert recording.metadata["recorder"]["written"] == "501"
    # The official reader (what Foxglove's tooling uses) reads it through the summary section.
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics.message_count == 501
        schemas = {s.encoding for s in summary.schemas.values()}
        assert schemas == {"jsonschema"}
        topics = [channel.topic for _, channel, _ in reader.iter_messages()]
    assert topics.count("/slave/state") == 500


def test_chunk_indexes_live_on_disk_and_index_every_chunk(tmp_path: Path) -> None:
    """The writer keeps no chunk index in memory (a long recording's memory stays flat), yet
    the summary lists one per chunk, in order, and an indexed reader finds every message
    through them, time-ordered and from a time window."""
    path = tmp_path / "long.mcap"
    recorder = McapRecorder(path, "master", chunk_size=1024).open()
    recorder.add_channel("/master/state", ("time_s", "handle_force_x_N"))
    for i in range(3000):
        recorder.record("/master/state", 1_000_000_000 + i * 540_000, (i * 0.00054, 0.1 * i))
    spilled = recorder._chunk_indexes
    assert spilled is not None
    assert getattr(recorder._writer, _WRITER_CHUNK_INDEXES) is spilled
    recorder.close()
    assert list(tmp_path.iterdir()) == [path]  # nothing left beside the recording
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None
        indexes = summary.chunk_indexes
        assert len(indexes) == summary.statistics.chunk_count == len(spilled) > 50
        starts = [index.chunk_start_offset for index in indexes]
        assert starts == sorted(starts) and len(set(starts)) == len(starts)
        assert all(index.message_index_offsets for index in indexes)
        times = [message.log_time for _, _, message in reader.iter_messages()]
        assert times == [1_000_000_000 + i * 540_000 for i in range(3000)]
        window = list(reader.iter_messages(starting_at=1_000_000_000 + 1000 * 540_000,
                                           ending_before=1_000_000_000 + 1010 * 540_000))
        assert [json.loads(message.data)["handle_force_x_N"] for _, _, message in window] == [
            0.1 * i for i in range(1000, 1010)]


def test_full_queue_drops_and_counts(tmp_path: Path) -> None:
    recorder = McapRecorder(tmp_path / "drops.mcap", "master", queue_size=5)
    recorder.add_channel("/master/state", ("time_s",))
    accepted = [recorder.record("/master/state", i, (float(i),)) for i in range(12)]
    assert accepted == [True] * 5 + [False] * 7
    assert recorder.dropped == 7 and recorder.dropped_by_channel == {"/master/state": 7}
    recorder.open()
    recorder.close()
    recording = read_recording(tmp_path / "drops.mcap")
    assert recording.counts() == {"/master/state": 5}
    assert recording.metadata["recorder"]["dropped"] == "7"


WRITER = textwrap.dedent("""
    import sys, time
    from haptic.common.records.recorder import _WRITER_CHUNK_INDEXES, McapRecorder
    recorder = McapRecorder(sys.argv[1], "slave", chunk_size=4096).open()
    recorder.add_channel("/slave/state", ("time_s", "tool_force_x_N"))
    i = 0
    while True:
        recorder.record("/slave/state", time.time_ns(), (i * 1e-3, 1.0))
        i += 1
        if i % 100 == 0:
            time.sleep(0.002)
""")


def test_sigkilled_writer_leaves_a_readable_file(tmp_path: Path) -> None:
    path = tmp_path / "killed.mcap"
    with Program([sys.executable, "-c", WRITER, str(path)]) as writer:
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline:
            if path.exists() and path.stat().st_size > 40_000:
                break
            time.sleep(0.05)
        writer.stop(signal.SIGKILL)
    assert path.stat().st_size > 40_000
    recording = read_recording(path)
    assert not recording.complete
    values = recording.columns("/slave/state")["time_s"]
    assert values.size > 100
    # Every message up to the last complete chunk, in order, none missing.
    assert json.dumps(list(values[:3])) == json.dumps([0.0, 0.001, 0.002])
    assert (abs(values[1:] - values[:-1] - 1e-3) < 1e-9).all()
