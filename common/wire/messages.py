"""The wire schema of the master-slave link: the one module that owns it.

Every message is a msgpack array (compact: no field names on the wire)::

    [version, kind, epoch, seq, send_time_ns, flags, *payload]

``version``
    :data:`SCHEMA_VERSION`; a receiver drops any other value (``unknown_version``), and a
    peer of another version is refused at start (common/wire/link.py). Version 2 adds
    the pairing hello (common/wire/auth.py) and, on an authenticated link, a 16-byte tag after
    the msgpack body; version 3 the handle's ``gain_k`` and the tool's
    ``echo_send_time_ns``; version 4 ``energy_J`` in both payloads and the
    :attr:`Flags.TDPA` bit; version 5 the :attr:`Flags.TDPA_SWITCHED` bit (the
    margin governor's run-time switch to the passivity layer, which a version-4 slave would
    not follow) and the handle's ``force_scale``.
``kind``
    :data:`KIND_HANDLE` (master to slave, :class:`HandleState`) or :data:`KIND_TOOL` (slave to
    master, :class:`ToolState`).
``epoch``
    a number the sender draws once per run (unsigned 32 bit); a new epoch tells the receiver the
    peer restarted, so its sequence numbers start again.
``seq``
    the sender's message counter within the epoch (unsigned 63 bit), +1 per message.
``send_time_ns``
    the sender's ``CLOCK_REALTIME`` (:func:`time.time_ns`) when the message was handed to
    Zenoh, ns; always a msgpack uint64 (``0xcf`` and 8 big-endian bytes), so a sender can
    encode everything else first and stamp the time last (:func:`encode_around_send_time`).
``flags``
    a bit field of :class:`Flags`.
payload, :class:`HandleState` (7 floats)
    ``handle_force_N`` x, y; ``handle_position_m`` x, y; ``gain_k``, the Ch1 gain k the
    master's compensator uses now (> 0; 0: not said, the slave uses its configured k): the
    margin governor (master/margin_governor.py) lowers it and the slave follows;
    ``energy_J`` (>= 0); ``force_scale`` (0..1), the master's force ramp at this sample
    (master/node.py), which the slave applies to its Ct2's input so that both sides'
    Ct integrate the same scaled tool force.
payload, :class:`ToolState` (9 floats and an integer)
    ``tool_force_N`` x, y; ``tool_position_m`` x, y; ``tool_velocity_m_s`` x, y;
    ``clay_engagement`` (0..1); ``removed_volume_m3`` (>= 0); ``energy_J`` (>= 0);
    ``echo_send_time_ns``, the ``send_time_ns`` of the newest handle message the slave had
    used when it sent this one (0: none yet), so the master measures the loop's round trip
    on its own clock.

``energy_J`` is the sender's cumulative energy handed to the peer by the passivity layer
(common/model/passivity.py, ``[control] mode = "tdpa"``), J; monotone, so a lost message only
delays it. A sender in the paper's scheme leaves :attr:`Flags.TDPA` clear and sends the energy
its layer handed over while the governor had it switched on (:attr:`Flags.TDPA_SWITCHED`; 0
if never).

:func:`decode` never lets an exception other than :class:`DecodeError` escape; the error's
``reason`` (a :class:`DropReason`) says which counter the receiver charges.
"""

from __future__ import annotations

import enum
import math
import struct
from dataclasses import dataclass
from typing import Any

import msgpack

SCHEMA_VERSION = 5
KIND_HANDLE = 1
KIND_TOOL = 2

_HEADER_LENGTH = 6
_HANDLE_FLOATS = 7
_TOOL_FLOATS = 9
_TOOL_VALUES = _TOOL_FLOATS + 1  # the floats and the echoed send time
_MAX_U32 = 2**32 - 1
_MAX_U63 = 2**63 - 1
_MAX_FLAGS = 0xFF
_MAX_PAYLOAD_BYTES = 1024


