"""The shared-memory feed between a loop and its ROS 2 bridge (common/ros2/feed.py): what is
written is read once, a record caught mid-write or malformed is skipped and counted, and a
feed file of the wrong size is refused."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from haptic.common.ros2.feed import (
    STATE_OFFSET,
    STATUS_BYTES,
    STATUS_OFFSET,
    FeedReader,
    FeedWriter,
    state_values,
)


@pytest.fixture
def feed() -> FeedWriter:
    writer = FeedWriter((4, 8))
    yield writer
    writer.close()


def test_each_record_is_read_once_as_written(feed: FeedWriter) -> None:
    reader = FeedReader(feed.path, (4, 8))
    try:
        assert reader.state() is None and reader.status() is None and reader.clay() is None
        feed.write_state(state_values(1.5, (3.6, -0.1), (0.02, 0.001), None, (3.5, 0.0),
                                      (1000, 3)))
        feed.write_status({"watchdog_state": "ok", "link_loss_ratio": 0.25, "trips": 2,
                           "events": [1, 2], "safe_state": False})
        heights = np.arange(32.0).reshape(4, 8) * 1e-3
        feed.write_clay(heights)
        state = reader.state()
        assert state == {"time_s": 1.5, "force_N": (3.6, -0.1), "position_m": (0.02, 0.001),
                         "effort_N": (3.5, 0.0), "loop_ticks": 1000.0, "loop_overruns": 3.0}
        assert reader.status() == {"watchdog_state": "ok", "link_loss_ratio": 0.25,
                                   "trips": 2, "safe_state": False}  # scalars only
        assert np.array_equal(reader.clay(), heights)
        assert reader.state() is None and reader.status() is None  # nothing new
        assert np.array_equal(reader.clay(), heights)  # the newest map stays
        feed.write_state(state_values(1.6, (1.0, 2.0), (0.0, 0.0), (0.1, 0.2), None, (1, 0)))
        newer = reader.state()
        assert newer is not None and newer["velocity_m_s"] == (0.1, 0.2)
        assert "effort_N" not in newer
        reader.write_counters({"published": 7, "connected": 1})
        assert feed.counters() == {"published": 7, "unwatched_skips": 0, "open_failures": 0,
                                   "publish_errors": 0, "connected": 1}
    finally:
        reader.close()


def test_a_record_caught_mid_write_is_skipped_and_counted(feed: FeedWriter) -> None:
    reader = FeedReader(feed.path, (4, 8))
    try:
        feed.write_state(state_values(1.0, (1.0, 1.0), (0.0, 0.0), None, None, (1, 0)))
        buffer = feed._buffer  # the writer's mapping: make its sequence odd, as mid-write
        sequence = struct.unpack_from("<Q", buffer, STATE_OFFSET)[0]
        struct.pack_into("<Q", buffer, STATE_OFFSET, sequence + 1)
        assert reader.state() is None and reader.torn_reads == 1
        struct.pack_into("<Q", buffer, STATE_OFFSET, sequence + 2)
        state = reader.state()
        assert state is not None and state["time_s"] == 1.0
    finally:
        reader.close()


def test_a_malformed_or_oversized_status_is_dropped_and_counted(feed: FeedWriter) -> None:
    reader = FeedReader(feed.path, (4, 8))
    try:
        feed.write_status({"note": "x" * (STATUS_BYTES + 1)})
        assert feed.status_dropped == 1 and reader.status() is None
        buffer = feed._buffer
        struct.pack_into("<QQ", buffer, STATUS_OFFSET, 2, 5)
        buffer[STATUS_OFFSET + 16:STATUS_OFFSET + 21] = b"{nope"
        assert reader.status() is None and reader.bad_status == 1
        struct.pack_into("<QQ", buffer, STATUS_OFFSET, 4, STATUS_BYTES + 10)  # length lies
        assert reader.status() is None
        struct.pack_into("<QQ", buffer, STATUS_OFFSET, 6, 2)
        buffer[STATUS_OFFSET + 16:STATUS_OFFSET + 18] = b"[]"
        assert reader.status() is None and reader.bad_status == 2
    finally:
        reader.close()


def test_non_finite_figures_travel_as_they_are_for_the_publisher_to_judge(
        feed: FeedWriter) -> None:
    reader = FeedReader(feed.path, (4, 8))
    try:
        feed.write_state(state_values(0.0, (math.inf, 0.0), (math.nan, 0.0), None, None,
                                      (0, 0)))
        state = reader.state()
        assert state is not None and math.isinf(state["force_N"][0])
        assert math.isnan(state["position_m"][0])
    finally:
        reader.close()


def test_a_feed_of_another_size_is_refused(feed: FeedWriter) -> None:
    with pytest.raises(ValueError, match="bytes was expected"):
        FeedReader(feed.path, (8, 8))
    with pytest.raises(ValueError, match="cells"):
        FeedWriter((0, 8))
