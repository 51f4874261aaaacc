"""The emulated CiA 301/402 drive (master/hardware/drive_device.py) against independent
references: python-canopen's own SDO client and PDO maps (a ``RemoteNode`` of the packaged
EDS) talking to the drive's SDO server, its abort-code, NMT-state and CiA 402 statusword
tables, its EMCY consumer, and the packaged EDS for the power-on values.

The project's CAN driver is tested against this drive, so a rule here that is wrong (too
lenient, or a value off) would hide a driver defect that only a real drive shows; these
tests pin each rule to CiA 301/402, not to the driver."""

from __future__ import annotations

import dataclasses
import struct
from pathlib import Path

import canopen
import pytest
from canopen import objectdictionary as od
from canopen.emcy import EmcyConsumer
from canopen.nmt import NMT_STATES
from canopen.profiles.p402 import OperationMode, State402
from canopen.sdo import SdoAbortedError

from haptic.master.hardware import cia402
from haptic.master.hardware import drive_device as dd
from haptic.master.hardware.cia402 import DriveState
from haptic.master.hardware.drive_device import DriveObjects, DriveRuntime
from tests.master.hardware import eds_variants

NODE = 3
INVALID = 0x80000000  # CiA 301 COB-ID bit 31: the PDO does not exist


def _abort(name: str) -> int:
    """The CiA 301 abort code canopen's table gives ``name``."""
    return next(code for code, text in SdoAbortedError.CODES.items() if text == name)


UNSUPPORTED = _abort("Unsupported access to an object")
NOT_MAPPABLE = _abort("Object cannot be mapped to the PDO")
PDO_LENGTH = _abort("PDO length exceeded")
VALUE_RANGE = _abort("Value range of parameter exceeded")
READ_ONLY = _abort("Attempt to write a read only object")


class _Link:
    """A ``canopen.RemoteNode`` of the drive's EDS wired to the drive frame by frame (this
    object is its network, no bus): the node's SDO requests go to
    :meth:`DriveObjects.on_sdo_request`, the drive's frames (its ``send``) to the node's
    subscribers; ``sent`` keeps every frame the drive sent."""

    def __init__(self, node_id: int = NODE, eds: str | Path | None = None,
                 runtime: DriveRuntime | None = None, position: int = 0, **options) -> None:
        self.node_id = node_id
        self.position = position
        self.sent: list[tuple[int, bytes]] = []
        self.subscribers: dict[int, list] = {}
        self.runtime = runtime or DriveRuntime(node_id)
        self.device = DriveObjects(node_id, eds, self._deliver, self.runtime,
                                   lambda: self.position, **options)
        self.node = canopen.RemoteNode(node_id, dd.load_drive_dictionary(eds, node_id))
        self.node.sdo.RESPONSE_TIMEOUT = 0.05  # the drive answers at once, or never
        self.node.associate_network(self)

    # --- the network canopen's node talks through ----------------------------------

    def subscribe(self, can_id: int, callback) -> None:
        self.subscribers.setdefault(can_id, []).append(callback)

    def unsubscribe(self, can_id: int, callback=None) -> None:
        self.subscribers.pop(can_id, None)

    def send_message(self, can_id: int, data: bytes, remote: bool = False) -> None:
        assert can_id == 0x600 + self.node_id and not remote  # only SDO requests
        self.device.on_sdo_request(bytes(data))

    def _deliver(self, frame_id: int, data: bytes) -> None:
        self.sent.append((frame_id, data))
        for callback in self.subscribers.get(frame_id, []):
            callback(frame_id, bytearray(data), 0.0)

    # --- SDO ------------------------------------------------------------------------

    def _sdo(self, index: int, subindex: int):
        entry = self.node.object_dictionary[index]
        return self.node.sdo[index] if isinstance(entry, od.ODVariable) else (
            self.node.sdo[index][subindex])

    def read(self, index: int, subindex: int = 0) -> int:
        """SDO upload of an object, as canopen's client decodes it."""
        return self._sdo(index, subindex).raw

    def write(self, index: int, subindex: int, value: int) -> int | None:
        """SDO download; the abort code, or None when the drive took it (then the drive
        re-reads its configuration, as the rig does after each SDO request)."""
        try:
            self._sdo(index, subindex).raw = value
        except SdoAbortedError as error:
            assert not self.device.refresh_if_changed()  # a refused write changes nothing
            return error.code
        assert self.device.refresh_if_changed()
        assert not self.device.refresh_if_changed()  # once per change
        return None

    def map_pdo(self, pdo, objects: tuple[int | tuple[int, int], ...], kind: int = 1) -> None:
        """Map and enable ``pdo`` (canopen's ``node.tpdo[1]`` or ``node.rpdo[1]``) the way
        canopen does it, then let the drive re-read its configuration."""
        pdo.read()
        pdo.clear()
        for item in objects:
            pdo.add_variable(*(item if isinstance(item, tuple) else (item,)))
        pdo.trans_type = kind
        pdo.enabled = True
        pdo.save()
        self.device.refresh_if_changed()