class Flags(enum.IntFlag):
    """Status bits carried in every message."""

    SAFE_STATE = 1
    """The sender is in its safe state (master: handle held, no reflected force; slave: tool
    stopped)."""
    FORCES_ENABLED = 2
    """The sender applies forces (it is past the watchdog's re-synchronisation)."""
    IN_CONTACT = 4
    """Slave only: the tool touches the clay."""
    TDPA = 8
    """The sender runs the passivity layer (``[control] mode = "tdpa"``): its ``energy_J``
    is the energy it handed over. Both sides must agree (:func:`control_mismatch`)."""
    WORK_AREA_STOP = 16
    """Slave only: the work-area guard stopped the tool (it left the scenario's grid by more
    than the margin); the master holds its handle while this is set, so the handle does not
    run on alone."""
    TDPA_SWITCHED = 32
    """The sender runs the passivity layer switched on at run time (its configured mode is
    ``paper``): the master while its margin governor holds the switch on
    (master/margin_governor.py), the slave while it follows the master's flag. Unlike
    :attr:`TDPA` it is not a start-up mismatch: a ``paper`` slave switches its layer on and
    off with the master's flag (slave_sim/tick.py)."""
    STOPPING = 64
    """The sender ends its run: this is its last message, sent from its safe state before its
    link closes. The receiver's watchdog goes to its safe state at once and records a
    ``peer_ended`` event instead of a trip (common/runtime/watchdog.py), so an orderly end is
    not counted as a fault. A receiver that does not know the bit ignores it (the peer's
    liveliness token then trips its watchdog as before); the schema version is unchanged."""


#: Every combination of the flags by its int value (building an IntFlag from an int costs
#: about 1 us, too much per lane and tick in the lockstep's sweeps).
FLAGS_BY_VALUE = {value: Flags(value) for value in range(2 * max(Flags))}


def _flags_of(value: int) -> Flags:
    """``Flags(value)``, looked up where it can be (a decoded message's flags, every tick)."""
    flags = FLAGS_BY_VALUE.get(value)
    return Flags(value) if flags is None else flags


class DropReason(enum.StrEnum):
    """Why a received message was dropped; each has its own counter in the link statistics."""

    MALFORMED = "malformed"
    UNKNOWN_VERSION = "unknown_version"
    WRONG_KIND = "wrong_kind"
    NON_FINITE = "non_finite"
    STALE = "stale"
    OUT_OF_ORDER = "out_of_order"
    INJECTED_LOSS = "injected_loss"
    UNAUTHENTICATED = "unauthenticated"
    """Authenticated link: the tag does not verify under the session key (common/wire/auth.py)."""
    UNPAIRED = "unpaired"
    """Authenticated link: no pairing yet, or an epoch other than the paired peer's."""
    IMPLAUSIBLE = "implausible"
    """A send time or sequence number no real sender gives: sent more than ``stale_after_s``
    ahead of this host's clock, or a sequence number beyond what the sender could have
    sent since its newest message (common/wire/receive.py)."""
    PEER_RESTART = "peer_restart"
    """Accepted and waiting for its delivery time when the peer restarted (a new epoch):
    discarded undelivered."""


class DecodeError(ValueError):
    """A payload that is not a valid message of the expected kind."""

    def __init__(self, reason: DropReason, detail: str, version: int | None = None) -> None:
        super().__init__(f"{reason.value}: {detail}")
        self.reason = reason
        self.version = version
        """``unknown_version``: the message's version."""


@dataclass(frozen=True, slots=True)
class HandleState:
    """Master to slave: the operator's force on the handle and the handle's position.

    Forces in N, positions in m, each as an (x, y) pair; ``send_time_ns`` is CLOCK_REALTIME, ns;
    ``energy_J`` the passivity layer's handed-over energy (J, cumulative).
    """

    epoch: int
    seq: int
    send_time_ns: int
    flags: Flags
    handle_force_N: tuple[float, float]
    handle_position_m: tuple[float, float]
    gain_k: float = 0.0
    """The Ch1 gain k the master's compensator uses (0: not said)."""
    energy_J: float = 0.0
    """The master's cumulative energy handed to the slave (tdpa), J."""
    force_scale: float = 1.0
    """The master's force ramp at this sample, 0..1: the factor its compensator's inputs (fh
    and the received ft) were scaled by; the slave scales its Ct2's input ft by it too."""

    KIND = KIND_HANDLE

    @property
    def safe_state(self) -> bool:
        return bool(self.flags & Flags.SAFE_STATE)

    @property
    def forces_enabled(self) -> bool:
        return bool(self.flags & Flags.FORCES_ENABLED)


