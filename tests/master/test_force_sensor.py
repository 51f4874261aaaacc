"""The force sensor's DBC frame and the counts <-> newtons conversion."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from haptic.master.hardware.force_sensor import (
    STATUS_INVALID,
    STATUS_OK,
    ForceSample,
    ForceSensorCodec,
    load_database,
)


def _codec() -> ForceSensorCodec:
    return ForceSensorCodec((0.005, -0.01), (12.0, -3.0))


def test_packaged_dbc_describes_the_sensor_frame() -> None:
    message = load_database().get_message_by_name("ForceSensor")
    assert message.frame_id == 0x190
    assert message.length == 8
    assert {s.name for s in message.signals} == {"ForceX", "ForceY", "Counter", "Status"}


@given(x=st.integers(-32768, 32767), y=st.integers(-32768, 32767), counter=st.integers(0, 255),
       status=st.integers(0, 255))
def test_frame_round_trips(x: int, y: int, counter: int, status: int) -> None:
    codec = _codec()
    sample = ForceSample(x, y, counter, status)
    payload = codec.encode(sample)
    assert len(payload) == 8
    assert codec.decode(payload) == sample


def test_counts_to_newtons_uses_scale_and_offset() -> None:
    codec = _codec()
    force = codec.to_newtons(ForceSample(212, -103, 0, STATUS_OK))
    np.testing.assert_allclose(force, [0.005 * 200, -0.01 * -100])


@given(fx=st.floats(-150, 150), fy=st.floats(-300, 300))
def test_newtons_to_counts_round_trips_within_one_count(fx: float, fy: float) -> None:
    codec = _codec()
    x, y, saturated = codec.to_counts(np.array([fx, fy]))
    assert not saturated
    back = codec.to_newtons(ForceSample(x, y, 0, STATUS_OK))
    assert abs(back[0] - fx) <= 0.5 * 0.005 + 1e-12
    assert abs(back[1] - fy) <= 0.5 * 0.01 + 1e-12


def test_saturation_is_flagged_and_a_bad_status_gives_nan() -> None:
    codec = _codec()
    x, _, saturated = codec.to_counts(np.array([1e6, 0.0]))
    assert saturated and x == 32767
    force = codec.to_newtons(ForceSample(10, 10, 0, STATUS_INVALID))
    assert all(math.isnan(f) for f in force)