def _eds_with_extras(tmp_path: Path) -> Path:
    """The packaged EDS plus manufacturer objects the packaged one lacks (a record with a
    16-bit rw and a 32-bit ro mappable entry, a mappable 64-bit object, a mappable write-only
    object) and without RPDO1's event timer (0x1400:05)."""
    eds = dd.packaged_eds_path().read_text()
    start = eds.index("[1400sub5]")
    eds = eds[:start] + eds[eds.index("[1600]"):]
    extras = {
        "2000": "ParameterName=Manufacturer record\nObjectType=0x9\nSubNumber=3",
        "2000sub0": "ParameterName=Highest sub-index\nObjectType=0x7\nDataType=0x0005\n"
                    "AccessType=const\nDefaultValue=2\nPDOMapping=0",
        "2000sub1": "ParameterName=Word\nObjectType=0x7\nDataType=0x0006\nAccessType=rw\n"
                    "DefaultValue=0x1111\nPDOMapping=1",
        "2000sub2": "ParameterName=Long\nObjectType=0x7\nDataType=0x0004\nAccessType=ro\n"
                    "DefaultValue=-7\nPDOMapping=1",
        "2001": "ParameterName=Wide\nObjectType=0x7\nDataType=0x001B\nAccessType=rw\n"
                "DefaultValue=0\nPDOMapping=1",
        "2002": "ParameterName=Write only\nObjectType=0x7\nDataType=0x0005\nAccessType=wo\n"
                "DefaultValue=0\nPDOMapping=1",
    }
    eds += "".join(f"\n[{name}]\n{body}\n" for name, body in extras.items())
    path = tmp_path / "extras.eds"
    path.write_text(eds)
    return path


# --- constants ----------------------------------------------------------------------


def test_the_abort_codes_are_cia_301s() -> None:
    """The named abort codes are the CiA 301 codes of their meaning (canopen's table)."""
    assert (dd.ABORT_UNSUPPORTED_ACCESS, dd.ABORT_NOT_MAPPABLE, dd.ABORT_PDO_LENGTH,
            dd.ABORT_VALUE_RANGE, dd.ABORT_INVALID_VALUE) == (
        UNSUPPORTED, NOT_MAPPABLE, PDO_LENGTH, VALUE_RANGE, VALUE_RANGE)


def test_the_emcy_codes_statusword_bits_and_pdo_constants_are_the_standards() -> None:
    """EMCY codes, statusword bits, COB-ID bits and PDO sizes are the CiA 301/402 values."""
    assert dd.EMCY_HEARTBEAT == 0x8130  # life guard or heartbeat error
    assert dd.EMCY_PDO_LENGTH_SHORT == 0x8210  # PDO not processed due to length error
    assert dd.EMCY_PDO_LENGTH_EXCEEDED == 0x8220  # PDO length exceeded
    assert dd.EMCY_SYNC_LENGTH == 0x8240  # unexpected SYNC data length
    assert dd.EMCY_RPDO_TIMEOUT == 0x8250  # RPDO time out
    assert dd.EMCY_FOLLOWING_ERROR == 0x8611  # CiA 402: following error
    assert (dd.SW_WARNING, dd.SW_REMOTE, dd.SW_TARGET_REACHED, dd.SW_INTERNAL_LIMIT,
            dd.SW_FOLLOWS_TARGET, dd.SW_FOLLOWING_ERROR) == tuple(
        1 << bit for bit in (7, 9, 10, 11, 12, 13))
    assert (dd.PDO_INVALID, dd.PDO_29BIT) == (1 << 31, 1 << 29)
    assert (dd.CLASSIC_PDO_BYTES, dd.FD_PDO_BYTES) == (8, 64)
    assert (dd.RPDO1_COMM, dd.RPDO1_MAP, dd.TPDO1_COMM, dd.TPDO1_MAP) == (
        0x1400, 0x1600, 0x1800, 0x1A00)


def test_the_heartbeat_carries_the_nmt_state_code() -> None:
    """The heartbeat payload is the one-byte NMT state of canopen's table."""
    link = _Link()
    for name in ("pre-operational", "operational", "stopped"):
        link.runtime.nmt_state = name
        payload = link.device.heartbeat_payload()
        assert len(payload) == 1 and NMT_STATES[payload[0]] == name.upper()
    assert dd.NMT_STATE_CODES == {name.lower(): code for code, name in NMT_STATES.items()
                                  if name.lower() in dd.NMT_STATE_CODES}


def test_an_emcy_payload_is_what_canopens_consumer_reads() -> None:
    """emcy_payload: 8 bytes, code, error register (default bit 0, generic), 5 zeros."""
    consumer = EmcyConsumer()
    for code, register in ((0x8611, None), (0x2310, 0x05)):
        payload = dd.emcy_payload(code) if register is None else dd.emcy_payload(code, register)
        assert len(payload) == 8
        consumer.on_emcy(0x80 + NODE, payload, 0.0)
        entry = consumer.log[-1]
        assert (entry.code, entry.register, entry.data) == (
            code, 0x01 if register is None else register, bytes(5))


def test_mapping_entries_are_the_cia_301_layout_the_eds_defaults_use(tmp_path: Path) -> None:
    """mapping_entry: index << 16 | sub-index << 8 | bits, as the EDS's default entries."""
    dictionary = dd.load_drive_dictionary(None, NODE)
    assert dd.mapping_entry(dictionary[0x6040]) == dictionary[0x1600][1].default == 0x60400010
    assert dd.mapping_entry(dictionary[0x6041]) == dictionary[0x1A00][1].default == 0x60410010
    assert dd.mapping_entry(dictionary[0x6064]) == 0x60640020
    extras = dd.load_drive_dictionary(_eds_with_extras(tmp_path), NODE)
    assert dd.mapping_entry(extras[0x2000][2]) == 0x20000220
    assert dd.mapping_entry(extras[0x2001]) == 0x20010040