@dataclass(frozen=True, slots=True)
class ToolState:
    """Slave to master: the tool's force on the clay, its motion, and the clay's status.

    ``tool_force_N`` is the force the tool applies to the clay (N, x and y; the clay pushes
    back with its negative), ``tool_position_m`` (m), ``tool_velocity_m_s`` (m/s);
    ``clay_engagement`` is the fraction of the tool's cutting edge inside clay (0..1) and
    ``removed_volume_m3`` the clay volume removed since the start (m^3); ``energy_J`` the
    passivity layer's handed-over energy (J, cumulative).
    """

    epoch: int
    seq: int
    send_time_ns: int
    flags: Flags
    tool_force_N: tuple[float, float]
    tool_position_m: tuple[float, float]
    tool_velocity_m_s: tuple[float, float]
    clay_engagement: float
    removed_volume_m3: float
    echo_send_time_ns: int = 0
    """``send_time_ns`` of the newest handle message the slave had used (0: none)."""
    energy_J: float = 0.0
    """The slave's cumulative energy handed to the master (tdpa), J."""

    KIND = KIND_TOOL

    @property
    def safe_state(self) -> bool:
        return bool(self.flags & Flags.SAFE_STATE)

    @property
    def forces_enabled(self) -> bool:
        return bool(self.flags & Flags.FORCES_ENABLED)

    @property
    def in_contact(self) -> bool:
        return bool(self.flags & Flags.IN_CONTACT)


Message = HandleState | ToolState

_packer = msgpack.Packer(use_bin_type=True, use_single_float=False)


def _header(values: int, kind: int) -> bytes:
    """The array header, version and kind of a message with ``values`` payload values."""
    return (_packer.pack_array_header(_HEADER_LENGTH + values) + _packer.pack(SCHEMA_VERSION)
            + _packer.pack(kind))


_HANDLE_HEADER = _header(_HANDLE_FLOATS, KIND_HANDLE)
_TOOL_HEADER = _header(_TOOL_VALUES, KIND_TOOL)
#: msgpack's float 64 (0xcb and 8 big-endian bytes) per payload float, in one pack.
_HANDLE_BODY = struct.Struct(">" + "Bd" * _HANDLE_FLOATS)
_TOOL_BODY = struct.Struct(">" + "Bd" * _TOOL_FLOATS)
_F64 = 0xCB
#: The flags' msgpack bytes by value (a positive fixint below 128, ``cc nn`` above).
_FLAG_BYTES = tuple(msgpack.packb(value) for value in range(_MAX_FLAGS + 1))
_pack = _packer.pack
_isfinite = math.isfinite


def encode_handle_around_send_time(
    epoch: int, seq: int, flags: int, handle_force_N: tuple[float, float],
    handle_position_m: tuple[float, float], gain_k: float, energy_J: float,
    force_scale: float,
) -> tuple[bytes, bytes]:
    """:func:`encode_around_send_time` of the :class:`HandleState` of these fields (N, m, J),
    without building it first."""
    fx, fy = handle_force_N
    yx, yy = handle_position_m
    if not (_isfinite(fx) and _isfinite(fy) and _isfinite(yx) and _isfinite(yy)
            and _isfinite(gain_k) and _isfinite(energy_J) and _isfinite(force_scale)):
        raise ValueError("non-finite value in HandleState: "
                         f"{[fx, fy, yx, yy, gain_k, energy_J, force_scale]}")
    before = _HANDLE_HEADER + _pack(int(epoch)) + _pack(int(seq))
    after = _FLAG_BYTES[int(flags)] + _HANDLE_BODY.pack(
        _F64, fx, _F64, fy, _F64, yx, _F64, yy, _F64, gain_k, _F64, energy_J,
        _F64, force_scale)
    return before, after


