"""The wire schema: round trips, classification of bad payloads, fuzzing of decode."""

from __future__ import annotations

import math

import msgpack
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from haptic.common.wire.messages import (
    KIND_HANDLE,
    KIND_TOOL,
    SCHEMA_VERSION,
    DecodeError,
    DropReason,
    Flags,
    HandleState,
    ToolState,
    control_mismatch,
    decode,
    encode,
)

finite = st.floats(allow_nan=False, allow_infinity=False, width=64)
pair = st.tuples(finite, finite)


@settings(deadline=None)
@given(
    epoch=st.integers(0, 2**32 - 1), seq=st.integers(0, 2**63 - 1),
    send=st.integers(0, 2**63 - 1), flags=st.integers(0, 7), force=pair, position=pair,
)
def test_handle_state_round_trip(epoch, seq, send, flags, force, position):
    message = HandleState(epoch, seq, send, Flags(flags), force, position)
    assert decode(encode(message), KIND_HANDLE) == message


@settings(deadline=None)
@given(
    seq=st.integers(0, 2**63 - 1), force=pair, position=pair, velocity=pair,
    engagement=st.floats(0.0, 1.0), volume=st.floats(0.0, 1.0), flags=st.integers(0, 7),
)
def test_tool_state_round_trip(seq, force, position, velocity, engagement, volume, flags):
    message = ToolState(7, seq, 123, Flags(flags), force, position, velocity, engagement, volume)
    decoded = decode(encode(message), KIND_TOOL)
    assert decoded == message
    assert decoded.in_contact == bool(flags & Flags.IN_CONTACT)
    assert decoded.safe_state == bool(flags & Flags.SAFE_STATE)


def test_wire_layout_is_a_compact_array():
    message = HandleState(5, 9, 1000, Flags.FORCES_ENABLED, (1.0, 2.0), (0.1, 0.2), 13.0)
    assert msgpack.unpackb(encode(message)) == [
        SCHEMA_VERSION, KIND_HANDLE, 5, 9, 1000, 2, 1.0, 2.0, 0.1, 0.2, 13.0, 0.0, 1.0
    ]
    tool = ToolState(5, 9, 1000, Flags(0), (1.0, 2.0), (0.1, 0.2), (0.0, 0.0), 0.5, 0.0, 777)
    assert msgpack.unpackb(encode(tool))[-1] == 777  # the echoed send time, last


def test_gain_and_echo_are_validated():
    handle = msgpack.packb([SCHEMA_VERSION, KIND_HANDLE, 1, 2, 3, 0, 0.0, 0.0, 0.0, 0.0, -1.0,
                            0.0, 1.0])
    with pytest.raises(DecodeError, match="gain_k"):
        decode(handle, KIND_HANDLE)
    handle = msgpack.packb([SCHEMA_VERSION, KIND_HANDLE, 1, 2, 3, 0, 0.0, 0.0, 0.0, 0.0, 1.0,
                            -1e-9, 1.0])
    with pytest.raises(DecodeError, match="energy_J"):
        decode(handle, KIND_HANDLE)
    for scale in (-1e-9, 1.0 + 1e-9):  # the force ramp's factor is 0..1
        handle = msgpack.packb([SCHEMA_VERSION, KIND_HANDLE, 1, 2, 3, 0, 0.0, 0.0, 0.0, 0.0,
                                1.0, 0.0, scale])
        with pytest.raises(DecodeError, match="force_scale"):
            decode(handle, KIND_HANDLE)
    fields = _valid_tool_fields()
    fields[-2] = -1e-9
    with pytest.raises(DecodeError, match="energy_J"):
        decode(msgpack.packb(fields), KIND_TOOL)
    fields = _valid_tool_fields()
    fields[-1] = -5
    with pytest.raises(DecodeError, match="echo_send_time_ns"):
        decode(msgpack.packb(fields), KIND_TOOL)
    fields[-1] = 1.5
    with pytest.raises(DecodeError, match="echo_send_time_ns"):
        decode(msgpack.packb(fields), KIND_TOOL)


def test_encode_refuses_non_finite():
    with pytest.raises(ValueError):
        encode(HandleState(0, 0, 0, Flags(0), (math.nan, 0.0), (0.0, 0.0)))


flag_values = st.integers(0, 63)
wide_send = st.integers(2**32, 2**63 - 1)  # where msgpack itself writes a uint64 too


@settings(deadline=None)
@given(epoch=st.integers(0, 2**32 - 1), seq=st.integers(0, 2**63 - 1), send=wide_send,
       flags=flag_values, values=st.lists(finite, min_size=7, max_size=7))