# --- power-on -----------------------------------------------------------------------


def test_the_dictionary_is_the_packaged_edss_with_the_node_id_resolved() -> None:
    """No EDS (None or ''): the packaged one, $NODEID resolved; SDO replies on 0x580+id."""
    assert dd.packaged_eds_path().name == "haptic_cia402_drive.eds"
    assert dd.packaged_eds_path().is_file()
    for eds in (None, ""):
        dictionary = dd.load_drive_dictionary(eds, 5)
        assert dictionary[0x1400][1].default == INVALID | 0x205
        assert dictionary[0x1800][1].default == INVALID | 0x185
    link = _Link(node_id=5)
    assert link.read(0x1000) == 0x00020192  # CiA 402 device, servo
    assert link.read(0x1018, 2) == 0x4C02
    assert link.node.sdo[0x1008].raw == "haptic-teleop CiA 402 drive"  # segmented upload
    assert {frame_id for frame_id, _ in link.sent} == {0x585}


def test_a_fresh_drive_has_the_eds_defaults_cached() -> None:
    """The cached configuration of a new drive is the packaged EDS's defaults."""
    device = _Link().device
    assert device.rpdo == dd.PdoLayout(False, 0x203, 255, (device.dictionary[0x6040],), 0)
    assert device.tpdo == dd.PdoLayout(False, 0x183, 255, (device.dictionary[0x6041],), 0)
    assert device.sync_cob_id == 0x80 and device.sync_counter_overflow == 0
    assert device.heartbeat_producer_ms == 0
    assert (device.heartbeat_consumer_node, device.heartbeat_consumer_ms) == (0, 0)
    assert device.interpolation_period_s == pytest.approx(0.010, rel=1e-12)
    assert device.following_error_window_counts == 20000
    assert device.following_error_timeout_s == pytest.approx(0.010, rel=1e-12)
    assert (device.abort_connection_option, device.quick_stop_option) == (1, 2)
    assert not device.refresh_if_changed()


def test_the_cached_layouts_are_values_changed_only_through_the_dictionary() -> None:
    """A cached PdoLayout is frozen: it changes only by a dictionary write and refresh."""
    device = _Link().device
    with pytest.raises(dataclasses.FrozenInstanceError):
        device.tpdo.enabled = True  # type: ignore[misc]
    assert not device.tpdo.enabled


def test_a_fresh_runtime_is_a_drive_at_power_on() -> None:
    """DriveRuntime's defaults: pre-operational, switch on disabled, no mode, all zero."""
    runtime = DriveRuntime(9)
    assert dataclasses.asdict(runtime) == {
        "node_id": 9, "nmt_state": "pre-operational", "state": DriveState.SWITCH_ON_DISABLED,
        "mode": 0, "controlword": 0, "received_controlword": None, "received_target": None,
        "target_counts": 0, "position_counts": 0, "pending_fault_code": 0,
        "persistent_fault_code": 0, "error_code": 0, "drop_tpdo": 0, "syncs_without_rpdo": 0,
        "following_error_syncs": 0, "status_extra": 0, "last_tpdos": (), "sync_count": 0}


def test_a_runtime_copy_is_equal_and_independent() -> None:
    """DriveRuntime.copy: the same fields, and changing the copy leaves the original."""
    runtime = DriveRuntime(4, mode=8, target_counts=17, last_tpdos=(b"\x01",))
    clone = runtime.copy()
    assert clone == runtime and clone is not runtime and type(clone) is DriveRuntime
    clone.target_counts = 18
    assert runtime.target_counts == 17


# --- PDO communication parameters ---------------------------------------------------


def test_a_valid_pdos_cob_id_is_fixed_and_29_bit_ids_are_refused() -> None:
    """PDO COB-ID: free while invalid, fixed (bits 0-10) while valid, 29-bit refused."""
    for comm, base in ((0x1400, 0x200), (0x1800, 0x180)):
        link = _Link()
        assert link.read(comm, 1) == INVALID | base + NODE
        assert link.write(comm, 1, INVALID | base + 0x21) is None
        assert link.write(comm, 1, base + 0x22) is None  # invalid to valid, a new id
        layout = link.device.rpdo if comm == 0x1400 else link.device.tpdo
        assert layout.enabled and layout.cob_id == base + 0x22
        assert link.write(comm, 1, base + 0x22) is None  # the same id again
        assert link.write(comm, 1, 0x40000000 | base + 0x22) is None  # bit 30 only
        assert link.write(comm, 1, base + 0x23) == VALUE_RANGE  # valid: its id is fixed
        assert link.write(comm, 1, base + 0x22 + 0x100) == VALUE_RANGE
        assert link.write(comm, 1, base + 0x22 + 0x400) == VALUE_RANGE
        assert link.write(comm, 1, INVALID | base + 0x24) is None  # invalid, a new id
        layout = link.device.rpdo if comm == 0x1400 else link.device.tpdo
        assert not layout.enabled and layout.cob_id == base + 0x24
        assert link.write(comm, 1, INVALID | dd.PDO_29BIT | base + 0x24) == VALUE_RANGE
        assert link.write(comm, 1, dd.PDO_29BIT | base + 0x24) == VALUE_RANGE
        assert link.read(comm, 1) == INVALID | base + 0x24


