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


@given(x=st.integers(-32768, 32767), y=st.integers(-32768, 32767),
       status=st.one_of(st.just(STATUS_OK), st.integers(0, 255)))
def test_the_drivers_scalar_newtons_are_the_arrays_values(x: int, y: int, status: int) -> None:
    """``newtons`` (two floats, the driver's read) gives what ``to_newtons`` gives, bit for
    bit: the same arithmetic as the array's, NaN on both channels unless the status is ok."""
    codec = _codec()
    sample = ForceSample(x, y, 0, status)
    scalars = codec.newtons(sample)
    array = codec.to_newtons(sample)
    assert all(type(value) is float for value in scalars)
    if status == STATUS_OK:
        assert scalars == tuple(float(v) for v in np.array([0.005, -0.01]) * (
            np.array([x, y], float) - np.array([12.0, -3.0])))
    else:
        assert all(math.isnan(value) for value in scalars)
    np.testing.assert_array_equal(array, np.array(scalars))


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


# --- the struct fast path against cantools -------------------------------------------------

_OTHER_LAYOUT_DBC = """VERSION ""
NS_ :
BS_:
BU_: MASTER FORCE_SENSOR
BO_ 400 ForceSensor: 8 FORCE_SENSOR
 SG_ ForceX : 7|16@0- (1,0) [-32768|32767] "count" MASTER
 SG_ ForceY : 23|16@0- (1,0) [-32768|32767] "count" MASTER
 SG_ Counter : 32|8@1+ (1,0) [0|255] "" MASTER
 SG_ Status : 40|8@1+ (1,0) [0|255] "" MASTER
"""


@given(x=st.integers(-32768, 32767), y=st.integers(-32768, 32767), counter=st.integers(0, 255),
       status=st.integers(0, 255), tail=st.binary(max_size=3))
def test_struct_codec_gives_cantools_bytes_and_values(x: int, y: int, counter: int, status: int,
                                                      tail: bytes) -> None:
    codec = _codec()
    assert codec._layout is not None  # the packaged frame takes the struct path
    values = {"ForceX": x, "ForceY": y, "Counter": counter, "Status": status}
    payload = codec.encode(ForceSample(x, y, counter, status))
    assert payload == codec.message.encode(values)
    # bytes beyond the frame are ignored by both
    decoded = codec.message.decode(payload + tail, decode_choices=False, scaling=False)
    assert codec.decode(payload + tail) == ForceSample(decoded["ForceX"], decoded["ForceY"],
                                                       decoded["Counter"], decoded["Status"])


def test_struct_codec_refuses_what_cantools_refuses() -> None:
    import cantools
    import pytest

    codec = _codec()
    for sample in (ForceSample(40000, 0, 0, 0), ForceSample(0, -32769, 0, 0),
                   ForceSample(0, 0, 256, 0), ForceSample(0, 0, 0, -1)):
        with pytest.raises(cantools.database.errors.EncodeError):
            codec.encode(sample)
    with pytest.raises(cantools.database.errors.DecodeError):
        codec.decode(b"\x01\x02\x03")


def test_a_layout_struct_cannot_pack_goes_through_cantools() -> None:
    import cantools

    from haptic.master.hardware.force_sensor import packed_layout

    database = cantools.database.load_string(_OTHER_LAYOUT_DBC, database_format="dbc")
    assert packed_layout(database.get_message_by_name("ForceSensor")) is None
    codec = ForceSensorCodec((0.005, -0.01), (12.0, -3.0), database)
    assert codec._layout is None
    sample = ForceSample(-1234, 4321, 7, 0)
    payload = codec.encode(sample)
    assert payload[:2] == (-1234).to_bytes(2, "big", signed=True)  # big-endian, as the DBC says
    assert codec.decode(payload) == sample


@given(fx=st.floats(-400.0, 400.0), fy=st.floats(-400.0, 400.0))
def test_to_counts_matches_numpy_rounding_and_saturation(fx: float, fy: float) -> None:
    codec = _codec()
    raw = np.rint(np.array([fx, fy]) / codec.scale_N_per_count + codec.offset_count)
    expected = np.clip(raw, -32767, 32767)
    x, y, saturated = codec.to_counts(np.array([fx, fy]))
    assert (x, y) == (int(expected[0]), int(expected[1]))
    assert saturated == bool(np.any(np.abs(raw) > 32767))


def test_to_counts_rounds_half_to_even_and_holds_infinities() -> None:
    codec = ForceSensorCodec((1.0, 1.0), (0.0, 0.0))
    assert codec.to_counts(np.array([2.5, -3.5]))[:2] == (2, -4)
    assert codec.to_counts(np.array([math.inf, -math.inf])) == (32767, -32767, True)
