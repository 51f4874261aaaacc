"""One emulated CiA 301/402 servo drive's object dictionary and communication objects, built on
:mod:`canopen`'s ``LocalNode`` with the dictionary of an EDS or DCF file
(:mod:`haptic.master.hardware.eds_reader`).

:class:`DriveObjects` is the drive's CANopen side as a real drive has it: the object dictionary
of its EDS (the packaged ``eds/haptic_cia402_drive.eds`` by default, vendor-typical: every PDO
disabled until configured, TPDO1 = statusword only, RPDO1 = controlword only, 0x60C2 = 10 ms,
no heartbeat), answered by canopen's SDO server (expedited and segmented transfers, the
standard abort codes), with the CiA 301 rules for PDO configuration enforced on every write
(mapping only while the PDO is disabled and its count is 0, mappable objects that exist,
at most 8 bytes, or 64 on CAN FD) of every RPDO and TPDO the EDS has. The PDO layouts, SYNC
COB-ID and counter (0x1019), heartbeat producer and consumer, node guarding (0x100C/0x100D),
interpolation period, following-error window and the reaction options are read from the
dictionary once per change (cached: the cyclic path only looks at attributes); an optional
object the EDS lacks has CiA 301/402's "not there" meaning (no SYNC counter, no heartbeat, no
guarding, no window, 0x60C2 = the rig's SYNC period, 0x1005 = 0x80, 0x6007 = 1 fault, 0x605A =
2). The drive reports the identity its EDS's ``[DeviceInfo]`` names (0x1018:01-03; a
``DefaultValue`` there is often a placeholder), and an object the EDS gives no value reads 0,
as a device's firmware would give it one.

The drive's motion state (CiA 402 state, targets, the model's position) lives in
:class:`DriveRuntime`, which the rig (:mod:`haptic.master.simulated_rig.can_devices`) copies and
steps once per
SYNC; the dictionary reads the dynamic objects (statusword, position actual value, mode
display, error code) from it through a read callback.
"""

from __future__ import annotations

import dataclasses
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
from haptic.master.hardware.eds_reader import read_dictionary, variables

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
#: Offset of a PDO's mapping object from its communication object.
MAPPING_OFFSET = 0x200
PDO_INVALID = 0x80000000
PDO_29BIT = 0x20000000
NMT_STATE_CODES = {"pre-operational": 0x7F, "operational": 0x05, "stopped": 0x04}


def packaged_eds_path() -> Path:
    """Path of the EDS shipped with this package (the emulated drive's)."""
    eds = resources.files("haptic.master.hardware").joinpath("eds/haptic_cia402_drive.eds")
    return Path(str(eds))


def load_drive_dictionary(eds_file: str | Path | None, node_id: int) -> od.ObjectDictionary:
    """The object dictionary of ``eds_file`` (an EDS or DCF; empty/``None``: the packaged EDS)
    for ``node_id`` (``$NODEID`` resolved, a DCF's ``ParameterValue`` over ``DefaultValue``;
    :func:`~haptic.master.hardware.eds_reader.read_dictionary`)."""
    return read_dictionary(eds_file or packaged_eds_path(), node_id)


