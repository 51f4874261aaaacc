"""The CAN bus-load budget of one control cycle: the frames' bit-times with worst-case bit
stuffing against the sample period Ts.

Classical CAN, 11-bit identifier, n data bytes (Davis, Burns, Bril and Lukkien 2007): the
stuffed part (SOF to CRC) is 34 + 8n bits, at most one stuff bit per 4 of them after the
first, and 13 bits follow unstuffed (CRC delimiter, ACK, EOF, intermission)::

    bits(n) = 47 + 8n + floor((34 + 8n - 1) / 4)      (55 for n = 0, 115 for 6, 135 for 8)

CAN FD with bit-rate switch, 11-bit identifier: the arbitration phase at the nominal rate
(SOF to BRS, 17 bits with up to 4 stuff bits, and CRC delimiter, ACK, EOF, intermission,
13 bits) and the data phase at the data rate (ESI, DLC, the data with up to one stuff bit in
4, the stuff count and the CRC, 17 bits up to 16 data bytes, 21 above, with their fixed
stuff bits, one per 4)::

    nominal(n) = 17 + 4 + 13 = 34 bits
    data(n)    = 5 + 8L + floor((5 + 8L - 1) / 4) + (4 + crc) + ceil((4 + crc) / 4)

where L is n rounded up to the next FD data length (0-8, 12, 16, 20, 24, 32, 48, 64).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

FD_LENGTHS = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)


def classic_frame_bits(data_bytes: int) -> int:
    """Bit-times of a classical CAN frame (11-bit id) with worst-case stuffing."""
    stuffed = 34 + 8 * data_bytes
    return stuffed + 13 + (stuffed - 1) // 4


def fd_length(data_bytes: int) -> int:
    """The CAN FD data length that carries ``data_bytes`` (padded)."""
    for length in FD_LENGTHS:
        if length >= data_bytes:
            return length
    raise ValueError(f"a CAN FD frame carries at most 64 bytes (got {data_bytes})")


def fd_frame_time_s(data_bytes: int, bitrate: float, data_bitrate: float) -> float:
    """Duration of a CAN FD frame (11-bit id, bit-rate switch) with worst-case stuffing, s."""
    length = fd_length(data_bytes)
    crc = 17 if length <= 16 else 21
    dynamic = 5 + 8 * length
    data_bits = dynamic + (dynamic - 1) // 4 + (4 + crc) + math.ceil((4 + crc) / 4)
    return 34 / bitrate + data_bits / data_bitrate


@dataclass(frozen=True)
class CycleFrame:
    """One frame of the cycle: what it is and its payload, bytes."""

    name: str
    data_bytes: int


@dataclass(frozen=True)
class BusLoad:
    """The budget: each frame's time, the cycle's total against Ts, the limit."""

    frames: tuple[tuple[str, float], ...]
    cycle_s: float
    sample_period_s: float
    limit: float
    fd: bool
    bitrate: int
    data_bitrate: int

    @property
    def load(self) -> float:
        """Fraction of Ts the cycle's frames occupy the bus (worst case)."""
        return self.cycle_s / self.sample_period_s

    @property
    def ok(self) -> bool:
        """True when the load is within the limit."""
        return self.load <= self.limit

    def summary(self) -> str:
        """One line: the frames, the total, the load and the limit."""
        bus = (f"CAN FD {self.bitrate / 1e6:g}/{self.data_bitrate / 1e6:g} Mbit/s" if self.fd
               else f"classical CAN {self.bitrate / 1e6:g} Mbit/s")
        frames = ", ".join(f"{name} {time_s * 1e6:.1f} us" for name, time_s in self.frames)
        return (f"bus load {self.load:.0%} of Ts = {self.sample_period_s * 1e6:.0f} us on "
                f"{bus} ({self.cycle_s * 1e6:.1f} us per cycle with worst-case stuffing: "
                f"{frames}; limit {self.limit:.0%})")

    def refusal(self) -> str:
        """Why the cycle does not fit, and the options."""
        return (f"{self.summary()}: the bus cannot carry the loop. Options: a longer Ts "
                f"([model] sample_period_s >= {self.cycle_s / self.limit * 1e6:.0f} us), fewer "
                "frames per cycle (e.g. the force sensor on its own bus), a higher bitrate, "
                "or CAN FD ([master.can] fd = true, data_bitrate)")


def cycle_frames(sensor_bytes: int = 8, sync_bytes: int = 0,
                 tpdo_bytes: tuple[int, ...] = (6, 6),
                 rpdo_bytes: tuple[int, ...] = (6, 6)) -> tuple[CycleFrame, ...]:
    """The frames of one control cycle: SYNC (``sync_bytes``: 1 with the SYNC counter), both
    drives' TPDO (statusword + position, 6 bytes where the driver maps it; ``tpdo_bytes``,
    x then y: a static mapping may carry more), the sensor frame, both RPDOs (controlword +
    target, ``rpdo_bytes``)."""
    return (CycleFrame("SYNC", sync_bytes), CycleFrame("TPDO1 x", tpdo_bytes[0]),
            CycleFrame("TPDO1 y", tpdo_bytes[1]), CycleFrame("sensor", sensor_bytes),
            CycleFrame("RPDO1 x", rpdo_bytes[0]), CycleFrame("RPDO1 y", rpdo_bytes[1]))


def bus_load(sample_period_s: float, bitrate: int, fd: bool, data_bitrate: int,
             limit: float, heartbeat_period_s: float = 0.0,
             frames: tuple[CycleFrame, ...] | None = None) -> BusLoad:
    """The budget of ``frames`` (default :func:`cycle_frames`) per Ts; with a heartbeat
    period, the three heartbeats (master and both drives, classical, 1 byte) prorated per
    cycle."""
    frames = cycle_frames() if frames is None else frames
    timed: list[tuple[str, float]] = []
    for frame in frames:
        time_s = (fd_frame_time_s(frame.data_bytes, bitrate, data_bitrate) if fd
                  else classic_frame_bits(frame.data_bytes) / bitrate)
        timed.append((frame.name, time_s))
    if heartbeat_period_s > 0.0:
        share = sample_period_s / heartbeat_period_s
        timed.append(("heartbeats", 3 * classic_frame_bits(1) / bitrate * share))
    total = sum(time_s for _, time_s in timed)
    return BusLoad(tuple(timed), total, sample_period_s, limit, fd, bitrate, data_bitrate)