def encode_tool_around_send_time(
    epoch: int, seq: int, flags: int, tool_force_N: tuple[float, float],
    tool_position_m: tuple[float, float], tool_velocity_m_s: tuple[float, float],
    clay_engagement: float, removed_volume_m3: float, echo_send_time_ns: int,
    energy_J: float,
) -> tuple[bytes, bytes]:
    """:func:`encode_around_send_time` of the :class:`ToolState` of these fields (N, m, m/s,
    m^3, ns, J), without building it first."""
    fx, fy = tool_force_N
    px, py = tool_position_m
    vx, vy = tool_velocity_m_s
    echo = int(echo_send_time_ns)
    if not 0 <= echo <= _MAX_U63:
        raise ValueError(f"echo_send_time_ns {echo} out of range")
    if not (_isfinite(fx) and _isfinite(fy) and _isfinite(px) and _isfinite(py)
            and _isfinite(vx) and _isfinite(vy) and _isfinite(clay_engagement)
            and _isfinite(removed_volume_m3) and _isfinite(energy_J)):
        values = [fx, fy, px, py, vx, vy, clay_engagement, removed_volume_m3, energy_J]
        raise ValueError(f"non-finite value in ToolState: {values}")
    before = _TOOL_HEADER + _pack(int(epoch)) + _pack(int(seq))
    after = _FLAG_BYTES[int(flags)] + _TOOL_BODY.pack(
        _F64, fx, _F64, fy, _F64, px, _F64, py, _F64, vx, _F64, vy, _F64, clay_engagement,
        _F64, removed_volume_m3, _F64, energy_J) + _pack(echo)
    return before, after


def encode_around_send_time(message: Message) -> tuple[bytes, bytes]:
    """The msgpack bytes of ``message`` before and after its send time: the payload is
    ``before + send_time_bytes(t) + after`` for any send time ``t``. The sender stamps the
    time last, so the measured one-way delay starts when the message goes to Zenoh, not
    before its encoding. Every payload number is a float 64, whatever its value. Raises
    ``ValueError`` for a non-finite value."""
    if isinstance(message, HandleState):
        return encode_handle_around_send_time(
            message.epoch, message.seq, message.flags, message.handle_force_N,
            message.handle_position_m, message.gain_k, message.energy_J, message.force_scale)
    if isinstance(message, ToolState):
        return encode_tool_around_send_time(
            message.epoch, message.seq, message.flags, message.tool_force_N,
            message.tool_position_m, message.tool_velocity_m_s, message.clay_engagement,
            message.removed_volume_m3, message.echo_send_time_ns, message.energy_J)
    raise TypeError(f"not a message: {type(message).__name__}")


def send_time_bytes(send_time_ns: int) -> bytes:
    """The send time as a msgpack uint64 (9 bytes), ns since the epoch of CLOCK_REALTIME."""
    return b"\xcf" + int(send_time_ns).to_bytes(8, "big")


def encode(message: Message) -> bytes:
    """The msgpack bytes of ``message``. Raises ``ValueError`` for a non-finite value."""
    before, after = encode_around_send_time(message)
    return before + send_time_bytes(message.send_time_ns) + after


def _floats(values: list[Any]) -> list[float]:
    for value in values:
        if not isinstance(value, float | int) or isinstance(value, bool):
            raise DecodeError(DropReason.MALFORMED, f"payload value {value!r} is not a number")
    result = [float(v) for v in values]
    if not all(map(math.isfinite, result)):
        raise DecodeError(DropReason.NON_FINITE, f"non-finite payload {result}")
    return result


def _payload_floats(values: list[Any]) -> list[float]:
    """``values`` as finite floats (:func:`_floats`), the common case first: a sender of this
    schema writes every payload number as a float64, which needs no conversion."""
    if _ALL_FLOATS.issuperset(map(type, values)) and all(map(math.isfinite, values)):
        return values
    return _floats(values)


_ALL_FLOATS = frozenset((float,))
_unpackb = msgpack.unpackb