def test_the_transmission_types_are_cia_301s_without_rtr() -> None:
    """Transmission types 0-240, 254, 255 taken; 241-253 refused (reserved, RTR only)."""
    for comm in (0x1400, 0x1800):
        link = _Link()
        for kind in (0, 1, 2, 239, 240, 254, 255):
            assert link.write(comm, 2, kind) is None, kind
            layout = link.device.rpdo if comm == 0x1400 else link.device.tpdo
            assert layout.transmission_type == kind
        for kind in (241, 250, 251, 252, 253):
            assert link.write(comm, 2, kind) == VALUE_RANGE, kind
        assert link.read(comm, 2) == 255
        assert link.write(comm, 5, 250) is None  # the event timer, ms
        layout = link.device.rpdo if comm == 0x1400 else link.device.tpdo
        assert layout.event_timer_ms == 250
    assert link.write(0x1800, 3, 1000) is None  # the inhibit time, 100 us


def test_a_pdo_without_an_event_timer_entry_has_none(tmp_path: Path) -> None:
    """A communication record without sub-index 5 (an EDS may omit it): event timer 0."""
    link = _Link(eds=_eds_with_extras(tmp_path))
    assert 5 not in link.device.dictionary[0x1400]
    assert link.write(0x1800, 5, 40) is None
    assert (link.device.rpdo.event_timer_ms, link.device.tpdo.event_timer_ms) == (0, 40)


# --- PDO mapping --------------------------------------------------------------------


@pytest.mark.parametrize(("comm", "mapping", "other"), [(0x1400, 0x1600, 0x1800),
                                                        (0x1800, 0x1A00, 0x1400)])
def test_a_pdo_is_mapped_only_while_it_is_invalid_and_its_count_is_0(
        comm: int, mapping: int, other: int) -> None:
    """Mapping only while this PDO is invalid and its count 0 (else 0x06010000)."""
    link = _Link()
    assert link.write(other + 0, 1, (0x180 if other == 0x1800 else 0x200) + NODE) is None
    assert link.write(mapping, 1, 0x60400010) == UNSUPPORTED  # count 1
    assert link.write(mapping, 0, 0) is None  # the other PDO valid: this one is still free
    entry = 0x60400010 if mapping == 0x1600 else 0x60410010
    assert link.write(mapping, 1, entry) is None
    assert link.write(mapping, 0, 1) is None
    assert link.write(comm, 1, (0x180 if comm == 0x1800 else 0x200) + NODE) is None
    assert link.write(mapping, 0, 0) == UNSUPPORTED
    assert link.write(mapping, 1, entry) == UNSUPPORTED
    assert link.write(mapping, 2, entry) == UNSUPPORTED
    assert link.read(mapping, 0) == 1


def _free(link: _Link, comm: int, mapping: int) -> None:
    """Disable the PDO and set its count to 0 (steps 1 and 2 of the mapping procedure)."""
    assert link.write(comm, 1, link.read(comm, 1) | INVALID) is None
    assert link.write(mapping, 0, 0) is None


def _map(link: _Link, mapping: int, entries: tuple[int, ...]) -> int | None:
    """Write ``entries`` then the count; the count's abort code, or None."""
    for subindex, entry in enumerate(entries, 1):
        assert link.write(mapping, subindex, entry) is None  # checked with the count
    return link.write(mapping, 0, len(entries))


def test_only_existing_mappable_objects_of_the_right_length_and_access_are_mapped(
        tmp_path: Path) -> None:
    """The count checks each entry: exists, mappable, its length, RPDO writable/TPDO readable."""
    link = _Link(eds=_eds_with_extras(tmp_path))
    _free(link, 0x1400, 0x1600)
    _free(link, 0x1800, 0x1A00)
    for mapping, entry, code in (
            (0x1600, 0x12340020, NOT_MAPPABLE),  # no such object
            (0x1600, 0x20000320, NOT_MAPPABLE),  # no such sub-index
            (0x1600, 0x60650020, NOT_MAPPABLE),  # exists, not mappable
            (0x1A00, 0x60650020, NOT_MAPPABLE),
            (0x1600, 0x607A0010, NOT_MAPPABLE),  # wrong length
            (0x1600, 0x607A0040, NOT_MAPPABLE),
            (0x1A00, 0x60640010, NOT_MAPPABLE),
            (0x1600, 0x60410010, NOT_MAPPABLE),  # read-only into an RPDO
            (0x1600, 0x20000220, NOT_MAPPABLE),
            (0x1A00, 0x20020008, NOT_MAPPABLE),  # write-only into a TPDO
            (0x1600, 0x20020008, None),
            (0x1600, 0x20000110, None),
            (0x1A00, 0x20000110, None),
            (0x1A00, 0x20000220, None),
            (0x1A00, 0x60410010, None),
            (0x1600, 0x607A0020, None)):
        assert _map(link, mapping, (entry,)) == code, hex(entry)
        assert link.write(mapping, 0, 0) is None
    assert _map(link, 0x1A00, (0x20000220, 0x20000110, 0x60410010)) is None
    assert [(v.index, v.subindex) for v in link.device.tpdo.mapping] == [
        (0x2000, 2), (0x2000, 1), (0x6041, 0)]
    assert link.device.tpdo.size == 8 and link.device.tpdo.indices == (0x2000, 0x2000, 0x6041)


