"""The two-channel handle force sensor's CAN frame, described by a DBC file (cantools).

The DBC (``dbc/force_sensor.dbc``, package data) carries raw counts; the conversion to
newtons, ``force_N = scale_N_per_count * (count - offset_count)``, uses the configured scale
and offset, so a recalibration never edits the DBC.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import cantools
import numpy as np

MESSAGE_NAME = "ForceSensor"
STATUS_OK = 0
STATUS_OVERLOAD = 1
STATUS_INVALID = 2
RAW_LIMIT = 32767


def load_database(path: str | Path | None = None) -> cantools.database.can.Database:
    """The force sensor DBC: the packaged one, or the file at ``path``."""
    if path:
        return cantools.database.load_file(str(path))
    text = resources.files("haptic.master.hardware").joinpath("dbc/force_sensor.dbc").read_text()
    return cantools.database.load_string(text, database_format="dbc")


#: struct codes of whole-byte little-endian integer signals, by (bits, signed).
_STRUCT_CODES = {(8, False): "B", (8, True): "b", (16, False): "H", (16, True): "h",
                 (32, False): "I", (32, True): "i", (64, False): "Q", (64, True): "q"}


@dataclass(frozen=True)
class _PackedLayout:
    """A message whose signals struct can pack as they are: their order in the payload, the
    struct, and each signal's (minimum, maximum) as the DBC states them (None: none)."""

    names: tuple[str, ...]
    codec: struct.Struct
    limits: tuple[tuple[int | float | None, int | float | None], ...]


def packed_layout(message: cantools.database.can.Message) -> _PackedLayout | None:
    """The struct layout of ``message`` when every signal is a little-endian integer on
    whole bytes with scale 1 and offset 0, none overlapping, no multiplexing (the packaged
    sensor frame); ``None`` otherwise (cantools then encodes and decodes every frame)."""
    if message.is_multiplexed():
        return None
    signals = sorted(message.signals, key=lambda signal: signal.start)
    parts, position = ["<"], 0
    for signal in signals:
        code = _STRUCT_CODES.get((signal.length, bool(signal.is_signed)))
        if (code is None or signal.is_float or signal.byte_order != "little_endian"
                or signal.start % 8 or signal.start < position or signal.scale != 1
                or signal.offset != 0):
            return None
        parts.append("x" * ((signal.start - position) // 8) + code)
        position = signal.start + signal.length
    if position > 8 * message.length:
        return None
    parts.append("x" * ((8 * message.length - position) // 8))
    return _PackedLayout(tuple(signal.name for signal in signals), struct.Struct("".join(parts)),
                         tuple((signal.minimum, signal.maximum) for signal in signals))


@dataclass(frozen=True)
class ForceSample:
    """One decoded sensor frame: raw counts per channel, sample counter, status code."""

    raw_x_count: int
    raw_y_count: int
    counter: int
    status: int


class ForceSensorCodec:
    """Encode/decode the sensor frame and convert counts <-> newtons (x, y)."""

    def __init__(
        self,
        scale_N_per_count: tuple[float, float],
        offset_count: tuple[float, float],
        database: cantools.database.can.Database | None = None,
    ) -> None:
        self.database = database if database is not None else load_database()
        self.message = self.database.get_message_by_name(MESSAGE_NAME)
        self.frame_id: int = self.message.frame_id
        self.scale_N_per_count = np.asarray(scale_N_per_count, float)
        self.offset_count = np.asarray(offset_count, float)
        self._scale = tuple(float(v) for v in self.scale_N_per_count)
        self._offset = tuple(float(v) for v in self.offset_count)
        # struct packs the frame at each SYNC on both sides (several times cheaper than
        # cantools); cantools does what struct cannot: another layout, a bad value or payload
        layout = packed_layout(self.message)
        self._layout = layout if layout is not None and set(layout.names) == {
            "ForceX", "ForceY", "Counter", "Status"} else None

    def encode(self, sample: ForceSample) -> bytes:
        """Frame payload for ``sample`` (raises on values outside the signals' ranges)."""
        return self.encode_counts(sample.raw_x_count, sample.raw_y_count, sample.counter,
                                  sample.status)

    def encode_counts(self, raw_x_count: int, raw_y_count: int, counter: int,
                      status: int) -> bytes:
        """:meth:`encode` of the sample's four fields (the emulated sensor's path at each
        SYNC, without building a :class:`ForceSample`)."""
        values = {"ForceX": raw_x_count, "ForceY": raw_y_count, "Counter": counter,
                  "Status": status}
        layout = self._layout
        if layout is not None:
            ordered = [values[name] for name in layout.names]
            for value, (low, high) in zip(ordered, layout.limits, strict=True):
                if type(value) is not int or (low is not None and value < low) or (
                        high is not None and value > high):
                    break
            else:
                try:
                    return layout.codec.pack(*ordered)
                except struct.error:
                    pass  # beyond the signal's bits: cantools says why
        return self.message.encode(values)

    def decode(self, payload: bytes) -> ForceSample:
        """Decode a frame payload into raw counts (raises on a payload shorter than the
        message; bytes beyond it are ignored, as cantools does)."""
        layout = self._layout
        if layout is not None and len(payload) >= layout.codec.size:
            values = dict(zip(layout.names, layout.codec.unpack_from(payload), strict=True))
        else:
            values = self.message.decode(bytes(payload), decode_choices=False, scaling=False)
        return ForceSample(int(values["ForceX"]), int(values["ForceY"]), int(values["Counter"]),
                           int(values["Status"]))

    def to_newtons(self, sample: ForceSample) -> np.ndarray:
        """Force (N) along x, y; NaN on both channels unless the status is ok, so a bad
        sample can never be mistaken for a force."""
        return np.array(self.newtons(sample))

    def newtons(self, sample: ForceSample) -> tuple[float, float]:
        """:meth:`to_newtons` as two floats (N), without an array (the driver's read at
        each SYNC)."""
        if sample.status != STATUS_OK:
            return math.nan, math.nan
        scale, offset = self._scale, self._offset
        return (scale[0] * (sample.raw_x_count - offset[0]),
                scale[1] * (sample.raw_y_count - offset[1]))

    def to_counts(self, force_N: np.ndarray) -> tuple[int, int, bool]:
        """Raw counts for a force (N): (x, y, saturated); saturates at the 16-bit range,
        rounding half to even (ValueError on a NaN force)."""
        x, x_saturated = _count(float(force_N[0]) / self._scale[0] + self._offset[0])
        y, y_saturated = _count(float(force_N[1]) / self._scale[1] + self._offset[1])
        return x, y, x_saturated or y_saturated


def _count(value: float) -> tuple[int, bool]:
    """``value`` rounded half to even and held to +-RAW_LIMIT, and whether it was held."""
    if math.isinf(value):
        return int(math.copysign(RAW_LIMIT, value)), True
    count = round(value)  # ValueError on NaN
    held = min(max(count, -RAW_LIMIT), RAW_LIMIT)
    return held, held != count