def pdo_kind(index: int) -> tuple[int, bool] | None:
    """(communication object, is an RPDO) of a PDO communication or mapping ``index``;
    ``None`` for any other object."""
    if 0x1400 <= index <= 0x15FF or 0x1800 <= index <= 0x19FF:
        return index, index < 0x1800
    if 0x1600 <= index <= 0x17FF or 0x1A00 <= index <= 0x1BFF:
        return index - MAPPING_OFFSET, index < 0x1A00
    return None


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
    #: The communication object (0x1400 + n, 0x1800 + n; where it is, not what it is).
    comm_index: int = dataclasses.field(default=RPDO1_COMM, compare=False)

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
    #: Each enabled TPDO's payload last sent (event-driven TPDOs go out when it changes): a
    #: tuple, so the runtime's shallow copy keeps its own.
    last_tpdos: tuple[bytes, ...] = ()
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
    ``sync_period_s``: the SYNC period, s, the drive's cycle where its EDS has no 0x60C2.
    """

    def __init__(self, node_id: int, eds_file: str | Path | None,
                 send: Callable[[int, bytes], None], runtime: DriveRuntime,
                 position_counts: Callable[[], int], fd: bool = True,
                 sync_period_s: float = 1e-3) -> None:
        self.node_id = node_id
        self.fd = fd
        self.sync_period_s = sync_period_s
        self.dictionary = load_drive_dictionary(eds_file, node_id)
        _give_values(self.dictionary)
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

    def raw_or(self, index: int, subindex: int, absent: int) -> int:
        """:meth:`raw` of an object, ``absent`` where the EDS does not have it."""
        entry = self.dictionary.get(index)
        if entry is None or (isinstance(entry, od.ODVariable) and subindex != 0) or (
                not isinstance(entry, od.ODVariable) and subindex not in entry):
            return absent
        return self.raw(index, subindex)

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
        pdo = pdo_kind(index)
        if pdo is not None:
            self._check_pdo_write(index, subindex, value, *pdo)
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

    def _check_pdo_write(self, index: int, subindex: int, value: int, comm: int,
                         rpdo: bool) -> None:
        """The CiA 301 rules of a write to a PDO's communication (``index`` == ``comm``) or
        mapping object: a 29-bit or changed valid COB-ID, a transmission type out of range, a
        mapping changed while the PDO is valid or its count is not 0 are refused."""
        if index == comm and subindex == 1:
            current = self.raw(index, 1)
            if value & PDO_29BIT:
                raise SdoAbortedError(ABORT_VALUE_RANGE)
            if not current & PDO_INVALID and not value & PDO_INVALID and (
                    (value & 0x7FF) != (current & 0x7FF)):
                raise SdoAbortedError(ABORT_VALUE_RANGE)  # a valid PDO's id is fixed
        elif index == comm and subindex == 2:
            if not (value <= 240 or value in (254, 255)):
                raise SdoAbortedError(ABORT_VALUE_RANGE)
        elif index != comm:
            if not self.raw(comm, 1) & PDO_INVALID:
                raise SdoAbortedError(ABORT_UNSUPPORTED_ACCESS)  # disable the PDO first
            if subindex == 0:
                self._check_mapping(index, value, rpdo=rpdo)
            elif self.raw(index, 0) != 0:
                raise SdoAbortedError(ABORT_UNSUPPORTED_ACCESS)  # set the count to 0 first

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
        self._refresh_pdos()
        raw_or = self.raw_or
        self.sync_cob_id = raw_or(0x1005, 0, cia402.SYNC_COB_ID) & 0x7FF
        #: 0x1019: 0, SYNCs carry no data; 2..240, a 1-byte counter 1..this value
        self.sync_counter_overflow = raw_or(0x1019, 0, 0)
        self.heartbeat_producer_ms = raw_or(0x1017, 0, 0)
        consumer = raw_or(0x1016, 1, 0)
        self.heartbeat_consumer_node = (consumer >> 16) & 0x7F
        self.heartbeat_consumer_ms = consumer & 0xFFFF
        #: node guarding: the guard time (ms) and the life time factor, 0 off
        self.guard_time_ms = raw_or(0x100C, 0, 0)
        self.life_time_factor = raw_or(0x100D, 0, 0)
        self.interpolation_period_s = (
            self.raw(0x60C2, 1) * 10.0 ** self.raw(0x60C2, 2)
            if raw_or(0x60C2, 1, 0) else self.sync_period_s)
        self.following_error_window_counts = raw_or(0x6065, 0, 0xFFFFFFFF)
        self.following_error_timeout_s = raw_or(0x6066, 0, 0) * 1e-3
        self.abort_connection_option = raw_or(0x6007, 0, 1)
        self.quick_stop_option = raw_or(0x605A, 0, 2)
        self._dirty = False

    def _refresh_pdos(self) -> None:
        """Every PDO's layout; :attr:`rpdo` and :attr:`tpdo` are PDO 1's (a disabled empty
        one where the EDS has none), :attr:`rpdos_by_id` the enabled RPDOs by COB-ID and
        :attr:`tpdos` the enabled TPDOs, PDO 1 first."""
        rpdos = [self._layout(comm, comm + MAPPING_OFFSET) for comm in self._pdo_comms(True)]
        tpdos = [self._layout(comm, comm + MAPPING_OFFSET) for comm in self._pdo_comms(False)]
        empty = PdoLayout(False, 0, 0, (), 0)
        self.rpdo = next((p for p in rpdos if p.comm_index == RPDO1_COMM), empty)
        self.tpdo = next((p for p in tpdos if p.comm_index == TPDO1_COMM),
                         dataclasses.replace(empty, comm_index=TPDO1_COMM))
        self._rpdo_codec, self._rpdo_indices = self.rpdo.codec(), self.rpdo.indices
        self._tpdo_codec, self._tpdo_indices = self.tpdo.codec(), self.tpdo.indices
        self.rpdos_by_id = {p.cob_id: p for p in rpdos if p.enabled}
        self.tpdos = tuple(p for p in tpdos if p.enabled)
        self._codecs = {p.comm_index: p.codec() for p in rpdos + tpdos}
        #: the RPDO deadline in force: the shortest of the enabled RPDOs', ms (0 none)
        self.rpdo_deadline_ms = min((p.event_timer_ms for p in self.rpdos_by_id.values()
                                     if p.event_timer_ms), default=0)

    def _pdo_comms(self, rpdo: bool) -> list[int]:
        """The communication objects of the EDS's RPDOs (or TPDOs) that have a mapping."""
        base = RPDO1_COMM if rpdo else TPDO1_COMM
        return [comm for comm in range(base, base + 0x200)
                if comm in self.dictionary and comm + MAPPING_OFFSET in self.dictionary]

    def refresh_if_changed(self) -> bool:
        """:meth:`refresh` when a write changed the dictionary; True when it did."""
        if self._dirty:
            self.refresh()
            return True
        return False

    def _layout(self, comm: int, mapping: int) -> PdoLayout:
        """One PDO's layout; one whose mapping names an object the drive cannot put in a
        frame (missing, or of no fixed size) is disabled."""
        cob_id = self.raw(comm, 1)
        mapped = []
        for subindex in range(1, self.raw_or(mapping, 0, 0) + 1):
            entry = self.raw_or(mapping, subindex, 0)
            try:
                variable = self._variable(entry >> 16, (entry >> 8) & 0xFF)
            except KeyError:
                variable = None
            if variable is None or variable.data_type not in variable.STRUCT_TYPES or (
                    len(variable) != entry & 0xFF):
                return PdoLayout(False, cob_id & 0x7FF, 0, (), 0, comm)
            mapped.append(variable)
        timer = self.raw(comm, 5) if 5 in self.dictionary[comm] else 0
        kind = self.raw_or(comm, 2, 255)
        return PdoLayout(not cob_id & PDO_INVALID, cob_id & 0x7FF, kind, tuple(mapped), timer,
                         comm)

    # --- PDO payloads -----------------------------------------------------------------

    def statusword(self, runtime: DriveRuntime) -> int:
        """The statusword of ``runtime``: the state's bits, remote, the warning bits."""
        word = cia402.STATUS_BITS[runtime.state] | SW_REMOTE | runtime.status_extra
        if runtime.state is DriveState.OPERATION_ENABLED and (
                runtime.mode == cia402.MODE_CYCLIC_SYNC_POSITION):
            word |= SW_FOLLOWS_TARGET
        return word

    def encode_tpdo(self, runtime: DriveRuntime, position_counts: int,
                    layout: PdoLayout | None = None) -> bytes:
        """A TPDO's payload as mapped (TPDO1, or ``layout``), from ``runtime`` and the position
        (counts)."""
        if layout is None or layout is self.tpdo:
            indices, codec, mapping = self._tpdo_indices, self._tpdo_codec, self.tpdo.mapping
        else:
            indices, codec, mapping = layout.indices, self._codecs[layout.comm_index], (
                layout.mapping)
        if indices == (0x6041, 0x6064):  # the loop's mapping
            return codec.pack(self.statusword(runtime), position_counts)
        values = {0x6041: self.statusword(runtime), 0x6064: position_counts,
                  0x6060: runtime.mode, 0x6061: runtime.mode, 0x603F: runtime.error_code,
                  0x607A: runtime.target_counts,
                  0x60F4: runtime.target_counts - position_counts, 0x6040: runtime.controlword}
        return codec.pack(*(  # any other object: its value in the dictionary
            values[variable.index] if variable.index in values
            else self.raw(variable.index, variable.subindex) for variable in mapping))

    def decode_rpdo(self, data: bytes, layout: PdoLayout | None = None) -> dict[int, int] | int:
        """The mapped objects' values (index -> value) of an RPDO payload (RPDO1, or
        ``layout``), or the EMCY code of a length error (0x8210 too short, 0x8220 too
        long)."""
        other = layout is not None and layout is not self.rpdo
        codec = self._codecs[layout.comm_index] if other else self._rpdo_codec
        if len(data) < codec.size:
            return EMCY_PDO_LENGTH_SHORT
        if len(data) > codec.size:
            return EMCY_PDO_LENGTH_EXCEEDED
        if other:
            return dict(zip(layout.indices, codec.unpack(data), strict=True))
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


def _give_values(dictionary: od.ObjectDictionary) -> None:
    """Values for the objects the EDS gives none, as a device's firmware has them: the
    identity of ``[DeviceInfo]`` (vendor, product, revision) in 0x1018:01-03, 0 for any
    other number."""
    info = dictionary.device_information
    identity = {1: info.vendor_number, 2: info.product_number, 3: info.revision_number}
    for variable in variables(dictionary):
        if variable.index == 0x1018 and identity.get(variable.subindex):
            variable.value = identity[variable.subindex]
        elif variable.value is None and variable.default is None and (
                variable.data_type in variable.STRUCT_TYPES):
            variable.default = 0


def emcy_payload(code: int, register: int = 0x01) -> bytes:
    """An EMCY frame's payload."""
    return struct.pack("<HB5s", code, register, b"")
