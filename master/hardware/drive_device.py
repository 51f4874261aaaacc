"""One emulated CiA 301/402 servo drive's object dictionary and communication objects, built on
:mod:`canopen`'s ``LocalNode`` with the dictionary of an EDS file.

:class:`DriveObjects` is the drive's CANopen side as a real drive has it: the object dictionary
of its EDS (the packaged ``eds/haptic_cia402_drive.eds`` by default, vendor-typical: every PDO
disabled until configured, TPDO1 = statusword only, RPDO1 = controlword only, 0x60C2 = 10 ms,
no heartbeat), answered by canopen's SDO server (expedited and segmented transfers, the
standard abort codes), with the CiA 301 rules for PDO configuration enforced on every write
(mapping only while the PDO is disabled and its count is 0, mappable objects that exist,
at most 8 bytes, or 64 on CAN FD). The PDO layouts, SYNC COB-ID and counter (0x1019),
heartbeat producer and consumer, interpolation period, following-error window and the
reaction options are read from the dictionary once per change (cached: the cyclic path only
looks at attributes).

The drive's motion state (CiA 402 state, targets, the model's position) lives in
:class:`DriveRuntime`, which the rig (:mod:`haptic.master.sim.sim_rig`) copies and steps once per
SYNC; the dictionary reads the dynamic objects (statusword, position actual value, mode
display, error code) from it through a read callback.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import canopen
from canopen import objectdictionary as od
from canopen.sdo import SdoAbortedError

from haptic.master.hardware import cia402
from haptic.master.hardware.cia402 import DriveState

#: Abort codes (CiA 301) the PDO rules use.
ABORT_UNSUPPORTED_ACCESS = 0x06010000
ABORT_NO_SUBINDEX = 0x06090011
ABORT_NOT_MAPPABLE = 0x06040041
ABORT_PDO_LENGTH = 0x06040042
ABORT_VALUE_RANGE = 0x06090030
ABORT_INVALID_VALUE = 0x06090030

#: EMCY error codes (CiA 301 / 402) the emulated drive sends.
EMCY_HEARTBEAT = 0x8130
EMCY_PDO_LENGTH_SHORT = 0x8210
EMCY_PDO_LENGTH_EXCEEDED = 0x8220
EMCY_SYNC_LENGTH = 0x8240
EMCY_RPDO_TIMEOUT = 0x8250
EMCY_FOLLOWING_ERROR = 0x8611

#: Statusword bits beyond the state coding (CiA 402).
SW_WARNING = 0x0080
SW_REMOTE = 0x0200
SW_TARGET_REACHED = 0x0400
SW_INTERNAL_LIMIT = 0x0800
SW_FOLLOWS_TARGET = 0x1000  # cyclic synchronous position: the drive follows the target
SW_FOLLOWING_ERROR = 0x2000

#: PDO payload limits, bytes: classical CAN and CAN FD.
CLASSIC_PDO_BYTES = 8
FD_PDO_BYTES = 64

RPDO1_COMM, RPDO1_MAP, TPDO1_COMM, TPDO1_MAP = 0x1400, 0x1600, 0x1800, 0x1A00
PDO_INVALID = 0x80000000
PDO_29BIT = 0x20000000
NMT_STATE_CODES = {"pre-operational": 0x7F, "operational": 0x05, "stopped": 0x04}


def packaged_eds_path() -> Path:
    """Path of the EDS shipped with this package (the emulated drive's)."""
    eds = resources.files("haptic.master.hardware").joinpath("eds/haptic_cia402_drive.eds")
    return Path(str(eds))


def load_drive_dictionary(eds_file: str | Path | None, node_id: int) -> od.ObjectDictionary:
    """The object dictionary of ``eds_file`` (empty/``None``: the packaged EDS) for
    ``node_id`` (``$NODEID`` resolved)."""
    return canopen.import_od(str(eds_file or packaged_eds_path()), node_id)


def mapping_entry(variable: od.ODVariable) -> int:
    """The PDO mapping entry (index << 16 | subindex << 8 | bit length) of ``variable``."""
    return (variable.index << 16) | (variable.subindex << 8) | len(variable)


@dataclass(frozen=True)
class PdoLayout:
    """One PDO as configured: enabled, COB-ID, transmission type, mapped variables, event
    timer (ms; for an RPDO the deadline monitoring time, 0 off)."""

    enabled: bool
    cob_id: int
    transmission_type: int
    mapping: tuple[od.ODVariable, ...]
    event_timer_ms: int

    @property
    def size(self) -> int:
        """Payload length, bytes."""
        return sum(len(variable) // 8 for variable in self.mapping)

    @property
    def indices(self) -> tuple[int, ...]:
        """The mapped objects' indices, in order."""
        return tuple(variable.index for variable in self.mapping)

    def codec(self) -> struct.Struct:
        """The payload's layout as one ``struct`` (little-endian, the mapped types)."""
        return struct.Struct("<" + "".join(
            variable.STRUCT_TYPES[variable.data_type].format.lstrip("<")
            for variable in self.mapping))


@dataclass
class DriveRuntime:
    """The drive's motion state, stepped by the rig once per SYNC (copied for a prepared
    answer: scalars only)."""

    node_id: int
    nmt_state: str = "pre-operational"
    state: DriveState = DriveState.SWITCH_ON_DISABLED
    mode: int = 0
    controlword: int = 0
    received_controlword: int | None = None
    received_target: int | None = None
    #: The target the drive applies (0x607A), counts.
    target_counts: int = 0
    #: Position actual value at the last SYNC, counts.
    position_counts: int = 0
    pending_fault_code: int = 0
    #: A fault whose cause stays (it comes back after a reset); 0 none.
    persistent_fault_code: int = 0
    error_code: int = 0
    drop_tpdo: int = 0
    #: SYNCs since the last RPDO while enabled (the RPDO deadline monitoring).
    syncs_without_rpdo: int = 0
    #: SYNCs the following error has exceeded the window.
    following_error_syncs: int = 0
    status_extra: int = 0
    #: The TPDO1 payload last sent (event-driven TPDOs go out when it changes).
    last_tpdo: bytes = b""
    sync_count: int = 0

    def copy(self) -> DriveRuntime:
        """A shallow copy (its fields are scalars), without :func:`copy.copy`'s generic
        path: the rig copies both drives for every prepared SYNC answer."""
        clone = object.__new__(DriveRuntime)
        clone.__dict__.update(self.__dict__)
        return clone


class DriveObjects:
    """The CANopen side of one emulated drive (see the module docstring).

    ``send(frame_id, data)`` sends a classical frame on the rig's bus (SDO replies).
    ``runtime`` is the committed :class:`DriveRuntime` (the rig updates it in place).
    ``position_counts()`` gives the position actual value now, counts (SDO reads).
    ``fd``: the drive is on CAN FD (PDOs of up to 64 bytes), else on classical CAN (8).
    """

    def __init__(self, node_id: int, eds_file: str | Path | None,
                 send: Callable[[int, bytes], None], runtime: DriveRuntime,
                 position_counts: Callable[[], int], fd: bool = True) -> None:
        self.node_id = node_id
        self.fd = fd
        self.dictionary = load_drive_dictionary(eds_file, node_id)
        self.node = canopen.LocalNode(node_id, self.dictionary)
        # The heartbeat is produced by the rig's loop (deterministically), not by canopen's
        # periodic-send thread.
        self.node._write_callbacks.remove(self.node.nmt.on_write)
        self.node.add_read_callback(self._on_read)
        self.node.add_write_callback(self._on_write)
        self.node.sdo.network = _Sender(send)
        self.runtime = runtime
        self._position_counts = position_counts
        self.refresh()

    # --- SDO ------------------------------------------------------------------------

    def on_sdo_request(self, data: bytes) -> None:
        """Answer one SDO request (canopen's server; the reply goes out through ``send``)."""
        self.node.sdo.on_request(cia402.SDO_RX_BASE + self.node_id, bytearray(data), 0.0)

    def raw(self, index: int, subindex: int = 0) -> int:
        """The value of an object now (as an SDO upload would give it)."""
        variable = self._variable(index, subindex)
        return int(variable.decode_raw(self.node.get_data(index, subindex)))

    def _variable(self, index: int, subindex: int) -> od.ODVariable:
        entry = self.dictionary[index]
        return entry if isinstance(entry, od.ODVariable) else entry[subindex]

    def _on_read(self, index: int, subindex: int, od: od.ODVariable) -> int | None:
        if subindex != od.subindex:  # canopen serves a variable at any sub-index
            raise SdoAbortedError(ABORT_NO_SUBINDEX)
        runtime = self.runtime
        if index == 0x6041:
            return self.statusword(runtime)
        if index == 0x6064:
            return self._position_counts()
        if index == 0x6061:
            return runtime.mode
        if index == 0x6060:
            return runtime.mode
        if index == 0x603F:
            return runtime.error_code
        if index == 0x1001:
            return 0x01 if runtime.state in (DriveState.FAULT,
                                             DriveState.FAULT_REACTION_ACTIVE) else 0x00
        if index == 0x6040:
            return runtime.controlword
        if index == 0x607A:
            return runtime.target_counts
        if index == 0x60F4:
            return runtime.target_counts - self._position_counts()
        return None

    def _on_write(self, index: int, subindex: int, od: od.ODVariable, data: bytes) -> None:
        """The CiA 301/402 rules of a write (raising :class:`SdoAbortedError` refuses it);
        the accepted value is stored by canopen after this returns."""
        if subindex != od.subindex:  # canopen serves a variable at any sub-index
            raise SdoAbortedError(ABORT_NO_SUBINDEX)
        value = int(od.decode_raw(bytes(data)))
        runtime = self.runtime
        if index in (RPDO1_COMM, TPDO1_COMM) and subindex == 1:
            current = self.raw(index, 1)
            if value & PDO_29BIT:
                raise SdoAbortedError(ABORT_VALUE_RANGE)
            if not current & PDO_INVALID and not value & PDO_INVALID and (
                    (value & 0x7FF) != (current & 0x7FF)):
                raise SdoAbortedError(ABORT_VALUE_RANGE)  # a valid PDO's id is fixed
        elif index in (RPDO1_COMM, TPDO1_COMM) and subindex == 2:
            if not (value <= 240 or value in (254, 255)):
                raise SdoAbortedError(ABORT_VALUE_RANGE)
        elif index in (RPDO1_MAP, TPDO1_MAP):
            comm = RPDO1_COMM if index == RPDO1_MAP else TPDO1_COMM
            if not self.raw(comm, 1) & PDO_INVALID:
                raise SdoAbortedError(ABORT_UNSUPPORTED_ACCESS)  # disable the PDO first
            if subindex == 0:
                self._check_mapping(index, value, rpdo=index == RPDO1_MAP)
            elif self.raw(index, 0) != 0:
                raise SdoAbortedError(ABORT_UNSUPPORTED_ACCESS)  # set the count to 0 first
        elif index == 0x6060:
            if value not in (0, 1, cia402.MODE_CYCLIC_SYNC_POSITION):
                raise SdoAbortedError(ABORT_VALUE_RANGE)
            runtime.mode = value
        elif index == 0x6040:
            runtime.received_controlword = value
        elif index == 0x607A:
            runtime.received_target = value
            if runtime.state is not DriveState.OPERATION_ENABLED:
                runtime.target_counts = value
        elif index == 0x60C2 and subindex == 1 and value == 0:
            raise SdoAbortedError(ABORT_VALUE_RANGE)
        elif index == 0x1019 and (value == 1 or value > 240):
            raise SdoAbortedError(ABORT_VALUE_RANGE)
        self._dirty = True

    def _check_mapping(self, index: int, count: int, rpdo: bool) -> None:
        if count > 8:
            raise SdoAbortedError(ABORT_VALUE_RANGE)
        bits = 0
        for subindex in range(1, count + 1):
            entry = self.raw(index, subindex)
            target_index, target_sub, length = entry >> 16, (entry >> 8) & 0xFF, entry & 0xFF
            try:
                variable = self._variable(target_index, target_sub)
            except KeyError:
                raise SdoAbortedError(ABORT_NOT_MAPPABLE) from None
            if variable.subindex != target_sub or not variable.pdo_mappable or (
                    len(variable) != length) or (
                    rpdo and not variable.writable) or (not rpdo and not variable.readable):
                raise SdoAbortedError(ABORT_NOT_MAPPABLE)
            bits += length
        if bits > 8 * (FD_PDO_BYTES if self.fd else CLASSIC_PDO_BYTES):
            raise SdoAbortedError(ABORT_PDO_LENGTH)

    # --- configuration, cached -----------------------------------------------------

    def refresh(self) -> None:
        """Read the communication configuration from the dictionary (after a write)."""
        self.rpdo = self._layout(RPDO1_COMM, RPDO1_MAP)
        self.tpdo = self._layout(TPDO1_COMM, TPDO1_MAP)
        self._rpdo_codec, self._rpdo_indices = self.rpdo.codec(), self.rpdo.indices
        self._tpdo_codec, self._tpdo_indices = self.tpdo.codec(), self.tpdo.indices
        self.sync_cob_id = self.raw(0x1005) & 0x7FF
        #: 0x1019: 0, SYNCs carry no data; 2..240, a 1-byte counter 1..this value
        self.sync_counter_overflow = self.raw(0x1019) if 0x1019 in self.dictionary else 0
        self.heartbeat_producer_ms = self.raw(0x1017)
        consumer = self.raw(0x1016, 1)
        self.heartbeat_consumer_node = (consumer >> 16) & 0x7F
        self.heartbeat_consumer_ms = consumer & 0xFFFF
        self.interpolation_period_s = self.raw(0x60C2, 1) * 10.0 ** self.raw(0x60C2, 2)
        self.following_error_window_counts = self.raw(0x6065)
        self.following_error_timeout_s = self.raw(0x6066) * 1e-3
        self.abort_connection_option = self.raw(0x6007)
        self.quick_stop_option = self.raw(0x605A)
        self._dirty = False

    def refresh_if_changed(self) -> bool:
        """:meth:`refresh` when a write changed the dictionary; True when it did."""
        if self._dirty:
            self.refresh()
            return True
        return False

    def _layout(self, comm: int, mapping: int) -> PdoLayout:
        cob_id = self.raw(comm, 1)
        variables = []
        for subindex in range(1, self.raw(mapping, 0) + 1):
            entry = self.raw(mapping, subindex)
            variables.append(self._variable(entry >> 16, (entry >> 8) & 0xFF))
        timer = self.raw(comm, 5) if 5 in self.dictionary[comm] else 0
        return PdoLayout(not cob_id & PDO_INVALID, cob_id & 0x7FF, self.raw(comm, 2),
                         tuple(variables), timer)

    # --- PDO payloads -----------------------------------------------------------------

    def statusword(self, runtime: DriveRuntime) -> int:
        """The statusword of ``runtime``: the state's bits, remote, the warning bits."""
        word = cia402.STATUS_BITS[runtime.state] | SW_REMOTE | runtime.status_extra
        if runtime.state is DriveState.OPERATION_ENABLED and (
                runtime.mode == cia402.MODE_CYCLIC_SYNC_POSITION):
            word |= SW_FOLLOWS_TARGET
        return word

    def encode_tpdo(self, runtime: DriveRuntime, position_counts: int) -> bytes:
        """TPDO1's payload as mapped, from ``runtime`` and the position (counts)."""
        indices = self._tpdo_indices
        if indices == (0x6041, 0x6064):  # the loop's mapping
            return self._tpdo_codec.pack(self.statusword(runtime), position_counts)
        values = {0x6041: self.statusword(runtime), 0x6064: position_counts,
                  0x6060: runtime.mode, 0x6061: runtime.mode, 0x603F: runtime.error_code,
                  0x607A: runtime.target_counts,
                  0x60F4: runtime.target_counts - position_counts, 0x6040: runtime.controlword}
        return self._tpdo_codec.pack(*(  # any other object: its value in the dictionary
            values[variable.index] if variable.index in values
            else self.raw(variable.index, variable.subindex) for variable in self.tpdo.mapping))

    def decode_rpdo(self, data: bytes) -> dict[int, int] | int:
        """The mapped objects' values (index -> value) of an RPDO1 payload, or the EMCY code
        of a length error (0x8210 too short, 0x8220 too long)."""
        codec = self._rpdo_codec
        if len(data) < codec.size:
            return EMCY_PDO_LENGTH_SHORT
        if len(data) > codec.size:
            return EMCY_PDO_LENGTH_EXCEEDED
        return dict(zip(self._rpdo_indices, codec.unpack(data), strict=True))

    def heartbeat_payload(self) -> bytes:
        """This drive's heartbeat: its NMT state."""
        return bytes([NMT_STATE_CODES[self.runtime.nmt_state]])


class _Sender:
    """The ``network`` canopen's SDO server sends its replies through."""

    def __init__(self, send: Callable[[int, bytes], None]) -> None:
        self._send = send

    def send_message(self, can_id: int, data: bytes, remote: bool = False) -> None:
        del remote
        self._send(can_id, bytes(data))


def emcy_payload(code: int, register: int = 0x01) -> bytes:
    """An EMCY frame's payload."""
    return struct.pack("<HB5s", code, register, b"")