def test_the_count_checks_its_entries_only_and_at_most_8() -> None:
    """The count checks only its entries, in order, and is at most the record's 8."""
    link = _Link()
    _free(link, 0x1400, 0x1600)
    assert link.write(0x1600, 3, 0x12340020) is None  # not mapped: not checked
    assert _map(link, 0x1600, (0x607A0020, 0x60400010)) is None
    assert link.device.rpdo.indices == (0x607A, 0x6040)
    assert link.write(0x1600, 0, 0) is None
    assert link.write(0x1600, 0, 3) == NOT_MAPPABLE
    for subindex in range(3, 9):
        assert link.write(0x1600, subindex, 0x60600008) is None
    assert link.write(0x1600, 0, 8) is None
    assert link.device.rpdo.indices == (0x607A, 0x6040) + (0x6060,) * 6
    assert link.write(0x1600, 0, 0) is None
    assert link.write(0x1600, 0, 9) == VALUE_RANGE
    assert link.read(0x1600, 0) == 0


def test_the_pdo_length_on_can_fd_is_the_8_entries(tmp_path: Path) -> None:
    """On CAN FD (the default) 8 entries of 64 bits, 64 bytes, are one PDO."""
    link = _Link(eds=_eds_with_extras(tmp_path))
    _free(link, 0x1800, 0x1A00)
    assert _map(link, 0x1A00, (0x20010040,) * 8) is None
    assert link.device.tpdo.size == 64


# --- cached configuration -----------------------------------------------------------


def test_the_communication_objects_are_read_back_after_a_write() -> None:
    """SYNC id, heartbeats, interpolation period, following error, reactions are re-read."""
    link = _Link()
    device = link.device
    assert link.write(0x1005, 0, 0x400000A1) is None
    assert device.sync_cob_id == 0xA1
    assert link.write(0x1017, 0, 150) is None
    assert device.heartbeat_producer_ms == 150
    assert link.write(0x1016, 1, 0x007F0123) is None
    assert (device.heartbeat_consumer_node, device.heartbeat_consumer_ms) == (0x7F, 0x123)
    assert link.write(0x1016, 1, 0x0001FFFF) is None
    assert (device.heartbeat_consumer_node, device.heartbeat_consumer_ms) == (1, 0xFFFF)
    assert link.write(0x60C2, 1, 5) is None
    assert link.write(0x60C2, 2, -4) is None
    assert device.interpolation_period_s == pytest.approx(5e-4, rel=1e-12)
    assert link.write(0x60C2, 2, 0) is None
    assert device.interpolation_period_s == 5.0
    assert link.write(0x6065, 0, 1234) is None
    assert device.following_error_window_counts == 1234
    assert link.write(0x6066, 0, 25) is None
    assert device.following_error_timeout_s == pytest.approx(0.025, rel=1e-12)
    assert link.write(0x6007, 0, 3) is None
    assert link.write(0x605A, 0, 6) is None
    assert (device.abort_connection_option, device.quick_stop_option) == (3, 6)


def test_the_interpolation_period_value_is_never_0() -> None:
    """0x60C2:01 = 0 refused (no period); 1 taken; the index (sub 2) may be 0."""
    link = _Link()
    assert link.write(0x60C2, 1, 0) == VALUE_RANGE
    assert link.write(0x60C2, 1, 1) is None
    assert link.write(0x60C2, 2, 0) is None
    assert link.read(0x60C2, 1) == 1


def test_the_sync_counter_overflow_is_0_or_2_to_240() -> None:
    """0x1019 (CiA 301): 0 no counter, 1 and 241-255 reserved (refused), 2-240 taken."""
    link = _Link()
    for value in (2, 240, 0, 17):
        assert link.write(0x1019, 0, value) is None
        assert link.device.sync_counter_overflow == value
    for value in (1, 241, 255):
        assert link.write(0x1019, 0, value) == VALUE_RANGE
    assert link.read(0x1019) == 17


# --- the application objects --------------------------------------------------------


def test_the_runtime_objects_read_the_runtime() -> None:
    """SDO uploads of the dynamic objects read the runtime and the position, not the store."""
    link = _Link(position=-1234)
    runtime = link.runtime
    runtime.state, runtime.mode = DriveState.OPERATION_ENABLED, 8
    runtime.error_code, runtime.controlword, runtime.target_counts = 0x2310, 0x000F, 5000
    runtime.status_extra = dd.SW_WARNING
    assert link.read(0x6041) == 0x1000 | 0x0200 | 0x80 | 0x27
    assert link.read(0x6064) == -1234
    assert link.read(0x6060) == link.read(0x6061) == 8
    assert link.read(0x603F) == 0x2310
    assert link.read(0x6040) == 0x000F
    assert link.read(0x607A) == 5000
    assert link.read(0x60F4) == 5000 - -1234  # demand - actual
    assert link.read(0x6065) == 20000  # not a runtime object: the dictionary's


@pytest.mark.parametrize("state", list(DriveState))
def test_the_error_register_shows_a_fault(state: DriveState) -> None:
    """0x1001 bit 0 (generic error) is set in Fault and Fault reaction active only."""
    link = _Link()
    link.runtime.state = state
    faulted = state in (DriveState.FAULT, DriveState.FAULT_REACTION_ACTIVE)
    assert link.read(0x1001) == (0x01 if faulted else 0x00)


