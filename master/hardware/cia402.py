"""CiA 402 servo drives over CANopen: object dictionary, state machine, PDO and SDO frames.

The object dictionary is built in code with :mod:`canopen`'s ``ObjectDictionary`` (the
objects a cyclic-synchronous-position drive needs: 0x6040 controlword, 0x6041 statusword,
0x6060/0x6061 modes of operation, 0x607A target position, 0x6064 position actual value).
PDO payloads are the mapped objects' ``encode_raw`` bytes concatenated, decoded with
``decode_raw``; frames are built here rather than through ``canopen.Network`` because the
master steps the bus deterministically, one SYNC per control cycle (docs/master.md says why).

COB-IDs follow the CiA 301 predefined connection set: NMT 0x000, SYNC 0x080, EMCY
0x080+node, TPDO1 0x180+node, RPDO1 0x200+node, SDO 0x580+node (server to client) and
0x600+node (client to server).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import Enum

from canopen import objectdictionary as od

NMT_COB_ID = 0x000
SYNC_COB_ID = 0x080
EMCY_BASE = 0x080
TPDO1_BASE = 0x180
RPDO1_BASE = 0x200
SDO_TX_BASE = 0x580  # server (drive) -> client (master)
SDO_RX_BASE = 0x600  # client (master) -> server (drive)
HEARTBEAT_BASE = 0x700  # NMT error control: heartbeats, node guarding

# NMT command specifiers (CiA 301).
NMT_START = 0x01
NMT_STOP = 0x02
NMT_PRE_OPERATIONAL = 0x80
NMT_RESET_NODE = 0x81
NMT_RESET_COMMUNICATION = 0x82

# Modes of operation (0x6060).
MODE_CYCLIC_SYNC_POSITION = 8

# Controlword commands (CiA 402 table "device control commands").
CW_SHUTDOWN = 0x0006
CW_SWITCH_ON = 0x0007
CW_ENABLE_OPERATION = 0x000F
CW_DISABLE_VOLTAGE = 0x0000
CW_QUICK_STOP = 0x0002
CW_DISABLE_OPERATION = 0x0007
CW_FAULT_RESET = 0x0080

# SDO abort codes used here.
SDO_ABORT_NO_OBJECT = 0x06020000
SDO_ABORT_VALUE_RANGE = 0x06090030
SDO_ABORT_READ_ONLY = 0x06010002
SDO_ABORT_COMMAND = 0x05040001


def _variable(name: str, index: int, data_type: int, writable: bool) -> od.ODVariable:
    variable = od.ODVariable(name, index, 0)
    variable.data_type = data_type
    variable.access_type = "rw" if writable else "ro"
    variable.pdo_mappable = True
    return variable


def build_object_dictionary() -> od.ObjectDictionary:
    """The CiA 402 objects the master and the simulated drives use."""
    dictionary = od.ObjectDictionary()
    for variable in (
        _variable("Controlword", 0x6040, od.UNSIGNED16, True),
        _variable("Statusword", 0x6041, od.UNSIGNED16, False),
        _variable("Modes of operation", 0x6060, od.INTEGER8, True),
        _variable("Modes of operation display", 0x6061, od.INTEGER8, False),
        _variable("Target position", 0x607A, od.INTEGER32, True),
        _variable("Position actual value", 0x6064, od.INTEGER32, False),
    ):
        dictionary.add_object(variable)
    return dictionary


OBJECT_DICTIONARY = build_object_dictionary()
CONTROLWORD = OBJECT_DICTIONARY[0x6040]
STATUSWORD = OBJECT_DICTIONARY[0x6041]
MODES_OF_OPERATION = OBJECT_DICTIONARY[0x6060]
MODES_OF_OPERATION_DISPLAY = OBJECT_DICTIONARY[0x6061]
TARGET_POSITION = OBJECT_DICTIONARY[0x607A]
POSITION_ACTUAL_VALUE = OBJECT_DICTIONARY[0x6064]

#: RPDO1 (master -> drive): controlword, target position (counts). 6 bytes.
RPDO1_MAPPING = (CONTROLWORD, TARGET_POSITION)
#: TPDO1 (drive -> master): statusword, position actual value (counts). 6 bytes.
TPDO1_MAPPING = (STATUSWORD, POSITION_ACTUAL_VALUE)


def encode_pdo(mapping: tuple[od.ODVariable, ...], values: tuple[int, ...]) -> bytes:
    """PDO payload: the mapped objects' raw encodings, in mapping order.

    Raises ``ValueError`` when a value does not fit its object's data type.
    """
    if len(values) != len(mapping):
        raise ValueError(f"{len(mapping)} values expected, got {len(values)}")
    pairs = zip(mapping, values, strict=True)
    return b"".join(variable.encode_raw(int(value)) for variable, value in pairs)


def decode_pdo(mapping: tuple[od.ODVariable, ...], data: bytes) -> tuple[int, ...]:
    """The mapped objects' values from a PDO payload; ``ValueError`` on a wrong length."""
    sizes = [variable.STRUCT_TYPES[variable.data_type].size for variable in mapping]
    if len(data) != sum(sizes):
        raise ValueError(f"PDO payload of {len(data)} bytes, expected {sum(sizes)}")
    values = []
    offset = 0
    for variable, size in zip(mapping, sizes, strict=True):
        values.append(int(variable.decode_raw(bytes(data[offset:offset + size]))))
        offset += size
    return tuple(values)


