"""The CAN driver's force reading (master/hardware/force_reading.py) on its own: a valid frame
becomes the codec's newtons with no fault; a counter that does not follow the last one by one
(modulo 256) is a fault that keeps the force; a malformed frame, a status other than ok and
counts that scale beyond a float are each a fault with NaN on both axes."""

from __future__ import annotations

import math

import pytest

from haptic.master.hardware.force_reading import ForceSensorReader
from haptic.master.hardware.force_sensor import (
    STATUS_INVALID,
    STATUS_OK,
    STATUS_OVERLOAD,
    ForceSample,
    ForceSensorCodec,
)

SCALE_N_PER_COUNT = (0.01, 0.02)
OFFSET_COUNT = (10.0, -4.0)


@pytest.fixture(scope="module")
def codec() -> ForceSensorCodec:
    return ForceSensorCodec(SCALE_N_PER_COUNT, OFFSET_COUNT)


def frame(codec: ForceSensorCodec, counter: int, x: int = 110, y: int = 46,
          status: int = STATUS_OK) -> bytes:
    return codec.encode(ForceSample(x, y, counter, status))


def test_a_valid_frame_is_the_codecs_force_without_a_fault(codec: ForceSensorCodec) -> None:
    reader = ForceSensorReader(codec)
    faults: list[str] = []
    assert reader.counter is None
    assert reader.force(frame(codec, 7), faults) == pytest.approx((1.0, 1.0))
    assert reader.force(frame(codec, 8, x=-90, y=-54), faults) == pytest.approx((-1.0, -1.0))
    assert faults == []
    assert reader.counter == 8


def test_the_counter_wraps_from_255_to_0_without_a_fault(codec: ForceSensorCodec) -> None:
    reader = ForceSensorReader(codec)
    faults: list[str] = []
    for counter in (254, 255, 0, 1):
        reader.force(frame(codec, counter), faults)
    assert faults == []
    assert reader.counter == 1


@pytest.mark.parametrize(("last", "now"), [(5, 7), (5, 5), (5, 4), (255, 1), (0, 255)])
def test_a_counter_that_does_not_follow_is_a_fault_the_force_kept(
        codec: ForceSensorCodec, last: int, now: int) -> None:
    reader = ForceSensorReader(codec)
    faults: list[str] = []
    reader.force(frame(codec, last), faults)
    assert faults == []
    assert reader.force(frame(codec, now), faults) == pytest.approx((1.0, 1.0))
    assert faults == [f"force sensor counter jumped from {last} to {now} "
                      "(a stale or lost sample)"]
    assert reader.counter == now
    reader.force(frame(codec, (now + 1) % 256), faults)
    assert len(faults) == 1  # the next in turn from the jumped-to counter is fine


def test_a_malformed_frame_is_a_fault_with_nan_and_keeps_the_counter(
        codec: ForceSensorCodec) -> None:
    reader = ForceSensorReader(codec)
    faults: list[str] = []
    reader.force(frame(codec, 3), faults)
    x, y = reader.force(b"\x01\x02", faults)
    assert math.isnan(x) and math.isnan(y)
    assert len(faults) == 1 and faults[0].startswith("force sensor frame malformed: ")
    assert reader.counter == 3


@pytest.mark.parametrize("status", [STATUS_OVERLOAD, STATUS_INVALID])
def test_a_status_other_than_ok_is_a_fault_with_nan(codec: ForceSensorCodec,
                                                      status: int) -> None:
    reader = ForceSensorReader(codec)
    faults: list[str] = []
    x, y = reader.force(frame(codec, 9, status=status), faults)
    assert math.isnan(x) and math.isnan(y)
    assert faults == [f"force sensor status {status} (not ok)"]
    assert reader.counter == 9  # a sample, if not a force: its counter counts


@pytest.mark.parametrize(("raw_x", "raw_y"), [(30000, 46), (110, 30000), (30000, 30000)])
def test_counts_beyond_a_float_in_newtons_are_a_fault_with_nan(raw_x: int,
                                                               raw_y: int) -> None:
    codec = ForceSensorCodec((1e305, 1e305), (0.0, 0.0))
    reader = ForceSensorReader(codec)
    faults: list[str] = []
    x, y = reader.force(frame(codec, 0, x=raw_x, y=raw_y), faults)
    assert math.isnan(x) and math.isnan(y)
    assert faults == [f"force sensor counts ({raw_x}, {raw_y}) are not finite in N: see "
                      "[master.can] force_scale_N_per_count and force_offset_count"]