def test_the_modes_taken_are_those_0x6502_lists() -> None:
    """0x6060 takes 0 and the modes 0x6502 lists (1, 8), sets the runtime's mode; else refused."""
    link = _Link()
    supported = link.read(0x6502)
    modes = {OperationMode.NAME2CODE[name] for name in OperationMode.NAME2CODE
             if OperationMode.NAME2CODE[name] and supported & 1 << (
                 OperationMode.NAME2CODE[name] - 1)}
    assert modes == {1, 8}
    for mode in (8, 0, 1):
        assert link.write(0x6060, 0, mode) is None
        assert link.runtime.mode == mode == link.read(0x6061)
    for mode in (-1, 2, 3, 6, 7, 9, 10):
        assert link.write(0x6060, 0, mode) == VALUE_RANGE
        assert link.runtime.mode == 1


def test_a_written_controlword_and_target_are_latched_for_the_sync() -> None:
    """0x6040/0x607A writes are latched; a target is applied at once unless enabled."""
    link = _Link()
    runtime = link.runtime
    assert link.write(0x6040, 0, 0x0006) is None
    assert runtime.received_controlword == 0x0006 and runtime.controlword == 0
    assert link.write(0x607A, 0, -300) is None
    assert (runtime.received_target, runtime.target_counts) == (-300, -300)
    runtime.state = DriveState.OPERATION_ENABLED
    assert link.write(0x607A, 0, 700) is None
    assert (runtime.received_target, runtime.target_counts) == (700, -300)
    assert link.write(0x6041, 0, 1) == READ_ONLY


@pytest.mark.parametrize("mode", [0, 1, 8])
@pytest.mark.parametrize("state", list(DriveState))
def test_the_statusword_is_the_states_coding_remote_and_csp_following(
        state: DriveState, mode: int) -> None:
    """Statusword: the state's coding, bit 9 remote, bit 12 enabled in csp, the extra bits."""
    link = _Link()
    runtime = link.runtime
    runtime.state, runtime.mode = state, mode
    for extra in (0, dd.SW_WARNING | dd.SW_FOLLOWING_ERROR):
        runtime.status_extra = extra
        word = link.device.statusword(runtime)
        assert [name for name, (mask, value) in State402.SW_MASK.items()
                if word & mask == value] == [state.value.upper()]
        follows = state is DriveState.OPERATION_ENABLED and mode == 8
        assert word == cia402.STATUS_BITS[state] | 1 << 9 | follows << 12 | extra
        assert link.read(0x6041) == word


# --- PDO payloads -------------------------------------------------------------------

_TPDO_OBJECTS = (0x6041, 0x6064, 0x6061, 0x603F, 0x607A, 0x60F4, 0x6040)


def _runtime_for_payloads() -> DriveRuntime:
    return DriveRuntime(NODE, state=DriveState.OPERATION_ENABLED, mode=8, controlword=0x000F,
                        target_counts=-40000, error_code=0x5441)


def test_a_tpdo_is_the_mapped_objects_values_as_canopen_decodes_them() -> None:
    """A TPDO is the mapped objects' values, of the runtime given, as their SDO uploads."""
    link = _Link(runtime=DriveRuntime(NODE))
    pdo = link.node.tpdo[1]
    link.map_pdo(pdo, _TPDO_OBJECTS)
    runtime = _runtime_for_payloads()
    payload = link.device.encode_tpdo(runtime, 123456)
    link._deliver(0x180 + NODE, payload)
    decoded = [variable.raw for variable in pdo.map]
    word = 0x0200 | 0x1000 | 0x27
    assert decoded == [word, 123456, 8, 0x5441, -40000, -40000 - 123456, 0x000F]
    assert len(payload) == 2 + 4 + 1 + 2 + 4 + 4 + 2
    link.runtime, link.device.runtime, link.position = runtime, runtime, 123456
    assert decoded == [link.read(index) for index in _TPDO_OBJECTS]
    link.map_pdo(pdo, tuple(reversed(_TPDO_OBJECTS)))
    link._deliver(0x180 + NODE, link.device.encode_tpdo(runtime, 123456))
    assert [variable.raw for variable in pdo.map] == list(reversed(decoded))


def test_the_loops_tpdo_and_the_default_one() -> None:
    """TPDO1 as the loop maps it (statusword, position) and at the EDS default."""
    link = _Link()
    runtime = _runtime_for_payloads()
    assert link.device.encode_tpdo(runtime, -5) == struct.pack("<H", 0x1227)
    link.map_pdo(link.node.tpdo[1], (0x6041, 0x6064))
    assert link.device.encode_tpdo(runtime, -5) == struct.pack("<Hi", 0x1227, -5)
    assert link.device.tpdo.codec().unpack(struct.pack("<Hi", 1, -2)) == (1, -2)
    assert link.device.tpdo.size == 6 and type(link.device.tpdo.size) is int


