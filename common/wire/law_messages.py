"""The wire schema of the comparison's lane laws (wave variables, four-channel,
model-mediated): what each side of such a law sends the other over a real link.

These laws do not exchange the programs' :class:`~haptic.common.wire.messages.HandleState`
and :class:`~haptic.common.wire.messages.ToolState`; each sends a vector of floats whose
meaning and length its control declares (:data:`LAW_CHANNELS`): wave variables a wave, its
integral and its energy per axis, four-channel a position, velocity and force per axis (with
the TDPA on its ports, the cumulative energy its passivity observer handed over after them),
model-mediated the handle's position and velocity one way and the environment model's four
fields the other. The message has the programs' header, so the receive path's ordering,
injection and counters (common/wire/receive.py) apply unchanged::

    [version, kind, epoch, seq, send_time_ns, flags, *values]

``version`` is :data:`~haptic.common.wire.messages.SCHEMA_VERSION`; ``kind`` names the
control and the direction (:func:`law_kind`: a program's receiver drops it as
``wrong_kind``, and a receiver of another law as well, so a mismatched pair never mixes
channels; such a pair does not start at all, its pairing hellos naming different controls:
common/wire/link.py); ``epoch``, ``seq``, ``send_time_ns`` and ``flags`` as in messages.py;
``values`` exactly the declared number of msgpack float 64s, every one finite.

:meth:`LawSchema.decode` never lets an exception other than
:class:`~haptic.common.wire.messages.DecodeError` escape; its reason says which counter the
receiver charges (``malformed``: not msgpack, wrong shape, types or length;
``unknown_version``; ``wrong_kind``; ``non_finite``).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from typing import Any

import msgpack

from haptic.common.wire.messages import (
    FLAGS_BY_VALUE,
    SCHEMA_VERSION,
    DecodeError,
    DropReason,
    Flags,
    send_time_bytes,
)

#: Each law's (handle, tool) payload lengths, floats: master to slave, slave to master. The
#: order fixes the kinds (:func:`law_kind`): a new law goes at the end.
LAW_CHANNELS: dict[str, tuple[int, int]] = {
    "wave": (6, 6),
    "four-channel": (6, 6),
    "mmt": (4, 8),
    "four-channel-tdpa": (7, 7),
}
DIRECTIONS = ("handle", "tool")
#: The first law kind; the programs' kinds are 1 (handle) and 2 (tool).
FIRST_LAW_KIND = 16
#: The header's items (version, kind, epoch, seq, send time, flags).
HEADER_LENGTH = 6
#: The most values a message may carry: the receive path's flood filter passes msgpack
#: arrays of at most 31 items (common/wire/receive.py).
MAX_VALUES = 31 - HEADER_LENGTH
_MAX_PAYLOAD_BYTES = 1024
_MAX_U32 = 2**32 - 1
_MAX_U63 = 2**63 - 1
_MAX_FLAGS = 0xFF
_F64 = 0xCB
_packer = msgpack.Packer(use_bin_type=True, use_single_float=False)


def law_kind(control: str, direction: str) -> int:
    """The message kind of ``control``'s messages in ``direction`` ("handle": master to
    slave, "tool": slave to master). Raises ValueError for an unknown one."""
    if control not in LAW_CHANNELS:
        raise ValueError(f"control must be one of {', '.join(LAW_CHANNELS)} (got {control!r})")
    if direction not in DIRECTIONS:
        raise ValueError(f"direction must be one of {', '.join(DIRECTIONS)}")
    return FIRST_LAW_KIND + 2 * list(LAW_CHANNELS).index(control) + DIRECTIONS.index(direction)


@dataclass(frozen=True, slots=True)
class LawMessage:
    """One law message as received: the header's fields and the law's ``values`` (their
    units are the law's: m, m/s, N, the wave's sqrt(W), the model's N/m and N s/m)."""

    kind: int
    epoch: int
    seq: int
    send_time_ns: int
    flags: Flags
    values: tuple[float, ...]


@dataclass(frozen=True)
class LawSchema:
    """The messages of one control in one direction: their ``kind`` and payload ``length``
    (floats), both derived from the control and the direction."""

    control: str
    direction: str
    kind: int = field(init=False)
    length: int = field(init=False)
    _body: struct.Struct = field(init=False, repr=False, compare=False)
    _header: bytes = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        kind = law_kind(self.control, self.direction)  # validates both
        length = LAW_CHANNELS[self.control][DIRECTIONS.index(self.direction)]
        if not 0 < length <= MAX_VALUES:
            raise ValueError(f"a law message carries 1 to {MAX_VALUES} values")
        object.__setattr__(self, "kind", kind)
        object.__setattr__(self, "length", length)
        object.__setattr__(self, "_body", struct.Struct(">" + "Bd" * length))
        object.__setattr__(self, "_header", _packer.pack_array_header(HEADER_LENGTH + length)
                           + _packer.pack(SCHEMA_VERSION) + _packer.pack(kind))

    def encode_around_send_time(self, epoch: int, seq: int, flags: int,
                                values: tuple[float, ...] | list[float]) -> tuple[bytes, bytes]:
        """The msgpack bytes before and after the send time (the payload is
        ``before + send_time_bytes(t) + after``, as messages.py's). Raises ValueError for a
        wrong length, a non-finite value or a header field out of range."""
        floats = [float(v) for v in values]
        if len(floats) != self.length:
            raise ValueError(f"{self.control} {self.direction} messages carry {self.length} "
                             f"values (got {len(floats)})")
        if not all(map(math.isfinite, floats)):
            raise ValueError(f"non-finite value in a {self.control} message: {floats}")
        if not (0 <= epoch <= _MAX_U32 and 0 <= seq <= _MAX_U63 and 0 <= flags <= _MAX_FLAGS):
            raise ValueError(f"header out of range: epoch {epoch}, seq {seq}, flags {flags}")
        pack = _packer.pack
        before = self._header + pack(int(epoch)) + pack(int(seq))
        body = self._body.pack(*(item for value in floats for item in (_F64, value)))
        return before, pack(int(flags)) + body

    def encode(self, message: LawMessage) -> bytes:
        """The msgpack bytes of ``message`` (its kind must be this schema's)."""
        if message.kind != self.kind:
            raise ValueError(f"kind {message.kind} is not {self.control} {self.direction}")
        before, after = self.encode_around_send_time(message.epoch, message.seq,
                                                     int(message.flags), message.values)
        return before + send_time_bytes(message.send_time_ns) + after

    def decode(self, payload: bytes, expected_kind: int | None = None) -> LawMessage:
        """Parse and validate one message of this schema (``expected_kind``, the receive
        path's, must be this schema's kind when given). Raises DecodeError only."""
        if expected_kind is not None and expected_kind != self.kind:
            raise DecodeError(DropReason.WRONG_KIND,
                              f"the receiver expects kind {expected_kind}, not {self.kind}")
        fields = _unpack(payload)
        version, kind, epoch, seq, send_time_ns, flags = fields[:HEADER_LENGTH]
        if type(version) is not int:
            raise DecodeError(DropReason.MALFORMED, f"version {version!r} is not an integer")
        if version != SCHEMA_VERSION:
            raise DecodeError(DropReason.UNKNOWN_VERSION, f"version {version}", version)
        if type(kind) is not int:
            raise DecodeError(DropReason.MALFORMED, f"kind {kind!r} is not an integer")
        if kind != self.kind:
            raise DecodeError(DropReason.WRONG_KIND, f"kind {kind}, expected {self.kind}")
        _check_header(epoch, seq, send_time_ns, flags)
        body = fields[HEADER_LENGTH:]
        if len(body) != self.length:
            raise DecodeError(DropReason.MALFORMED, f"{self.control} {self.direction} "
                              f"payload has {len(body)} values, not {self.length}")
        known = FLAGS_BY_VALUE.get(flags)
        return LawMessage(kind, epoch, seq, send_time_ns,
                          Flags(flags) if known is None else known, _finite_floats(body))


def _unpack(payload: bytes) -> list[Any]:
    """The msgpack array of a payload with at least a header; DecodeError(malformed)."""
    if len(payload) > _MAX_PAYLOAD_BYTES:
        raise DecodeError(DropReason.MALFORMED, f"{len(payload)} bytes is too long")
    try:
        fields = msgpack.unpackb(payload, use_list=True, raw=False, strict_map_key=True)
    except Exception as error:  # msgpack raises many types for corrupt input
        raise DecodeError(DropReason.MALFORMED, f"not msgpack: {type(error).__name__}") from None
    if type(fields) is not list or len(fields) < HEADER_LENGTH:
        raise DecodeError(DropReason.MALFORMED, "not an array with a header")
    return fields


def _check_header(epoch: Any, seq: Any, send_time_ns: Any, flags: Any) -> None:
    """The header's integers in range (``type(x) is int``: msgpack's true/false decode as
    bool, which is not one here); DecodeError(malformed)."""
    for name, value, largest in (("epoch", epoch, _MAX_U32), ("seq", seq, _MAX_U63),
                                 ("send_time_ns", send_time_ns, _MAX_U63),
                                 ("flags", flags, _MAX_FLAGS)):
        if not (type(value) is int and 0 <= value <= largest):
            raise DecodeError(DropReason.MALFORMED, f"{name} {value!r}")


def _finite_floats(values: list[Any]) -> tuple[float, ...]:
    """The payload as finite floats: DecodeError(malformed) for a non-number,
    DecodeError(non_finite) for a NaN or an infinity."""
    for value in values:
        if type(value) not in (float, int):
            raise DecodeError(DropReason.MALFORMED, f"payload value {value!r} is not a number")
    floats = tuple(float(v) for v in values)
    if not all(map(math.isfinite, floats)):
        raise DecodeError(DropReason.NON_FINITE, f"non-finite payload {floats}")
    return floats


__all__ = ["DIRECTIONS", "FIRST_LAW_KIND", "LAW_CHANNELS", "MAX_VALUES", "LawMessage",
           "LawSchema", "law_kind"]
