"""The decoder's limits pinned at the value: each range check accepts its last valid value and
refuses the next one, the flags keep their wire values, floats travel as float64."""

from __future__ import annotations

import dataclasses
import math

import msgpack
import pytest

from haptic.common.wire.messages import (
    FLAGS_BY_VALUE,
    KIND_HANDLE,
    KIND_TOOL,
    SCHEMA_VERSION,
    DecodeError,
    DropReason,
    Flags,
    HandleState,
    ToolState,
    decode,
    encode,
    encode_tool_around_send_time,
)

MAX_U32 = 2**32 - 1
MAX_U63 = 2**63 - 1


def _handle(epoch=1, seq=2, send=3, flags=2,
            floats=(0.5, -0.5, 0.01, 0.02, 13.0, 0.0, 1.0)) -> bytes:
    return msgpack.packb([SCHEMA_VERSION, KIND_HANDLE, epoch, seq, send, flags, *floats])


def _tool(engagement=0.5, volume=1e-9, flags=2, echo=0) -> bytes:
    return msgpack.packb([SCHEMA_VERSION, KIND_TOOL, 1, 2, 3, flags,
                          1.0, 2.0, 0.1, 0.2, 0.0, 0.0, engagement, volume, 0.0, echo])


def _refused(payload: bytes, kind: int = KIND_HANDLE) -> DecodeError:
    with pytest.raises(DecodeError) as caught:
        decode(payload, kind)
    return caught.value


def test_wire_values_of_the_kinds_and_flags() -> None:
    # 3: gain k and echo, 4: energy fields, 5: TDPA_SWITCHED and the force scale (#16)
    assert (SCHEMA_VERSION, KIND_HANDLE, KIND_TOOL) == (5, 1, 2)
    assert (int(Flags.SAFE_STATE), int(Flags.FORCES_ENABLED), int(Flags.IN_CONTACT),
            int(Flags.TDPA)) == (1, 2, 4, 8)
    wire = msgpack.unpackb(encode(ToolState(0, 0, 0, Flags.IN_CONTACT | Flags.SAFE_STATE,
                                            (0.0, 0.0), (0.0, 0.0), (0.0, 0.0), 0.0, 0.0)))
    assert wire[1] == 2 and wire[5] == 5


@pytest.mark.parametrize("flags", [0, 1, 2, 4, 3, 6, 7])
def test_flag_properties_read_each_bit_alone(flags: int) -> None:
    handle = decode(_handle(flags=flags), KIND_HANDLE)
    tool = decode(_tool(flags=flags), KIND_TOOL)
    for message in (handle, tool):
        assert message.safe_state is bool(flags & 1)
        assert message.forces_enabled is bool(flags & 2)
    assert tool.in_contact is bool(flags & 4)


def test_floats_travel_as_float64() -> None:
    sent = HandleState(1, 2, 3, Flags.FORCES_ENABLED, (0.1, -1.0 / 3.0), (1e-7, 2.0 / 3.0))
    assert decode(encode(sent), KIND_HANDLE) == sent
    tool = ToolState(1, 2, 3, Flags(0), (0.1, 0.2), (0.3, 1e-7), (1.0 / 3.0, 0.7), 0.1, 1e-12)
    assert decode(encode(tool), KIND_TOOL) == tool


def test_messages_are_frozen_and_slotted() -> None:
    message = decode(_handle(), KIND_HANDLE)
    with pytest.raises(dataclasses.FrozenInstanceError):
        message.seq = 5
    tool = decode(_tool(), KIND_TOOL)
    with pytest.raises(dataclasses.FrozenInstanceError):
        tool.seq = 5
    assert not hasattr(message, "__dict__") and not hasattr(tool, "__dict__")


def test_payload_length_limit_is_1024_bytes() -> None:
    at_limit = msgpack.packb("a" * 1021)  # str16: 3 header bytes + 1021
    assert len(at_limit) == 1024
    assert _refused(at_limit).args[0] != "1024 bytes is too long"
    assert "not an array" in str(_refused(at_limit))
    over = msgpack.packb("a" * 1022)
    assert len(over) == 1025
    assert "1025 bytes is too long" in str(_refused(over))


def test_a_header_needs_six_fields() -> None:
    header_only = msgpack.packb([SCHEMA_VERSION, KIND_HANDLE, 1, 2, 3, 0])
    assert "handle payload has 0 values" in str(_refused(header_only))
    short = msgpack.packb([SCHEMA_VERSION, KIND_HANDLE, 1, 2, 3])
    assert "not an array with a header" in str(_refused(short))


