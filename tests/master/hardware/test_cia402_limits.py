"""The CiA 301/402 wire values of master/hardware/cia402.py against independent references:
python-canopen's own tables (NMT commands, SDO command specifiers and abort codes, the CiA
402 controlword commands and statusword masks, the operation modes, the SDO client's
COB-IDs) and the packaged drive EDS (the objects' types, access and PDO mapping).

The emulated drives use this module too, so a wrong constant would pass every test run
against them and fail only on a real drive; these tests pin each value to the standard."""

from __future__ import annotations

import dataclasses
import struct
from importlib import resources

import canopen
import pytest
from canopen import objectdictionary as od
from canopen.nmt import NMT_COMMANDS
from canopen.profiles.p402 import OperationMode, State402
from canopen.sdo import constants as sdo
from canopen.sync import SyncProducer

from haptic.master.hardware import cia402
from haptic.master.hardware.cia402 import DriveState

#: Our states by python-canopen's names.
CANOPEN_NAMES = {state: state.value.upper() for state in DriveState}


def test_the_built_in_objects_are_the_packaged_edss() -> None:
    path = resources.files("haptic.master.hardware").joinpath("eds/haptic_cia402_drive.eds")
    eds = canopen.import_od(str(path))
    for variable in (cia402.CONTROLWORD, cia402.STATUSWORD, cia402.MODES_OF_OPERATION,
                     cia402.MODES_OF_OPERATION_DISPLAY, cia402.TARGET_POSITION,
                     cia402.POSITION_ACTUAL_VALUE):
        reference = eds[variable.index]
        assert variable.name == reference.name
        assert variable.data_type == reference.data_type, variable.name
        assert (variable.readable, variable.writable) == (reference.readable,
                                                          reference.writable), variable.name
        assert variable.pdo_mappable is reference.pdo_mappable is True, variable.name
    assert [v.index for v in cia402.RPDO1_MAPPING] == [0x6040, 0x607A]
    assert [v.index for v in cia402.TPDO1_MAPPING] == [0x6041, 0x6064]


def test_the_cob_ids_are_the_predefined_connection_sets() -> None:
    node = canopen.RemoteNode(5, od.ObjectDictionary())
    assert (cia402.SDO_RX_BASE + 5, cia402.SDO_TX_BASE + 5) == (node.sdo.rx_cobid,
                                                              node.sdo.tx_cobid)
    assert cia402.SYNC_COB_ID == SyncProducer.cob_id
    # CiA 301 7.3.5: NMT 0x000, EMCY 0x080 + node, TPDO1 0x180 + node, RPDO1 0x200 + node
    assert (cia402.NMT_COB_ID, cia402.EMCY_BASE, cia402.TPDO1_BASE, cia402.RPDO1_BASE) == (
        0x000, 0x080, 0x180, 0x200)


def test_the_nmt_commands_and_the_mode_are_the_standards() -> None:
    assert cia402.NMT_START == NMT_COMMANDS["OPERATIONAL"]
    assert cia402.NMT_STOP == NMT_COMMANDS["STOPPED"]
    assert cia402.NMT_PRE_OPERATIONAL == NMT_COMMANDS["PRE-OPERATIONAL"]
    assert cia402.NMT_RESET_NODE == NMT_COMMANDS["RESET"]
    assert cia402.NMT_RESET_COMMUNICATION == NMT_COMMANDS["RESET COMMUNICATION"]
    assert cia402.MODE_CYCLIC_SYNC_POSITION == OperationMode.CYCLIC_SYNCHRONOUS_POSITION


def test_the_controlword_commands_are_the_standards() -> None:
    assert cia402.CW_SHUTDOWN == State402.CW_SHUTDOWN
    assert cia402.CW_SWITCH_ON == State402.CW_SWITCH_ON
    assert cia402.CW_ENABLE_OPERATION == State402.CW_OPERATION_ENABLED
    assert cia402.CW_DISABLE_VOLTAGE == State402.CW_DISABLE_VOLTAGE
    assert cia402.CW_QUICK_STOP == State402.CW_QUICK_STOP
    assert cia402.CW_FAULT_RESET == State402.TRANSITIONTABLE[("FAULT", "SWITCH ON DISABLED")]
    assert cia402.CW_DISABLE_OPERATION == State402.TRANSITIONTABLE[("OPERATION ENABLED",
                                                                    "SWITCHED ON")]


def test_every_statusword_decodes_to_the_state_canopen_reads() -> None:
    """All 65536 words: the state whose (mask, value) python-canopen lists, else (a reserved
    code) a fault."""
    for word in range(0x10000):
        names = [name for name, (mask, value) in State402.SW_MASK.items()
                 if word & mask == value]
        expected = names[0] if names else "FAULT"
        assert CANOPEN_NAMES[cia402.decode_statusword(word)] == expected, hex(word)