class DriveState(Enum):
    """CiA 402 power drive system states, decoded from the statusword."""

    NOT_READY_TO_SWITCH_ON = "not ready to switch on"
    SWITCH_ON_DISABLED = "switch on disabled"
    READY_TO_SWITCH_ON = "ready to switch on"
    SWITCHED_ON = "switched on"
    OPERATION_ENABLED = "operation enabled"
    QUICK_STOP_ACTIVE = "quick stop active"
    FAULT_REACTION_ACTIVE = "fault reaction active"
    FAULT = "fault"


# (mask, value, state), checked in order (CiA 402 statusword coding).
_STATUS_PATTERNS = (
    (0x4F, 0x00, DriveState.NOT_READY_TO_SWITCH_ON),
    (0x4F, 0x40, DriveState.SWITCH_ON_DISABLED),
    (0x6F, 0x21, DriveState.READY_TO_SWITCH_ON),
    (0x6F, 0x23, DriveState.SWITCHED_ON),
    (0x6F, 0x27, DriveState.OPERATION_ENABLED),
    (0x6F, 0x07, DriveState.QUICK_STOP_ACTIVE),
    (0x4F, 0x0F, DriveState.FAULT_REACTION_ACTIVE),
    (0x4F, 0x08, DriveState.FAULT),
)

#: The statusword low bits a drive reports in each state (bit 9 "remote" is added).
STATUS_BITS = {
    DriveState.NOT_READY_TO_SWITCH_ON: 0x00,
    DriveState.SWITCH_ON_DISABLED: 0x40,
    DriveState.READY_TO_SWITCH_ON: 0x21,
    DriveState.SWITCHED_ON: 0x23,
    DriveState.OPERATION_ENABLED: 0x27,
    DriveState.QUICK_STOP_ACTIVE: 0x07,
    DriveState.FAULT_REACTION_ACTIVE: 0x0F,
    DriveState.FAULT: 0x08,
}
STATUS_REMOTE = 0x0200
#: Statusword bit 12 in cyclic synchronous position mode: the drive follows the target.
STATUS_FOLLOWING_TARGET = 0x1000


def decode_statusword(statusword: int) -> DriveState:
    """The CiA 402 state a statusword reports."""
    for mask, value, state in _STATUS_PATTERNS:
        if statusword & mask == value:
            return state
    # Remaining codes are reserved; a drive reporting one is treated as faulty.
    return DriveState.FAULT


def statusword_for(state: DriveState, following_target: bool = False) -> int:
    """The statusword a drive in ``state`` reports (remote bit set)."""
    word = STATUS_BITS[state] | STATUS_REMOTE
    if following_target and state is DriveState.OPERATION_ENABLED:
        word |= STATUS_FOLLOWING_TARGET
    return word


def next_drive_state(state: DriveState, controlword: int, previous_controlword: int) -> DriveState:
    """The CiA 402 state machine's transition for a controlword (the drive side).

    Fault reset acts on the rising edge of bit 7. Transitions the standard does not allow
    from ``state`` leave it unchanged.
    """
    if state in (DriveState.FAULT, DriveState.FAULT_REACTION_ACTIVE):
        rising_reset = controlword & 0x80 and not previous_controlword & 0x80
        if state is DriveState.FAULT and rising_reset:
            return DriveState.SWITCH_ON_DISABLED
        return state
    if state is DriveState.NOT_READY_TO_SWITCH_ON:
        return DriveState.SWITCH_ON_DISABLED
    if controlword & 0x82 == 0x00:  # disable voltage
        return DriveState.SWITCH_ON_DISABLED
    if controlword & 0x86 == 0x02:  # quick stop
        if state in (DriveState.OPERATION_ENABLED, DriveState.QUICK_STOP_ACTIVE):
            return DriveState.QUICK_STOP_ACTIVE  # (held: no transition out of quick stop)
        return DriveState.SWITCH_ON_DISABLED
    if controlword & 0x87 == 0x06:  # shutdown
        if state in (DriveState.SWITCH_ON_DISABLED, DriveState.SWITCHED_ON,
                     DriveState.OPERATION_ENABLED, DriveState.READY_TO_SWITCH_ON):
            return DriveState.READY_TO_SWITCH_ON
        return state
    if controlword & 0x8F == 0x07:  # switch on / disable operation
        if state in (DriveState.READY_TO_SWITCH_ON, DriveState.OPERATION_ENABLED,
                     DriveState.SWITCHED_ON):
            return DriveState.SWITCHED_ON
        return state
    if controlword & 0x8F == 0x0F:  # enable operation
        if state in (DriveState.SWITCHED_ON, DriveState.QUICK_STOP_ACTIVE,
                     DriveState.OPERATION_ENABLED):
            return DriveState.OPERATION_ENABLED
        if state is DriveState.READY_TO_SWITCH_ON:  # switch on + enable in one go
            return DriveState.OPERATION_ENABLED
        return state
    return state