def decode(payload: bytes, expected_kind: int) -> Message:
    """Parse and validate one message of ``expected_kind``.

    Raises :class:`DecodeError` (and nothing else) with reason ``malformed`` (not msgpack,
    wrong shape or types, values out of range), ``unknown_version``, ``wrong_kind`` or
    ``non_finite``.
    """
    # Integer checks are ``type(x) is int``: msgpack decodes an integer as exactly ``int``
    # and true/false as ``bool``, which is not one here.
    if len(payload) > _MAX_PAYLOAD_BYTES:
        raise DecodeError(DropReason.MALFORMED, f"{len(payload)} bytes is too long")
    try:
        fields = _unpackb(payload, use_list=True, raw=False, strict_map_key=True)
    except Exception as error:  # msgpack raises many types for corrupt input
        raise DecodeError(DropReason.MALFORMED, f"not msgpack: {type(error).__name__}") from None
    if type(fields) is not list or len(fields) < _HEADER_LENGTH:
        raise DecodeError(DropReason.MALFORMED, "not an array with a header")
    version, kind, epoch, seq, send_time_ns, flags = fields[:_HEADER_LENGTH]
    if version != SCHEMA_VERSION or type(version) is not int:
        if type(version) is not int:
            raise DecodeError(DropReason.MALFORMED, f"version {version!r} is not an integer")
        raise DecodeError(DropReason.UNKNOWN_VERSION, f"version {version}", version)
    if kind != expected_kind or type(kind) is not int:
        if type(kind) is not int:
            raise DecodeError(DropReason.MALFORMED, f"kind {kind!r} is not an integer")
        raise DecodeError(DropReason.WRONG_KIND, f"kind {kind}, expected {expected_kind}")
    if not (type(epoch) is int and 0 <= epoch <= _MAX_U32):
        raise DecodeError(DropReason.MALFORMED, f"epoch {epoch!r}")
    if not (type(seq) is int and 0 <= seq <= _MAX_U63):
        raise DecodeError(DropReason.MALFORMED, f"seq {seq!r}")
    if not (type(send_time_ns) is int and 0 <= send_time_ns <= _MAX_U63):
        raise DecodeError(DropReason.MALFORMED, f"send_time_ns {send_time_ns!r}")
    if not (type(flags) is int and 0 <= flags <= _MAX_FLAGS):
        raise DecodeError(DropReason.MALFORMED, f"flags {flags!r}")
    body = fields[_HEADER_LENGTH:]
    if kind == KIND_HANDLE:
        if len(body) != _HANDLE_FLOATS:
            raise DecodeError(DropReason.MALFORMED, f"handle payload has {len(body)} values")
        v = _payload_floats(body)
        if v[4] < 0.0:
            raise DecodeError(DropReason.MALFORMED, f"gain_k {v[4]} is negative")
        if v[5] < 0.0:
            raise DecodeError(DropReason.MALFORMED, f"energy_J {v[5]} is negative")
        if not 0.0 <= v[6] <= 1.0:
            raise DecodeError(DropReason.MALFORMED, f"force_scale {v[6]} outside 0..1")
        return HandleState(
            epoch, seq, send_time_ns, _flags_of(flags), (v[0], v[1]), (v[2], v[3]), v[4],
            v[5], v[6],
        )
    if len(body) != _TOOL_VALUES:
        raise DecodeError(DropReason.MALFORMED, f"tool payload has {len(body)} values")
    echo = body.pop()
    if not (type(echo) is int and 0 <= echo <= _MAX_U63):
        raise DecodeError(DropReason.MALFORMED, f"echo_send_time_ns {echo!r}")
    v = _payload_floats(body)
    if not 0.0 <= v[6] <= 1.0:
        raise DecodeError(DropReason.MALFORMED, f"clay_engagement {v[6]} outside 0..1")
    if v[7] < 0.0:
        raise DecodeError(DropReason.MALFORMED, f"removed_volume_m3 {v[7]} is negative")
    if v[8] < 0.0:
        raise DecodeError(DropReason.MALFORMED, f"energy_J {v[8]} is negative")
    return ToolState(
        epoch, seq, send_time_ns, _flags_of(flags), (v[0], v[1]), (v[2], v[3]), (v[4], v[5]),
        v[6], v[7], echo, v[8],
    )


_TDPA = int(Flags.TDPA)


def control_mismatch(own_mode: str, message: Message) -> str | None:
    """Why a peer's message shows it runs another control mode than ``own_mode`` ("paper"
    or "tdpa"), or None: a tdpa side paired with a paper side would wait for energy that
    never comes (and a paper side would ignore it), so the programs refuse the pairing."""
    peer = "tdpa" if int(message.flags) & _TDPA else "paper"
    if peer == own_mode:
        return None
    return (f"the peer runs [control] mode = \"{peer}\", this side \"{own_mode}\"; "
            "set the same mode on both sides")
