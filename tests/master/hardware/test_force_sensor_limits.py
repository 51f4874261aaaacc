"""The force sensor's codec at its edges (master/hardware/force_sensor.py): the status codes
the DBC defines, which layouts the struct fast path takes and which it leaves to cantools,
the DBC's value ranges kept on the fast path, the fallback decode's raw counts, and the
saturation at exactly the 16-bit limit. What the device sends is trusted only this far:
a frame decodes to counts, and only a frame whose status is "ok" becomes a force."""

from __future__ import annotations

import dataclasses
import math

import cantools
import numpy as np
import pytest

from haptic.master.hardware.force_sensor import (
    RAW_LIMIT,
    STATUS_INVALID,
    STATUS_OK,
    STATUS_OVERLOAD,
    ForceSample,
    ForceSensorCodec,
    load_database,
    packed_layout,
)


def message(signals: str, length: int = 8, extra: str = "") -> cantools.database.can.Message:
    """A one-message DBC (frame 400, ``length`` bytes) with ``signals`` (SG_ lines, each
    received by the master)."""
    lines = [line + " MASTER" for line in signals.split("\n")]
    text = (f'VERSION ""\nNS_ :\nBS_:\nBU_: MASTER FORCE_SENSOR\n'
            f"BO_ 400 ForceSensor: {length} FORCE_SENSOR\n" + "\n".join(lines) + f"\n{extra}\n")
    database = cantools.database.load_string(text, database_format="dbc", strict=False)
    result = database.get_message_by_name("ForceSensor")
    assert len(result.signals) == len(lines)  # every signal parsed
    return result


def sensor_database(x_range: str = "[-32768|32767]", status_range: str = "[0|255]",
                    x_type: str = "0|16@1-", extra: str = "") -> cantools.database.can.Database:
    """The packaged frame's four signals with ForceX's range, type and Status's range as
    given."""
    text = ('VERSION ""\nNS_ :\nBS_:\nBU_: MASTER FORCE_SENSOR\n'
            "BO_ 400 ForceSensor: 8 FORCE_SENSOR\n"
            f' SG_ ForceX : {x_type} (1,0) {x_range} "count" MASTER\n'
            ' SG_ ForceY : 16|16@1- (1,0) [-32768|32767] "count" MASTER\n'
            ' SG_ Counter : 32|8@1+ (1,0) [0|255] "" MASTER\n'
            f' SG_ Status : 40|8@1+ (1,0) {status_range} "" MASTER\n{extra}\n')
    return cantools.database.load_string(text, database_format="dbc", strict=False)


def test_the_status_codes_are_the_dbcs() -> None:
    status = load_database().get_message_by_name("ForceSensor").get_signal_by_name("Status")
    assert dict(status.choices) == {0: "ok", 1: "overload", 2: "invalid"}
    assert (STATUS_OK, STATUS_OVERLOAD, STATUS_INVALID) == (0, 1, 2)
    assert RAW_LIMIT == 32767


def test_only_a_frame_whose_status_byte_is_ok_becomes_a_force() -> None:
    codec = ForceSensorCodec((0.5, 0.25), (0.0, 0.0))
    frame = bytearray((100).to_bytes(2, "little", signed=True)
                      + (-8).to_bytes(2, "little", signed=True) + bytes([7, 0, 0, 0]))
    assert codec.newtons(codec.decode(bytes(frame))) == (50.0, -2.0)
    for status in (1, 2, 3, 255):
        frame[5] = status
        sample = codec.decode(bytes(frame))
        assert sample == ForceSample(100, -8, 7, status)
        assert all(math.isnan(value) for value in codec.newtons(sample))


def test_the_codecs_records_are_frozen() -> None:
    layout = packed_layout(load_database().get_message_by_name("ForceSensor"))
    assert layout is not None
    with pytest.raises(dataclasses.FrozenInstanceError):
        layout.names = ()  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        ForceSample(0, 0, 0, 0).status = 1  # type: ignore[misc]


@pytest.mark.parametrize(("signals", "length", "fmt"), [
    (' SG_ A : 0|8@1+ (1,0) [0|0] ""\n SG_ B : 8|8@1- (1,0) [0|0] ""\n'
     ' SG_ C : 16|16@1+ (1,0) [0|0] ""\n SG_ D : 32|16@1- (1,0) [0|0] ""', 8, "<BbHhxx"),
    (' SG_ A : 0|32@1+ (1,0) [0|0] ""\n SG_ B : 32|32@1- (1,0) [0|0] ""', 8, "<Ii"),
    (' SG_ A : 0|64@1+ (1,0) [0|0] ""', 8, "<Q"),
    (' SG_ A : 0|64@1- (1,0) [0|0] ""', 8, "<q"),
    (' SG_ A : 0|8@1+ (1,0) [0|0] ""\n SG_ B : 24|8@1+ (1,0) [0|0] ""', 8, "<BxxBxxxx"),
    (' SG_ A : 48|16@1+ (1,0) [0|0] ""', 8, "<xxxxxxH"),  # ends on the frame's last bit
])
def test_whole_byte_little_endian_integers_take_the_struct_path(signals: str, length: int,
                                                                  fmt: str) -> None:
    layout = packed_layout(message(signals, length))
    assert layout is not None and layout.codec.format == fmt