@pytest.mark.parametrize(("field", "last"), [("epoch", MAX_U32), ("seq", MAX_U63),
                                             ("send", MAX_U63), ("flags", 0xFF)])
def test_header_integers_accept_their_last_value_and_refuse_the_next(field, last) -> None:
    decoded = decode(_handle(**{field: last}), KIND_HANDLE)
    assert {"epoch": decoded.epoch, "seq": decoded.seq, "send": decoded.send_time_ns,
            "flags": int(decoded.flags)}[field] == last
    decode(_handle(**{field: 0}), KIND_HANDLE)
    for bad in (last + 1, -1):
        error = _refused(_handle(**{field: bad}))
        assert error.reason is DropReason.MALFORMED


@pytest.mark.parametrize("engagement", [0.0, 1.0])
def test_engagement_accepts_both_ends_of_0_to_1(engagement: float) -> None:
    assert decode(_tool(engagement=engagement), KIND_TOOL).clay_engagement == engagement


@pytest.mark.parametrize("engagement", [-1e-12, 1.0 + 1e-12])
def test_engagement_outside_0_to_1_is_refused(engagement: float) -> None:
    error = _refused(_tool(engagement=engagement), KIND_TOOL)
    assert error.reason is DropReason.MALFORMED
    assert str(error) == f"malformed: clay_engagement {engagement} outside 0..1"


def test_removed_volume_may_be_zero_never_negative() -> None:
    assert decode(_tool(volume=0.0), KIND_TOOL).removed_volume_m3 == 0.0
    error = _refused(_tool(volume=-1e-15), KIND_TOOL)
    assert str(error) == "malformed: removed_volume_m3 -1e-15 is negative"


# The schema-4 fields (#16, #19): handle gain_k and energy_J, tool energy_J and echo.
def _handle4(gain_k: float = 13.0, energy_J: float = 0.0, force_scale: float = 1.0) -> bytes:
    return msgpack.packb([SCHEMA_VERSION, KIND_HANDLE, 1, 2, 3, 2,
                          0.5, -0.5, 0.01, 0.02, gain_k, energy_J, force_scale])


def _tool4(energy_J: float = 0.0, echo: object = 0) -> bytes:
    return msgpack.packb([SCHEMA_VERSION, KIND_TOOL, 1, 2, 3, 2,
                          1.0, 2.0, 0.1, 0.2, 0.0, 0.0, 0.5, 1e-9, energy_J, echo])


def _tool_state(echo: int = 0, energy_J: float = 0.0) -> ToolState:
    return ToolState(1, 2, 3, Flags(2), (1.0, 2.0), (0.1, 0.2), (0.0, 0.0), 0.5, 1e-9,
                     echo, energy_J=energy_J)


def test_defaults_of_the_schema_4_fields_are_zero() -> None:
    handle = HandleState(1, 2, 3, Flags(2), (0.0, 0.0), (0.0, 0.0))
    tool = ToolState(1, 2, 3, Flags(2), (0.0, 0.0), (0.0, 0.0), (0.0, 0.0), 0.0, 0.0)
    assert (handle.gain_k, handle.energy_J) == (0.0, 0.0)
    assert (tool.echo_send_time_ns, tool.energy_J) == (0, 0.0)


def test_handle_gain_and_energy_round_trip_in_their_places() -> None:
    sent = HandleState(1, 2, 3, Flags(2), (0.5, -0.5), (0.01, 0.02), 13.25, energy_J=0.75,
                       force_scale=0.25)
    got = decode(encode(sent), KIND_HANDLE)
    assert got == sent
    assert (got.gain_k, got.energy_J, got.force_scale) == (13.25, 0.75, 0.25)
    assert msgpack.unpackb(encode(sent))[-3:] == [13.25, 0.75, 0.25]  # scale last


def test_tool_energy_and_echo_round_trip_in_their_places() -> None:
    sent = _tool_state(echo=123_456_789, energy_J=0.5)
    got = decode(encode(sent), KIND_TOOL)
    assert got == sent
    assert (got.echo_send_time_ns, got.energy_J) == (123_456_789, 0.5)


@pytest.mark.parametrize("gain_k", [0.0, 1e-300, 13.0])
def test_gain_k_may_be_zero_or_positive(gain_k: float) -> None:
    assert decode(_handle4(gain_k=gain_k), KIND_HANDLE).gain_k == gain_k


