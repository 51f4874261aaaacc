"""The CAN driver's drive events (master/hardware/drive_events.py) on their own: the
statusword's warning bits as events once per change, each EMCY as a fault with its CiA 301/402
meaning (an error reset none, a malformed one a fault too), and the watch on each drive taking
the master's quick stop within its SYNCs."""

from __future__ import annotations

import struct

import pytest
from canopen.emcy import EmcyConsumer

from haptic.master.hardware import cia402
from haptic.master.hardware.cia402 import DriveState
from haptic.master.hardware.drive_events import (
    WARNING_BITS,
    WARNING_IDLE,
    QuickStopWatch,
    emcy_fault,
    warning_events,
)

# CiA 402 statusword bits: 7 warning, 9 remote, 11 internal limit, 12 follows the target (in
# cyclic synchronous position mode), 13 following error.
WARNING = 0x0080
REMOTE = 0x0200
INTERNAL_LIMIT = 0x0800
FOLLOWS = 0x1000
FOLLOWING_ERROR = 0x2000


def test_the_watched_bits_and_their_healthy_state() -> None:
    assert WARNING_BITS == WARNING | REMOTE | INTERNAL_LIMIT | FOLLOWS | FOLLOWING_ERROR
    assert WARNING_IDLE == REMOTE | FOLLOWS
    assert (cia402.STATUS_REMOTE, cia402.STATUS_FOLLOWING_TARGET) == (REMOTE, FOLLOWS)


@pytest.mark.parametrize(("bit", "text"), [
    (WARNING, "warning (bit 7)"), (REMOTE, "not remote (bit 9 clear)"),
    (INTERNAL_LIMIT, "internal limit active (bit 11)"),
    (FOLLOWS, "target ignored (bit 12 clear)"), (FOLLOWING_ERROR, "following error (bit 13)")])
def test_each_watched_bit_is_an_event_when_it_changes(bit: int, text: str) -> None:
    events: list[str] = []
    warning_events(1, 0x0037, 0x0037 | bit, events)
    assert events == [f"y drive statusword: {text} on"]
    warning_events(0, 0x0037 | bit, 0x0037, events)
    assert events[1:] == [f"x drive statusword: {text} off"]


def test_unchanged_and_unwatched_bits_are_no_event() -> None:
    events: list[str] = []
    warning_events(0, 0x3A80 | 0x0027, 0x3A80 | 0x0027, events)
    warning_events(0, 0x0027, 0x0027 ^ 0x0001 ^ 0x0400 ^ 0x4000 ^ 0x8000, events)
    assert events == []


def test_several_bits_changing_at_once_are_an_event_each_in_bit_order() -> None:
    events: list[str] = []
    warning_events(0, REMOTE | FOLLOWS, WARNING | FOLLOWING_ERROR, events)
    assert events == ["x drive statusword: warning (bit 7) on",
                      "x drive statusword: not remote (bit 9 clear) off",
                      "x drive statusword: target ignored (bit 12 clear) off",
                      "x drive statusword: following error (bit 13) on"]


def emcy(code: int, register: int) -> bytes:
    return struct.pack("<HB5x", code, register)


@pytest.mark.parametrize(("code", "meaning"), [
    (0x8130, "heartbeat or life guard lost"), (0x8210, "PDO shorter than mapped"),
    (0x8220, "PDO longer than mapped"),
    (0x8240, "unexpected SYNC data length: the drive's 0x1019 does not match the SYNC "
             "counter"),
    (0x8250, "RPDO deadline missed"), (0x8611, "following error")])
def test_an_emcy_of_a_known_code_is_a_fault_with_its_meaning(code: int, meaning: str) -> None:
    faults: list[str] = []
    assert emcy_fault(1, emcy(code, 0x11), faults) == code
    assert faults == [f"y drive EMCY error code 0x{code:04X} (register 0x11; {meaning})"]


def test_an_emcy_of_another_code_is_a_fault_without_a_meaning() -> None:
    faults: list[str] = []
    assert emcy_fault(0, emcy(0x5530, 0x01), faults) == 0x5530
    assert faults == ["x drive EMCY error code 0x5530 (register 0x01)"]