@pytest.mark.parametrize("signals", [
    ' SG_ A : 0|12@1+ (1,0) [0|0] ""',  # no struct code for 12 bits
    ' SG_ A : 0|16@0+ (1,0) [0|0] ""',  # big-endian
    ' SG_ A : 4|8@1+ (1,0) [0|0] ""',  # not on a byte
    ' SG_ A : 0|16@1+ (1,0) [0|0] ""\n SG_ B : 8|8@1+ (1,0) [0|0] ""',  # overlapping
    ' SG_ A : 0|16@1+ (2,0) [0|0] ""',  # scaled
    ' SG_ A : 0|16@1+ (1,5) [0|0] ""',  # offset
    ' SG_ A : 56|16@1+ (1,0) [0|0] ""',  # beyond the frame
])
def test_every_other_layout_is_left_to_cantools(signals: str) -> None:
    assert packed_layout(message(signals)) is None


def test_a_float_signal_is_left_to_cantools() -> None:
    signals = ' SG_ A : 0|32@1- (1,0) [0|0] ""'
    assert packed_layout(message(signals)) is not None  # as an integer it would pack
    assert packed_layout(message(signals, extra="SIG_VALTYPE_ 400 A : 1;")) is None


def test_a_multiplexed_message_is_left_to_cantools() -> None:
    signals = (' SG_ M M : 0|8@1+ (1,0) [0|0] ""\n SG_ A m0 : 8|8@1+ (1,0) [0|0] ""\n'
               ' SG_ B m1 : 8|8@1+ (1,0) [0|0] ""')
    assert packed_layout(message(signals)) is None


def test_the_fast_path_keeps_the_dbcs_ranges_at_their_ends() -> None:
    """A DBC may state a narrower range than the signal's bits: the fast path packs the
    ends and refuses one count beyond, as cantools does."""
    codec = ForceSensorCodec((1.0, 1.0), (0.0, 0.0), sensor_database("[-1000|1000]", "[0|2]"))
    assert codec._layout is not None
    for x in (-1000, 1000):
        assert codec.encode_counts(x, 0, 0, 2) == codec.message.encode(
            {"ForceX": x, "ForceY": 0, "Counter": 0, "Status": 2})
    for x, status in ((-1001, 0), (1001, 0), (0, 3)):
        with pytest.raises(cantools.database.errors.EncodeError):
            codec.encode_counts(x, 0, 0, status)


def test_beyond_the_bits_without_a_range_is_cantools_error_not_structs() -> None:
    codec = ForceSensorCodec((1.0, 1.0), (0.0, 0.0), sensor_database("[0|0]"))
    assert codec._layout is not None and codec._layout.limits[0] == (None, None)
    assert codec.decode(codec.encode_counts(-32768, 0, 0, 0)).raw_x_count == -32768
    with pytest.raises(OverflowError):
        codec.encode_counts(70000, 0, 0, 0)


def test_the_sensors_frame_never_calls_cantools_at_a_sync(monkeypatch: pytest.MonkeyPatch
                                                          ) -> None:
    """Whole counts in range are packed, and a frame of exactly the message's length is
    unpacked, by struct (cantools costs 20-30 us a frame); anything else goes to cantools."""
    codec = ForceSensorCodec((1.0, 1.0), (0.0, 0.0))
    calls: list[str] = []
    encode, decode = codec.message.encode, codec.message.decode
    monkeypatch.setattr(codec.message, "encode",
                        lambda *a, **k: calls.append("encode") or encode(*a, **k))
    monkeypatch.setattr(codec.message, "decode",
                        lambda *a, **k: calls.append("decode") or decode(*a, **k))
    payload = codec.encode_counts(-32768, 32767, 255, 0)
    assert codec.decode(payload) == ForceSample(-32768, 32767, 255, 0)
    assert calls == []
    assert codec.encode_counts(1.0, 0, 0, 0) == codec.encode_counts(1, 0, 0, 0)  # type: ignore
    assert calls == ["encode"]
    with pytest.raises(cantools.database.errors.DecodeError):
        codec.decode(payload[:7])
    assert calls == ["encode", "decode"]


def test_the_cantools_path_decodes_raw_counts_and_codes() -> None:
    """A layout struct cannot pack (here ForceX big-endian and scaled, Status with named
    values) decodes to raw counts and the status code, never scaled values or names."""
    database = sensor_database(x_type="7|16@0-", extra='VAL_ 400 Status 0 "ok" 1 "overload" ;')
    text = database.as_dbc_string().replace("ForceX : 7|16@0- (1,0)", "ForceX : 7|16@0- (2,0)")
    database = cantools.database.load_string(text, database_format="dbc", strict=False)
    codec = ForceSensorCodec((1.0, 1.0), (0.0, 0.0), database)
    assert codec._layout is None
    frame = (-300).to_bytes(2, "big", signed=True) + (5).to_bytes(2, "little") + bytes([3, 1])
    assert codec.decode(frame + b"\x00\x00") == ForceSample(-300, 5, 3, 1)


def test_counts_saturate_only_beyond_the_limit() -> None:
    codec = ForceSensorCodec((1.0, 1.0), (0.0, 0.0))
    assert codec.to_counts(np.array([32767.0, -32767.0])) == (32767, -32767, False)
    assert codec.to_counts(np.array([32768.0, 0.0])) == (32767, 0, True)
    assert codec.to_counts(np.array([0.0, -32768.0])) == (0, -32767, True)
    assert codec.to_counts(np.array([-math.inf, 1.0])) == (-32767, 1, True)
    assert all(type(value) is int for value in codec.to_counts(np.array([math.inf, 0.4]))[:2])
    with pytest.raises(ValueError):
        codec.to_counts(np.array([math.nan, 0.0]))
