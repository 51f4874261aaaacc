"""The two-channel handle force sensor's CAN frame, described by a DBC file (cantools).

The DBC (``dbc/force_sensor.dbc``, package data) carries raw counts; the conversion to
newtons, ``force_N = scale_N_per_count * (count - offset_count)``, uses the configured scale
and offset, so a recalibration never edits the DBC.
"""

from __future__ import annotations

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

    def encode(self, sample: ForceSample) -> bytes:
        """Frame payload for ``sample`` (raises on values outside the signals' ranges)."""
        return self.message.encode(
            {"ForceX": sample.raw_x_count, "ForceY": sample.raw_y_count,
             "Counter": sample.counter, "Status": sample.status}
        )

    def decode(self, payload: bytes) -> ForceSample:
        """Decode a frame payload into raw counts."""
        values = self.message.decode(bytes(payload), decode_choices=False, scaling=False)
        return ForceSample(int(values["ForceX"]), int(values["ForceY"]), int(values["Counter"]),
                           int(values["Status"]))

    def to_newtons(self, sample: ForceSample) -> np.ndarray:
        """Force (N) along x, y; NaN on both channels unless the status is ok, so a bad
        sample can never be mistaken for a force."""
        if sample.status != STATUS_OK:
            return np.full(2, np.nan)
        raw = np.array([sample.raw_x_count, sample.raw_y_count], float)
        return self.scale_N_per_count * (raw - self.offset_count)

    def to_counts(self, force_N: np.ndarray) -> tuple[int, int, bool]:
        """Raw counts for a force (N): (x, y, saturated); saturates at the 16-bit range."""
        raw = np.rint(np.asarray(force_N, float) / self.scale_N_per_count + self.offset_count)
        saturated = bool(np.any(np.abs(raw) > RAW_LIMIT))
        raw = np.clip(raw, -RAW_LIMIT, RAW_LIMIT)
        return int(raw[0]), int(raw[1]), saturated