def test_each_state_reports_its_bits_the_remote_bit_and_following_only_when_enabled() -> None:
    for state in DriveState:
        word = cia402.statusword_for(state)
        mask, value = State402.SW_MASK[CANOPEN_NAMES[state]]
        assert word & mask == value and word & 0x0200, state
        assert word & ~0x0200 == cia402.STATUS_BITS[state]
        following = cia402.statusword_for(state, following_target=True)
        assert following == word | (0x1000 if state is DriveState.OPERATION_ENABLED else 0)
    assert (cia402.STATUS_REMOTE, cia402.STATUS_FOLLOWING_TARGET) == (1 << 9, 1 << 12)


def test_fault_reset_acts_on_bit_7s_rising_edge_only() -> None:
    step = cia402.next_drive_state
    assert step(DriveState.FAULT, 0x80, 0x00) is DriveState.SWITCH_ON_DISABLED
    assert step(DriveState.FAULT, 0x80, 0x01) is DriveState.SWITCH_ON_DISABLED  # bit 0 only
    assert step(DriveState.FAULT, 0x80, 0x80) is DriveState.FAULT  # held, not rising
    assert step(DriveState.FAULT, 0x01, 0x00) is DriveState.FAULT  # another bit
    assert step(DriveState.FAULT, 0x00, 0x00) is DriveState.FAULT
    assert step(DriveState.FAULT_REACTION_ACTIVE, 0x80, 0x00) is DriveState.FAULT_REACTION_ACTIVE


def test_disable_voltage_and_quick_stop_read_only_their_bits() -> None:
    step = cia402.next_drive_state
    # disable voltage: bits 1 and 7 clear, whatever bits 0, 2 and 3 say
    for word in (0x00, 0x01, 0x04, 0x0D):
        assert step(DriveState.OPERATION_ENABLED, word, 0x0F) is DriveState.SWITCH_ON_DISABLED
    # quick stop: bit 1 set, bits 2 and 7 clear, whatever bits 0 and 3 say
    for word in (0x02, 0x03, 0x0A, 0x0B):
        assert step(DriveState.OPERATION_ENABLED, word, 0x0F) is DriveState.QUICK_STOP_ACTIVE


@pytest.mark.parametrize(("data_type", "size"), [(od.UNSIGNED8, 1), (od.UNSIGNED16, 2),
                                                 (od.INTEGER24, 3), (od.UNSIGNED32, 4)])
def test_expedited_sdo_command_specifiers_are_the_standards(data_type: int, size: int) -> None:
    """Download request and upload response: the command, expedited, size indicated, and
    the count of unused bytes (4 - size) in bits 2-3."""
    variable = od.ODVariable("x", 0x2000, 1)
    variable.data_type = data_type
    unused = (4 - size) << 2
    download = cia402.sdo_download_request(variable, 1)
    assert download[0] == sdo.REQUEST_DOWNLOAD | sdo.EXPEDITED | sdo.SIZE_SPECIFIED | unused
    assert cia402.sdo_download_size(download[0]) == size
    upload = cia402.sdo_upload_response(variable, 1)
    assert upload[0] == sdo.RESPONSE_UPLOAD | sdo.EXPEDITED | sdo.SIZE_SPECIFIED | unused
    assert download[1:4] == upload[1:4] == struct.pack("<HB", 0x2000, 1)
    assert download[4:4 + size] == upload[4:4 + size] == variable.encode_raw(1)
    assert len(download) == len(upload) == 8


def test_the_other_sdo_frames_and_the_abort_codes_are_the_standards() -> None:
    assert cia402.sdo_upload_request(cia402.STATUSWORD)[0] == sdo.REQUEST_UPLOAD
    assert cia402.sdo_download_response(0x6040, 0)[0] == sdo.RESPONSE_DOWNLOAD
    assert cia402.sdo_abort(0x6040, 0, 1)[0] == sdo.RESPONSE_ABORTED
    assert cia402.sdo_download_size(sdo.REQUEST_UPLOAD) is None
    assert cia402.SDO_ABORT_NO_OBJECT == sdo.ABORT_NOT_IN_OD
    assert cia402.SDO_ABORT_VALUE_RANGE == sdo.ABORT_INVALID_VALUE
    assert cia402.SDO_ABORT_READ_ONLY == sdo.ABORT_WRITE_READONLY
    assert cia402.SDO_ABORT_COMMAND == sdo.ABORT_INVALID_COMMAND_SPECIFIER


def test_a_decoded_sdo_frame_is_frozen_and_carries_its_four_data_bytes() -> None:
    frame = cia402.decode_sdo(bytes([0x43, 0x41, 0x60, 0x00, 1, 2, 3, 4]))
    assert frame == cia402.SdoFrame(0x43, 0x6041, 0, bytes([1, 2, 3, 4]))
    with pytest.raises(dataclasses.FrozenInstanceError):
        frame.command = 0  # type: ignore[misc]


def test_emcy_frames_carry_the_generic_error_bit_by_default_and_need_three_bytes() -> None:
    assert cia402.emcy_frame(0x8611) == bytes([0x11, 0x86, 0x01, 0, 0, 0, 0, 0])
    assert cia402.decode_emcy(bytes([0x11, 0x86, 0x81])) == (0x8611, 0x81)
    with pytest.raises(ValueError):
        cia402.decode_emcy(bytes([0x11, 0x86]))