def test_an_rpdo_is_decoded_as_canopen_encodes_it_and_a_wrong_length_is_an_emcy() -> None:
    """An RPDO decodes as canopen encodes it; a wrong length is EMCY 0x8210/0x8220."""
    link = _Link()
    pdo = link.node.rpdo[1]
    link.map_pdo(pdo, (0x607A, 0x6040, 0x6060))
    values = {0x607A: -123456, 0x6040: 0x000F, 0x6060: 8}
    for variable in pdo.map:
        variable.raw = values[variable.index]
    payload = bytes(pdo.data)
    assert len(payload) == 7
    assert link.device.decode_rpdo(payload) == values
    assert link.device.decode_rpdo(payload[:-1]) == dd.EMCY_PDO_LENGTH_SHORT == 0x8210
    assert link.device.decode_rpdo(payload + b"\x00") == dd.EMCY_PDO_LENGTH_EXCEEDED == 0x8220
    assert link.device.decode_rpdo(b"") == 0x8210


# --- defects found (fixed) ------------------------------------------------------------

NO_SUBINDEX = _abort("Subindex does not exist")


def test_a_variable_has_only_sub_index_0() -> None:
    """A plain variable has only sub-index 0: SDO access to 1 is 0x06090011, no mapping."""
    link = _Link()
    assert dd.ABORT_NO_SUBINDEX == NO_SUBINDEX == 0x06090011
    for index in (0x6041, 0x6065, 0x1017):
        with pytest.raises(SdoAbortedError) as error:
            link.node.sdo.upload(index, 1)
        assert error.value.code == NO_SUBINDEX
    with pytest.raises(SdoAbortedError) as error:
        link.node.sdo.download(0x6040, 1, b"\x0f\x00")
    assert error.value.code == NO_SUBINDEX and link.runtime.received_controlword is None
    with pytest.raises(SdoAbortedError) as error:
        link.node.sdo.upload(0x1018, 5)
    assert error.value.code == NO_SUBINDEX
    _free(link, 0x1400, 0x1600)
    assert _map(link, 0x1600, (0x607A0120,)) == NOT_MAPPABLE


def test_a_tpdo_carries_the_mode_and_any_other_objects_value(tmp_path: Path) -> None:
    """A TPDO carries 0x6060's mode and any other object's value in the dictionary."""
    link = _Link(eds=_eds_with_extras(tmp_path))
    pdo = link.node.tpdo[1]
    link.map_pdo(pdo, (0x6060, (0x2000, 1), (0x2000, 2), 0x2001))
    assert link.write(0x2001, 0, 2**40 + 3) is None
    runtime = _runtime_for_payloads()
    link._deliver(0x180 + NODE, link.device.encode_tpdo(runtime, 0))
    assert [variable.raw for variable in pdo.map] == [8, 0x1111, -7, 2**40 + 3]


def test_on_classical_can_a_pdo_is_at_most_8_bytes() -> None:
    """A drive on classical CAN refuses a mapping of more than 8 bytes (0x06040042)."""
    link = _Link(fd=False)
    _free(link, 0x1800, 0x1A00)
    assert _map(link, 0x1A00, (0x60640020, 0x607A0020, 0x60610008)) == PDO_LENGTH  # 9
    assert link.write(0x1A00, 0, 2) is None  # 8 bytes
    assert link.device.tpdo.size == 8
    assert link.write(0x1A00, 0, 0) is None
    assert _map(link, 0x1A00, (0x60640020, 0x60410010, 0x60610008, 0x60600008)) is None
    assert link.write(0x1A00, 0, 0) is None
    assert link.write(0x1A00, 0, 4) is None
    assert link.write(0x1A00, 0, 0) is None
    assert link.write(0x1A00, 2, 0x607A0020) is None  # 2 bytes more
    assert link.write(0x1A00, 0, 4) == PDO_LENGTH  # 10 bytes
    assert link.read(0x1A00, 0) == 0


@pytest.mark.parametrize(("index", "kind"), [
    (0x13FF, None),
    (0x1400, (0x1400, True)), (0x15FF, (0x15FF, True)),  # RPDO communication
    (0x1600, (0x1400, True)), (0x17FF, (0x15FF, True)),  # RPDO mapping
    (0x1800, (0x1800, False)), (0x19FF, (0x19FF, False)),  # TPDO communication
    (0x1A00, (0x1800, False)), (0x1BFF, (0x19FF, False)),  # TPDO mapping
    (0x1C00, None),
])
def test_the_pdo_object_ranges_end_where_cia_301_ends_them(
        index: int, kind: tuple[int, bool] | None) -> None:
    """CiA 301's ranges: RPDO communication 0x1400-0x15FF and mapping 0x1600-0x17FF, TPDO
    communication 0x1800-0x19FF and mapping 0x1A00-0x1BFF (512 PDOs each); a mapping object
    belongs to the communication object 0x200 below it. Each range's first and last index."""
    assert dd.pdo_kind(index) == kind


def test_raw_or_gives_the_absent_value_for_a_sub_index_the_eds_lacks() -> None:
    """A variable has only sub-index 0, a record only its own entries: anything else is
    absent, never another entry's value."""
    device = _Link().device
    assert device.raw_or(0x1017, 0, 42) == device.raw(0x1017)
    assert device.raw_or(0x1017, 1, 42) == 42  # a variable at sub-index 1
    assert device.raw_or(0x1018, 1, 7) == device.raw(0x1018, 1)
    assert device.raw_or(0x1018, 0x7F, 7) == 7  # a record without that entry
    assert device.raw_or(0x2FFF, 0, 9) == 9  # no such object