def test_handle_bytes_are_msgpacks_own(epoch, seq, send, flags, values):
    """The field-wise encoder writes what msgpack writes for the message's field list."""
    values[4:7] = abs(values[4]), abs(values[5]), min(abs(values[6]), 1.0)
    message = HandleState(epoch, seq, send, Flags(flags), tuple(values[0:2]),
                          tuple(values[2:4]), *values[4:7])
    fields = [SCHEMA_VERSION, KIND_HANDLE, epoch, seq, send, flags, *values]
    assert encode(message) == msgpack.packb(fields, use_single_float=False)


@settings(deadline=None)
@given(epoch=st.integers(0, 2**32 - 1), seq=st.integers(0, 2**63 - 1), send=wide_send,
       flags=flag_values, values=st.lists(finite, min_size=9, max_size=9),
       echo=st.integers(0, 2**63 - 1))
def test_tool_bytes_are_msgpacks_own(epoch, seq, send, flags, values, echo):
    values[6:9] = min(abs(values[6]), 1.0), abs(values[7]), abs(values[8])
    message = ToolState(epoch, seq, send, Flags(flags), tuple(values[0:2]), tuple(values[2:4]),
                        tuple(values[4:6]), values[6], values[7], echo, values[8])
    fields = [SCHEMA_VERSION, KIND_TOOL, epoch, seq, send, flags, *values, echo]
    assert encode(message) == msgpack.packb(fields, use_single_float=False)
    assert decode(encode(message), KIND_TOOL) == message


def test_payload_numbers_of_another_encoder_are_read_as_floats():
    """A peer may write whole numbers as integers or floats as float 32: the same message."""
    as_ints = [SCHEMA_VERSION, KIND_TOOL, 1, 2, 3, 0, 1, -2, 0, 0, 0, 0, 1, 0, 0, 0]
    decoded = decode(msgpack.packb(as_ints), KIND_TOOL)
    assert decoded == ToolState(1, 2, 3, Flags(0), (1.0, -2.0), (0.0, 0.0), (0.0, 0.0), 1.0,
                                0.0, 0, 0.0)
    assert all(type(v) is float for v in (*decoded.tool_force_N, decoded.clay_engagement))
    handle = [SCHEMA_VERSION, KIND_HANDLE, 1, 2, 3, 0, 0.5, 0.25, 0.125, 1.5, 13.0, 0.0, 1.0]
    assert decode(msgpack.packb(handle, use_single_float=True), KIND_HANDLE) == HandleState(
        1, 2, 3, Flags(0), (0.5, 0.25), (0.125, 1.5), 13.0, 0.0, 1.0)


def _valid_tool_fields() -> list:
    return [SCHEMA_VERSION, KIND_TOOL, 1, 2, 3, 0, 1.0, 2.0, 0.1, 0.2, 0.0, 0.0, 0.5, 1e-6,
            0.25, 0]


@pytest.mark.parametrize(
    ("change", "reason"),
    [
        (lambda f: f.__setitem__(0, SCHEMA_VERSION + 1), DropReason.UNKNOWN_VERSION),
        (lambda f: f.__setitem__(0, "1"), DropReason.MALFORMED),
        (lambda f: f.__setitem__(0, float(SCHEMA_VERSION)), DropReason.MALFORMED),
        (lambda f: f.__setitem__(1, float(KIND_TOOL)), DropReason.MALFORMED),
        (lambda f: f.__setitem__(1, True), DropReason.MALFORMED),
        (lambda f: f.__setitem__(1, KIND_HANDLE), DropReason.WRONG_KIND),
        (lambda f: f.__setitem__(3, -1), DropReason.MALFORMED),
        (lambda f: f.__setitem__(3, True), DropReason.MALFORMED),
        (lambda f: f.__setitem__(5, 256), DropReason.MALFORMED),
        (lambda f: f.__setitem__(7, math.inf), DropReason.NON_FINITE),
        (lambda f: f.__setitem__(8, math.nan), DropReason.NON_FINITE),
        (lambda f: f.__setitem__(9, "x"), DropReason.MALFORMED),
        (lambda f: f.__setitem__(10, True), DropReason.MALFORMED),
        (lambda f: f.__setitem__(11, None), DropReason.MALFORMED),
        (lambda f: f.__setitem__(15, 1.0), DropReason.MALFORMED),  # the echo is an integer
        (lambda f: f.__setitem__(12, 1.5), DropReason.MALFORMED),
        (lambda f: f.__setitem__(14, -1.0), DropReason.MALFORMED),  # energy is cumulative
        (lambda f: f.pop(), DropReason.MALFORMED),  # a version-2 tool payload
        (lambda f: f.__setitem__(13, -1.0), DropReason.MALFORMED),
        (lambda f: f.pop(), DropReason.MALFORMED),
        (lambda f: f.append(0.0), DropReason.MALFORMED),
    ],
)
def test_bad_fields_are_classified(change, reason):
    fields = _valid_tool_fields()
    change(fields)
    with pytest.raises(DecodeError) as caught:
        decode(msgpack.packb(fields), KIND_TOOL)
    assert caught.value.reason is reason