@pytest.mark.parametrize("code", [0x0000, 0x0001, 0x0010, 0x00FF])
def test_an_error_reset_of_any_code_of_its_group_is_no_fault(code: int) -> None:
    """CiA 301's group 00xxh is "error reset or no error": a drive clearing its errors, with
    a vendor's low byte or without."""
    faults: list[str] = []
    assert emcy_fault(0, emcy(code, 0x00), faults) == 0
    assert faults == []


@pytest.mark.parametrize("code", [0x0000, 0x0001, 0x00FF, 0x0100, 0x1000, 0x5530, 0x8130,
                                  0xFF00, 0xFFFF])
def test_an_emcy_is_a_fault_exactly_when_the_canopen_library_keeps_it_active(code: int) -> None:
    """The python-canopen library's EMCY consumer (not ours) clears its active errors on an
    error reset and keeps any other code active: ours faults on the same codes."""
    consumer = EmcyConsumer()
    consumer.on_emcy(cia402.EMCY_BASE + 1, emcy(0x8611, 0x81), 0.0)
    consumer.on_emcy(cia402.EMCY_BASE + 1, emcy(code, 0x01), 0.0)
    library_active = [error.code for error in consumer.active]
    faults: list[str] = []
    ours = emcy_fault(0, emcy(code, 0x01), faults)
    if library_active:
        assert library_active == [0x8611, code]
        assert ours == code and len(faults) == 1
    else:
        assert ours == 0 and faults == []


def test_a_malformed_emcy_is_a_fault() -> None:
    faults: list[str] = []
    assert emcy_fault(1, b"\x30\x81", faults) == -1
    assert faults == ["y drive EMCY malformed: EMCY payload of 2 bytes, expected 8"]


def watch_after(cycles: int) -> QuickStopWatch:
    watch = QuickStopWatch()
    watch.cycles = cycles
    return watch


@pytest.mark.parametrize("state", [DriveState.QUICK_STOP_ACTIVE,
                                   DriveState.SWITCH_ON_DISABLED])
def test_a_drive_taking_the_quick_stop_is_an_event_once(state: DriveState) -> None:
    watch = QuickStopWatch()
    events: list[str] = []
    faults: list[str] = []
    drive_fault = [False, False]
    for _ in range(3):
        watch.check(1, state, 5, events, faults, drive_fault)
    assert events == [f"y drive took the quick stop ({state.value})"]
    assert watch.taken == [False, True]
    watch.cycles = 9  # taken: never late
    watch.check(1, DriveState.OPERATION_ENABLED, 5, events, faults, drive_fault)
    assert faults == [] and drive_fault == [False, False]


def test_a_drive_later_than_its_syncs_is_a_fault_once() -> None:
    events: list[str] = []
    faults: list[str] = []
    drive_fault = [False, False]
    watch = watch_after(5)
    watch.check(0, DriveState.OPERATION_ENABLED, 5, events, faults, drive_fault)
    assert faults == [] and drive_fault == [False, False] and watch.reported == [False, False]
    watch.cycles = 6
    for _ in range(2):
        watch.check(0, DriveState.OPERATION_ENABLED, 5, events, faults, drive_fault)
    assert faults == ["x drive did not take the quick stop (operation enabled after 6 SYNCs)"]
    assert drive_fault == [True, False]
    assert watch.reported == [True, False] and watch.taken == [False, False]
    assert events == []
    watch.check(1, DriveState.SWITCHED_ON, 5, events, faults, drive_fault)
    assert faults[1:] == ["y drive did not take the quick stop (switched on after 6 SYNCs)"]


def test_a_restart_watches_a_new_stop() -> None:
    events: list[str] = []
    faults: list[str] = []
    drive_fault = [False, False]
    watch = watch_after(9)
    watch.check(0, DriveState.QUICK_STOP_ACTIVE, 5, events, faults, drive_fault)
    watch.check(1, DriveState.OPERATION_ENABLED, 5, events, faults, drive_fault)
    watch.restart()
    assert (watch.cycles, watch.taken, watch.reported) == (0, [False, False], [False, False])
    fresh = QuickStopWatch()
    assert (fresh.cycles, fresh.taken, fresh.reported) == (0, [False, False], [False, False])
