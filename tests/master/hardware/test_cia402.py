"""CiA 402 object dictionary, PDO/SDO/EMCY frames and the drive state machine."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from haptic.master.hardware import cia402
from haptic.master.hardware.cia402 import DriveState


def test_object_dictionary_has_the_csp_objects_with_their_types() -> None:
    dictionary = cia402.OBJECT_DICTIONARY
    expected = {0x6040: 2, 0x6041: 2, 0x6060: 1, 0x6061: 1, 0x607A: 4, 0x6064: 4}
    for index, size in expected.items():
        variable = dictionary[index]
        assert variable.STRUCT_TYPES[variable.data_type].size == size
    assert dictionary[0x6041].writable is False
    assert dictionary[0x607A].writable is True


@given(controlword=st.integers(0, 0xFFFF), target=st.integers(-(2**31), 2**31 - 1))
def test_rpdo1_round_trips(controlword: int, target: int) -> None:
    payload = cia402.encode_pdo(cia402.RPDO1_MAPPING, (controlword, target))
    assert len(payload) == 6
    assert cia402.decode_pdo(cia402.RPDO1_MAPPING, payload) == (controlword, target)


@given(statusword=st.integers(0, 0xFFFF), position=st.integers(-(2**31), 2**31 - 1))
def test_tpdo1_round_trips(statusword: int, position: int) -> None:
    payload = cia402.encode_pdo(cia402.TPDO1_MAPPING, (statusword, position))
    assert cia402.decode_pdo(cia402.TPDO1_MAPPING, payload) == (statusword, position)


def test_tpdo1_layout_is_little_endian_statusword_then_position() -> None:
    payload = cia402.encode_pdo(cia402.TPDO1_MAPPING, (0x1237, -2))
    assert payload == bytes([0x37, 0x12, 0xFE, 0xFF, 0xFF, 0xFF])


def test_pdo_rejects_out_of_range_values_and_wrong_lengths() -> None:
    with pytest.raises(ValueError):
        cia402.encode_pdo(cia402.RPDO1_MAPPING, (0x1_0000, 0))
    with pytest.raises(ValueError):
        cia402.encode_pdo(cia402.RPDO1_MAPPING, (0, 2**31))
    with pytest.raises(ValueError):
        cia402.decode_pdo(cia402.TPDO1_MAPPING, b"\x00" * 5)


@pytest.mark.parametrize("state", list(DriveState))
def test_statusword_decodes_to_the_state_it_encodes(state: DriveState) -> None:
    assert cia402.decode_statusword(cia402.statusword_for(state, following_target=True)) is state


def test_statusword_ignores_unrelated_bits() -> None:
    assert cia402.decode_statusword(0x0627 | 0x1000) is DriveState.OPERATION_ENABLED
    assert cia402.decode_statusword(0x0250) is DriveState.SWITCH_ON_DISABLED  # bit 4 voltage
    assert cia402.decode_statusword(0x0218) is DriveState.FAULT


def test_enable_sequence_walks_the_state_machine_to_operation_enabled() -> None:
    state = DriveState.FAULT
    previous = 0
    visited = [state]
    for _ in range(10):
        command = cia402.enable_command_for(state)
        if command is None:
            break
        state = cia402.next_drive_state(state, command, previous)
        previous = command
        visited.append(state)
    assert visited == [DriveState.FAULT, DriveState.SWITCH_ON_DISABLED,
                       DriveState.READY_TO_SWITCH_ON, DriveState.SWITCHED_ON,
                       DriveState.OPERATION_ENABLED]


def test_fault_reset_needs_a_rising_edge() -> None:
    assert cia402.next_drive_state(DriveState.FAULT, 0x80, 0x80) is DriveState.FAULT
    assert cia402.next_drive_state(DriveState.FAULT, 0x80, 0x00) is DriveState.SWITCH_ON_DISABLED


def test_illegal_transitions_do_nothing_and_disable_voltage_always_disables() -> None:
    # Enable operation straight from switch on disabled is not allowed.
    assert cia402.next_drive_state(DriveState.SWITCH_ON_DISABLED, cia402.CW_ENABLE_OPERATION,
                                   0) is DriveState.SWITCH_ON_DISABLED
    assert cia402.next_drive_state(DriveState.OPERATION_ENABLED, cia402.CW_DISABLE_VOLTAGE,
                                   0x0F) is DriveState.SWITCH_ON_DISABLED
    assert cia402.next_drive_state(DriveState.OPERATION_ENABLED, cia402.CW_QUICK_STOP,
                                   0x0F) is DriveState.QUICK_STOP_ACTIVE
    assert cia402.next_drive_state(DriveState.OPERATION_ENABLED, cia402.CW_DISABLE_OPERATION,
                                   0x0F) is DriveState.SWITCHED_ON


@given(value=st.integers(-128, 127))
def test_sdo_download_and_upload_frames_round_trip(value: int) -> None:
    request = cia402.decode_sdo(cia402.sdo_download_request(cia402.MODES_OF_OPERATION, value))
    assert request.command == 0x2F and request.index == 0x6060 and request.subindex == 0
    assert cia402.MODES_OF_OPERATION.decode_raw(request.data[:1]) == value
    reply = cia402.decode_sdo(cia402.sdo_upload_response(cia402.MODES_OF_OPERATION_DISPLAY,
                                                         value))
    assert reply.command == 0x4F and reply.index == 0x6061
    assert cia402.sdo_download_size(cia402.sdo_download_request(
        cia402.TARGET_POSITION, -5)[0]) == 4


def test_sdo_abort_and_emcy_frames() -> None:
    abort = cia402.decode_sdo(cia402.sdo_abort(0x1234, 0, cia402.SDO_ABORT_NO_OBJECT))
    assert abort.command == 0x80
    assert int.from_bytes(abort.data, "little") == 0x06020000
    payload = cia402.emcy_frame(0x2310, 0x03)
    assert len(payload) == 8
    assert cia402.decode_emcy(payload) == (0x2310, 0x03)


def test_quick_stop_held_stays_in_quick_stop_active() -> None:
    """CiA 402: a drive in Quick stop active that keeps receiving quick stop stays there
    (option codes 5-8); disable voltage leaves it (transition 12), enable operation resumes
    (transition 16)."""
    qsa = cia402.DriveState.QUICK_STOP_ACTIVE
    assert cia402.next_drive_state(qsa, cia402.CW_QUICK_STOP, cia402.CW_QUICK_STOP) is qsa
    assert cia402.next_drive_state(qsa, cia402.CW_DISABLE_VOLTAGE, cia402.CW_QUICK_STOP) is \
        cia402.DriveState.SWITCH_ON_DISABLED
    assert cia402.next_drive_state(qsa, cia402.CW_ENABLE_OPERATION, cia402.CW_QUICK_STOP) is \
        cia402.DriveState.OPERATION_ENABLED