def test_a_drive_whose_eds_lacks_the_heartbeat_and_the_interpolation_period(tmp_path) -> None:
    """Without 0x1017 the drive produces no heartbeat (0 ms); without 0x60C2 its cycle is
    the SYNC period it was given, 1 ms unless told."""
    eds = eds_variants.written(tmp_path, "bare.eds",
                               eds_variants.without(eds_variants.packaged(), 0x1017, 0x60C2))
    device = _Link(eds=eds).device
    assert device.heartbeat_producer_ms == 0
    assert device.interpolation_period_s == 1e-3
    assert _Link(eds=eds, sync_period_s=0.00054).device.interpolation_period_s == 0.00054


def _drive_of(tmp_path: Path, text: str) -> DriveObjects:
    """The drive of an EDS variant ``text`` (written to ``tmp_path``)."""
    return _Link(eds=eds_variants.written(tmp_path, "variant.eds", text)).device


def test_the_optional_communication_objects_an_eds_lacks_take_their_cia_defaults(
        tmp_path) -> None:
    """No heartbeat consumer (0x1016), no node guarding (0x100C, 0x100D: the packaged EDS has
    neither), no following-error timeout (0x6066); the abort-connection option (0x6007) and
    the quick-stop option (0x605A) at CiA 402's defaults, 1 and 2."""
    packaged = _Link().device
    assert (packaged.guard_time_ms, packaged.life_time_factor) == (0, 0)
    device = _drive_of(tmp_path, eds_variants.without(
        eds_variants.packaged(), 0x1016, 0x6066, 0x6007, 0x605A))
    assert (device.heartbeat_consumer_node, device.heartbeat_consumer_ms) == (0, 0)
    assert (device.guard_time_ms, device.life_time_factor) == (0, 0)
    assert device.following_error_timeout_s == 0.0
    assert (device.abort_connection_option, device.quick_stop_option) == (1, 2)


def test_a_drive_without_pdo_1_has_disabled_empty_layouts_for_it(tmp_path) -> None:
    device = _drive_of(tmp_path, eds_variants.without(
        eds_variants.packaged(), 0x1400, 0x1600, 0x1800, 0x1A00))
    empty = dd.PdoLayout(False, 0, 0, (), 0)
    assert device.rpdo == empty and device.tpdo == empty
    assert (device.rpdo.comm_index, device.tpdo.comm_index) == (0x1400, 0x1800)
    assert device.rpdos_by_id == {} and device.tpdos == ()


def test_a_mapping_object_without_its_communication_object_is_no_pdo(tmp_path) -> None:
    """A PDO needs both objects. (The other way round, a communication object without its
    mapping, canopen's own node refuses the dictionary.)"""
    device = _drive_of(tmp_path, eds_variants.without(eds_variants.packaged(), 0x1800))
    assert device.tpdo == dd.PdoLayout(False, 0, 0, (), 0)
    assert device.tpdo.comm_index == 0x1800 and device.tpdos == ()


def test_a_mapping_without_its_count_maps_nothing(tmp_path) -> None:
    device = _drive_of(tmp_path, eds_variants.without_sections(eds_variants.packaged(),
                                                               "1A00sub0"))
    assert device.tpdo.mapping == () and device.tpdo.cob_id == 0x180 + NODE


def test_a_mapping_entry_of_the_wrong_length_disables_the_pdo(tmp_path) -> None:
    """The statusword (16 bits) mapped as 8 bits: the drive cannot fill that frame, so the
    PDO is disabled, its COB-ID kept, nothing else."""
    device = _drive_of(tmp_path, eds_variants.entry_set(
        eds_variants.packaged(), "1A00sub1", "DefaultValue", "0x60410008"))
    assert device.tpdo == dd.PdoLayout(False, 0x180 + NODE, 0, (), 0)
    assert device.tpdo.cob_id == 0x180 + NODE


def test_a_communication_record_without_its_transmission_type_is_255(tmp_path) -> None:
    """CiA 301: 255, event-driven (device profile specific), when the type is not given."""
    device = _drive_of(tmp_path, eds_variants.without_sections(eds_variants.packaged(),
                                                               "1800sub2"))
    assert device.tpdo.transmission_type == 255


def test_the_identity_objects_read_the_eds_device_information(tmp_path) -> None:
    """0x1018:01-03 are the ``[DeviceInfo]`` vendor, product and revision numbers, over what
    the EDS gives those entries as their defaults."""
    text = eds_variants.packaged()
    for key, value in (("VendorNumber", "0x0000ABCD"), ("ProductNumber", "0x00001234"),
                       ("RevisionNumber", "0x00020003")):
        text = eds_variants.entry_set(text, "DeviceInfo", key, value)
    device = _drive_of(tmp_path, text)
    assert [device.raw(0x1018, sub) for sub in (1, 2, 3)] == [0xABCD, 0x1234, 0x20003]


def test_an_object_the_eds_gives_no_value_reads_0(tmp_path) -> None:
    """As a drive's firmware has it: an object without a default value is 0."""
    text = "".join(body if name.upper() != "6066" else body.replace("DefaultValue=10\n", "")
                   for name, body in eds_variants.sections(eds_variants.packaged()))
    head = eds_variants.packaged().split("[", 1)[0]
    assert "DefaultValue=10\n" not in dict(eds_variants.sections(head + text))["6066"]
    device = _drive_of(tmp_path, head + text)
    assert device.raw(0x6066) == 0 and device.following_error_timeout_s == 0.0