def enable_command_for(state: DriveState) -> int | None:
    """The controlword that moves a drive one step towards Operation enabled (the master's
    side of the enable sequence); ``None`` once enabled."""
    return {
        DriveState.FAULT: CW_FAULT_RESET,
        DriveState.NOT_READY_TO_SWITCH_ON: CW_SHUTDOWN,
        DriveState.SWITCH_ON_DISABLED: CW_SHUTDOWN,
        DriveState.READY_TO_SWITCH_ON: CW_SWITCH_ON,
        DriveState.SWITCHED_ON: CW_ENABLE_OPERATION,
        DriveState.QUICK_STOP_ACTIVE: CW_DISABLE_VOLTAGE,
        DriveState.FAULT_REACTION_ACTIVE: CW_SHUTDOWN,
        DriveState.OPERATION_ENABLED: None,
    }[state]


# --- SDO (expedited transfers only: every object here fits in 4 bytes) ---------------

_EXPEDITED_DOWNLOAD = {1: 0x2F, 2: 0x2B, 3: 0x27, 4: 0x23}
_EXPEDITED_UPLOAD_RESPONSE = {1: 0x4F, 2: 0x4B, 3: 0x47, 4: 0x43}


@dataclass(frozen=True)
class SdoFrame:
    """A decoded SDO frame: command specifier byte, object index/subindex, 4 data bytes."""

    command: int
    index: int
    subindex: int
    data: bytes


def _sdo(command: int, index: int, subindex: int, data: bytes = b"") -> bytes:
    return struct.pack("<BHB", command, index, subindex) + data.ljust(4, b"\x00")


def decode_sdo(payload: bytes) -> SdoFrame:
    """Split an 8-byte SDO payload; ``ValueError`` on another length."""
    if len(payload) != 8:
        raise ValueError(f"SDO payload of {len(payload)} bytes, expected 8")
    command, index, subindex = struct.unpack_from("<BHB", payload)
    return SdoFrame(command, index, subindex, bytes(payload[4:]))


def sdo_download_request(variable: od.ODVariable, value: int) -> bytes:
    """Expedited download (write) of ``value`` to ``variable``."""
    raw = variable.encode_raw(int(value))
    return _sdo(_EXPEDITED_DOWNLOAD[len(raw)], variable.index, variable.subindex, raw)


def sdo_upload_request(variable: od.ODVariable) -> bytes:
    """Upload (read) request for ``variable``."""
    return _sdo(0x40, variable.index, variable.subindex)


def sdo_download_response(index: int, subindex: int) -> bytes:
    """The server's acknowledgement of a download."""
    return _sdo(0x60, index, subindex)


def sdo_upload_response(variable: od.ODVariable, value: int) -> bytes:
    """The server's expedited upload response carrying ``value``."""
    raw = variable.encode_raw(int(value))
    return _sdo(_EXPEDITED_UPLOAD_RESPONSE[len(raw)], variable.index, variable.subindex, raw)


def sdo_abort(index: int, subindex: int, code: int) -> bytes:
    """An SDO abort transfer frame with abort ``code``."""
    return _sdo(0x80, index, subindex, struct.pack("<I", code))


def sdo_download_size(command: int) -> int | None:
    """Data size of an expedited download request, ``None`` if ``command`` is not one."""
    for size, code in _EXPEDITED_DOWNLOAD.items():
        if command == code:
            return size
    return None


def emcy_frame(error_code: int, error_register: int = 0x01) -> bytes:
    """An EMCY payload: error code (u16), error register (u8), 5 manufacturer bytes."""
    return struct.pack("<HB5s", error_code, error_register, b"")


def decode_emcy(payload: bytes) -> tuple[int, int]:
    """(error code, error register) of an EMCY payload."""
    if len(payload) < 3:
        raise ValueError(f"EMCY payload of {len(payload)} bytes, expected 8")
    code, register = struct.unpack_from("<HB", payload)
    return code, register
