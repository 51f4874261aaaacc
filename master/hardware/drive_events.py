"""What the drives report besides their positions, as the reading's faults and events: EMCYs
(CiA 301), the statusword's warning bits (events once per change) and, after the master's
quick stop, whether each drive took it in time.
"""

from __future__ import annotations

from haptic.master.hardware import cia402
from haptic.master.hardware.cia402 import DriveState
from haptic.master.hardware.interface import AXES

FOLLOWS_TARGET = cia402.STATUS_FOLLOWING_TARGET
#: Statusword bits watched as events, with their texts, and those of them that are set when
#: healthy (9 remote and 12 "follows the target": flipped before comparing).
WARNING_TEXT = {0x0080: "warning (bit 7)", cia402.STATUS_REMOTE: "not remote (bit 9 clear)",
                0x0800: "internal limit active (bit 11)",
                FOLLOWS_TARGET: "target ignored (bit 12 clear)",
                0x2000: "following error (bit 13)"}
WARNING_BITS = sum(WARNING_TEXT)  # one bit each
WARNING_IDLE = cia402.STATUS_REMOTE | FOLLOWS_TARGET
#: The highest EMCY error code of CiA 301's "error reset or no error" group (00xxh): such an
#: EMCY reports that the drive's errors were cleared, not a new one.
ERROR_RESET_MAX = 0x00FF
#: What the EMCY codes of CiA 301/402 the loop meets mean.
EMCY_TEXT = {
    0x8130: "heartbeat or life guard lost", 0x8210: "PDO shorter than mapped",
    0x8220: "PDO longer than mapped",
    0x8240: "unexpected SYNC data length: the drive's 0x1019 does not match the SYNC counter",
    0x8250: "RPDO deadline missed", 0x8611: "following error",
}


def warning_events(axis: int, before: int, after: int, events: list[str]) -> None:
    """Events for the warning bits that changed from ``before`` to ``after`` (each: the bits
    not in their healthy state)."""
    changed = after ^ before
    for bit, text in WARNING_TEXT.items():
        if changed & bit:
            state = "on" if after & bit else "off"
            events.append(f"{AXES[axis]} drive statusword: {text} {state}")


def emcy_fault(axis: int, data: bytes, faults: list[str]) -> int:
    """The fault of an EMCY of ``axis``'s drive, appended to ``faults``; returns its error
    code (0 for any code of the error-reset group 0x0000-0x00FF, which is no fault; -1:
    malformed, a fault)."""
    try:
        code, register = cia402.decode_emcy(data)
    except ValueError as error:
        faults.append(f"{AXES[axis]} drive EMCY malformed: {error}")
        return -1
    if code <= ERROR_RESET_MAX:
        return 0
    meaning = EMCY_TEXT.get(code)
    faults.append(f"{AXES[axis]} drive EMCY error code 0x{code:04X} "
                  f"(register 0x{register:02X}" + (f"; {meaning})" if meaning else ")"))
    return code


class QuickStopWatch:
    """Since the master's quick stop: the SYNCs sent, and per axis whether the drive took it
    and whether its lateness was reported."""

    def __init__(self) -> None:
        self.cycles = 0
        self.taken = [False, False]
        self.reported = [False, False]

    def restart(self) -> None:
        """Watch each drive take a new stop."""
        self.cycles = 0
        self.taken = [False, False]
        self.reported = [False, False]

    def check(self, axis: int, state: DriveState, timeout_cycles: int, events: list[str],
              faults: list[str], drive_fault: list[bool]) -> None:
        """The drive in Quick stop active or Switch on disabled (an event, once), or a fault
        once it is later than ``timeout_cycles`` SYNCs."""
        if state in (DriveState.QUICK_STOP_ACTIVE, DriveState.SWITCH_ON_DISABLED):
            if not self.taken[axis]:
                self.taken[axis] = True
                events.append(f"{AXES[axis]} drive took the quick stop ({state.value})")
        elif (self.cycles > timeout_cycles
              and not self.taken[axis] and not self.reported[axis]):
            self.reported[axis] = True
            drive_fault[axis] = True
            faults.append(f"{AXES[axis]} drive did not take the quick stop ({state.value} "
                          f"after {self.cycles} SYNCs)")