def test_not_msgpack_and_not_an_array_are_malformed():
    for payload in (b"", b"\xc1", b"\x92\x01", msgpack.packb({"a": 1}), msgpack.packb(1)):
        with pytest.raises(DecodeError) as caught:
            decode(payload, KIND_TOOL)
        assert caught.value.reason is DropReason.MALFORMED


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=200))
def test_decode_of_random_bytes_raises_only_decode_error(payload):
    try:
        decode(payload, KIND_HANDLE)
    except DecodeError:
        pass


json_like = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**63), 2**64 - 1) | st.floats() | st.text(max_size=5)
    | st.binary(max_size=5),
    lambda children: (
        st.lists(children, max_size=16) | st.dictionaries(st.text(max_size=3), children)
    ),
    max_leaves=30,
)


@settings(max_examples=300, deadline=None)
@given(json_like)
def test_decode_of_random_msgpack_structures_raises_only_decode_error(value):
    payload = msgpack.packb(value, use_bin_type=True)
    try:
        decode(payload, KIND_TOOL)
    except DecodeError:
        pass


def test_energy_travels_and_a_control_mismatch_is_named() -> None:

    message = HandleState(1, 2, 3, Flags.TDPA | Flags.FORCES_ENABLED, (1.0, 2.0), (0.1, 0.2),
                          energy_J=0.125)
    decoded = decode(encode(message), KIND_HANDLE)
    assert decoded.energy_J == 0.125
    assert control_mismatch("tdpa", decoded) is None
    assert 'mode = "tdpa"' in control_mismatch("paper", decoded)
    paper = ToolState(1, 2, 3, Flags(0), (0.0, 0.0), (0.0, 0.0), (0.0, 0.0), 0.0, 0.0)
    assert control_mismatch("paper", paper) is None
    assert 'mode = "paper"' in control_mismatch("tdpa", paper)


def test_the_flag_bits_are_the_wire_format() -> None:
    """Each flag is one bit of its own, at the value the wire has always carried: a peer of
    another build reads WORK_AREA_STOP without also reading SAFE_STATE, and the other way."""
    assert {flag.name: flag.value for flag in Flags} == {
        "SAFE_STATE": 1, "FORCES_ENABLED": 2, "IN_CONTACT": 4, "TDPA": 8,
        "WORK_AREA_STOP": 16, "TDPA_SWITCHED": 32, "STOPPING": 64}
    switched = decode(encode(HandleState(1, 1, 1, Flags.TDPA_SWITCHED, (0.0, 0.0), (0.0, 0.0))),
                      KIND_HANDLE)
    assert Flags.TDPA_SWITCHED in switched.flags and Flags.TDPA not in switched.flags
    assert control_mismatch("paper", switched) is None  # a run-time switch, not a mismatch
    stopped = decode(encode(ToolState(1, 1, 1, Flags.WORK_AREA_STOP, (0.0, 0.0), (0.0, 0.0),
                                      (0.0, 0.0), 0.0, 0.0)), KIND_TOOL)
    assert not stopped.safe_state and Flags.WORK_AREA_STOP in stopped.flags


def test_a_last_message_says_the_sender_stops() -> None:
    """STOPPING travels in both message kinds next to SAFE_STATE and reads back alone."""
    goodbye = Flags.SAFE_STATE | Flags.STOPPING
    handle = decode(encode(HandleState(1, 1, 1, goodbye, (0.0, 0.0), (0.0, 0.0))), KIND_HANDLE)
    tool = decode(encode(ToolState(1, 1, 1, goodbye, (0.0, 0.0), (0.0, 0.0), (0.0, 0.0), 0.0,
                                   0.0)), KIND_TOOL)
    assert handle.flags == tool.flags == goodbye
    assert handle.safe_state and not handle.forces_enabled