@pytest.mark.parametrize("gain_k", [-1e-300, -13.0])
def test_negative_gain_k_is_refused(gain_k: float) -> None:
    error = _refused(_handle4(gain_k=gain_k), KIND_HANDLE)
    assert error.reason is DropReason.MALFORMED
    assert str(error) == f"malformed: gain_k {gain_k} is negative"


@pytest.mark.parametrize("energy_J", [0.0, 1e-300, 2.5])
def test_energy_may_be_zero_or_positive_on_both_messages(energy_J: float) -> None:
    assert decode(_handle4(energy_J=energy_J), KIND_HANDLE).energy_J == energy_J
    assert decode(_tool4(energy_J=energy_J), KIND_TOOL).energy_J == energy_J


@pytest.mark.parametrize("energy_J", [-1e-300, -2.5])
def test_negative_energy_is_refused_on_both_messages(energy_J: float) -> None:
    for payload, kind in ((_handle4(energy_J=energy_J), KIND_HANDLE),
                          (_tool4(energy_J=energy_J), KIND_TOOL)):
        error = _refused(payload, kind)
        assert error.reason is DropReason.MALFORMED
        assert str(error) == f"malformed: energy_J {energy_J} is negative"


@pytest.mark.parametrize("echo", [0, 1, MAX_U63])
def test_echo_accepts_0_to_max_u63_on_decode_and_encode(echo: int) -> None:
    assert decode(_tool4(echo=echo), KIND_TOOL).echo_send_time_ns == echo
    assert decode(encode(_tool_state(echo=echo)), KIND_TOOL).echo_send_time_ns == echo


@pytest.mark.parametrize("echo", [-1, MAX_U63 + 1, 1.0, True])
def test_echo_outside_u63_or_not_an_int_is_refused_on_decode(echo: object) -> None:
    error = _refused(_tool4(echo=echo), KIND_TOOL)
    assert error.reason is DropReason.MALFORMED
    assert str(error) == f"malformed: echo_send_time_ns {echo!r}"


@pytest.mark.parametrize("echo", [-1, MAX_U63 + 1])
def test_echo_outside_u63_is_refused_on_encode(echo: int) -> None:
    with pytest.raises(ValueError, match=f"echo_send_time_ns {echo} out of range"):
        encode(_tool_state(echo=echo))


@pytest.mark.parametrize("field", range(9))
def test_any_one_non_finite_tool_value_is_refused_on_encode(field: int) -> None:
    values = [1.0, 2.0, 0.1, 0.2, 0.0, 0.0, 0.5, 1e-9, 0.0]
    values[field] = math.nan
    fx, fy, px, py, vx, vy, engagement, volume, energy = values
    with pytest.raises(ValueError, match="non-finite value in ToolState"):
        encode_tool_around_send_time(1, 2, 2, (fx, fy), (px, py), (vx, vy), engagement,
                                     volume, 0, energy)


def test_the_largest_flags_byte_is_encoded() -> None:
    before, after = encode_tool_around_send_time(1, 2, 0xFF, (1.0, 2.0), (0.1, 0.2),
                                                 (0.0, 0.0), 0.5, 1e-9, 0, 0.0)
    message = decode(before + msgpack.packb(3) + after, KIND_TOOL)
    assert int(message.flags) == 0xFF
    with pytest.raises((IndexError, ValueError)):  # beyond a byte: never encoded
        encode_tool_around_send_time(1, 2, 0x100, (1.0, 2.0), (0.1, 0.2), (0.0, 0.0), 0.5,
                                     1e-9, 0, 0.0)


def test_a_force_scale_of_0_to_1_is_accepted() -> None:
    for scale in (0.0, 1.0):
        floats = (0.5, -0.5, 0.01, 0.02, 13.0, 0.0, scale)
        assert decode(_handle(floats=floats), KIND_HANDLE).force_scale == scale
    for scale in (-1e-9, 1.0 + 1e-9):
        assert "force_scale" in str(_refused(_handle(floats=(0.5, -0.5, 0.01, 0.02, 13.0,
                                                              0.0, scale))))


def test_the_flags_table_holds_exactly_every_combination_of_the_defined_flags() -> None:
    """FLAGS_BY_VALUE has the keys 0..127 (the seven flags' combinations), each its own
    Flags."""
    assert list(FLAGS_BY_VALUE) == list(range(128))
    assert all(type(flags) is Flags and int(flags) == value
               for value, flags in FLAGS_BY_VALUE.items())
    assert 128 not in FLAGS_BY_VALUE  # a bit no flag defines: the callers' lookup refuses it
    assert int(decode(_handle(flags=128 | 2), KIND_HANDLE).flags) == 130  # decode reads it
