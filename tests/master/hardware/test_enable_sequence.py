"""The CAN driver's enable sequence (master/hardware/enable_sequence.py) on its own: two drives
stepped by CiA 402's state machine (``cia402.next_drive_state``) at each cycle, with the
misbehaviour a test names (a drive that stays faulted, goes elsewhere, or sends an EMCY), over
python-can's virtual bus. The sequence enables both, holds the targets at the positions until
then, resets a fault once, and stops with both drives disabled on anything unexpected."""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterator

import can
import pytest

from haptic.master.hardware import cia402
from haptic.master.hardware.cia402 import DriveState
from haptic.master.hardware.enable_sequence import enable_drives
from haptic.master.hardware.frame_sender import FrameSender
from haptic.master.hardware.interface import HardwareError
from haptic.master.hardware.pdo_cycle import PdoCycle

_CHANNELS = itertools.count()
#: A drive's state after a cycle, from (axis, state before, controlword, CiA 402's state).
Deviation = Callable[[int, DriveState, int, DriveState], DriveState]


class SteppedDrives:
    """The cycle's ``read``: each drive takes its last controlword by CiA 402's state machine,
    then ``deviation`` (the test's misbehaviour) may change the result; the positions move by
    one count a cycle; ``emcy_at``: the cycle (1-based) at which the x drive sends an EMCY."""

    def __init__(self, pdos: PdoCycle, emcy_log: list[tuple[str, int]],
                 deviation: Deviation | None = None, emcy_at: int | None = None) -> None:
        self.pdos, self.emcy_log = pdos, emcy_log
        self.deviation, self.emcy_at = deviation, emcy_at
        self.previous = [cia402.CW_DISABLE_VOLTAGE] * 2
        self.cycles = 0
        self.positions: list[list[int]] = []

    def __call__(self) -> None:
        self.cycles += 1
        pdos = self.pdos
        for axis in range(2):
            before, word = pdos.drive_states[axis], pdos.last_controlword[axis]
            after = cia402.next_drive_state(before, word, self.previous[axis])
            if self.deviation is not None:
                after = self.deviation(axis, before, word, after)
            pdos.drive_states[axis] = after
            self.previous[axis] = word
        pdos.position_counts += (1, -1)
        self.positions.append(pdos.position_counts.tolist())
        if self.cycles == self.emcy_at:
            self.emcy_log.append(("x", 0x8611))


@pytest.fixture
def pdos() -> Iterator[PdoCycle]:
    """The drives' cycle on a virtual bus of its own, both drives switch-on disabled at
    positions (100, -200) counts."""
    bus = can.Bus(interface="virtual", channel=f"enable-sequence-{next(_CHANNELS)}")
    frames = FrameSender(set())
    frames.bus = bus
    cycle = PdoCycle(frames, (3, 4), 0x190, False)
    cycle.drive_states = [DriveState.SWITCH_ON_DISABLED] * 2
    cycle.position_counts[:] = (100, -200)
    yield cycle
    bus.shutdown()


def test_both_drives_are_enabled_the_targets_held_at_the_positions_until_then(
        pdos: PdoCycle) -> None:
    drives = SteppedDrives(pdos, [])
    enable_drives(pdos, drives, [], 10)
    assert pdos.drive_states == [DriveState.OPERATION_ENABLED] * 2
    assert drives.cycles == 3  # shutdown, switch on, enable operation
    assert pdos.last_controlword == [cia402.CW_ENABLE_OPERATION] * 2
    # held after each cycle but the one that enabled both
    assert pdos.target_counts.tolist() == drives.positions[-2]


def test_a_drive_enabled_already_is_left_alone(pdos: PdoCycle) -> None:
    pdos.drive_states = [DriveState.OPERATION_ENABLED] * 2
    drives = SteppedDrives(pdos, [])
    enable_drives(pdos, drives, [], 10)
    assert drives.cycles == 0 and pdos.last_controlword == [cia402.CW_DISABLE_VOLTAGE] * 2


def test_a_faulted_drive_is_reset_once_and_enabled(pdos: PdoCycle) -> None:
    pdos.drive_states = [DriveState.FAULT, DriveState.FAULT]
    drives = SteppedDrives(pdos, [])
    enable_drives(pdos, drives, [], 10)
    assert pdos.drive_states == [DriveState.OPERATION_ENABLED] * 2
    assert drives.cycles == 4  # fault reset, shutdown, switch on, enable operation


def test_a_drive_that_stays_faulted_stops_the_sequence_after_its_second_reset(
        pdos: PdoCycle) -> None:
    pdos.drive_states = [DriveState.SWITCH_ON_DISABLED, DriveState.FAULT]

    def stays_faulted(axis: int, before: DriveState, word: int,
                      after: DriveState) -> DriveState:
        return DriveState.FAULT if axis == 1 and before is DriveState.FAULT else after

    drives = SteppedDrives(pdos, [], stays_faulted)
    with pytest.raises(HardwareError, match="a drive faulted again after its fault reset"):
        enable_drives(pdos, drives, [], 20)
    assert drives.cycles == 3  # reset, its bit 7 cleared, reset again
    assert pdos.last_controlword == [cia402.CW_DISABLE_VOLTAGE] * 2


def test_a_drive_going_elsewhere_stops_the_sequence(pdos: PdoCycle) -> None:
    def faults_on_switch_on(axis: int, before: DriveState, word: int,
                            after: DriveState) -> DriveState:
        return DriveState.FAULT if axis == 0 and word == cia402.CW_SWITCH_ON else after

    drives = SteppedDrives(pdos, [], faults_on_switch_on)
    with pytest.raises(HardwareError) as stopped:
        enable_drives(pdos, drives, [], 10)
    assert str(stopped.value) == (
        "activation stopped: x drive went from ready to switch on to fault on controlword "
        "0x0007 (x: fault, y: switched on; EMCY none)")
    assert pdos.last_controlword == [cia402.CW_DISABLE_VOLTAGE] * 2


def test_a_quick_stopped_drive_faulting_on_disable_voltage_stops_the_sequence(
        pdos: PdoCycle) -> None:
    pdos.drive_states = [DriveState.QUICK_STOP_ACTIVE, DriveState.SWITCH_ON_DISABLED]

    def faults(axis: int, before: DriveState, word: int, after: DriveState) -> DriveState:
        return DriveState.FAULT if before is DriveState.QUICK_STOP_ACTIVE else after

    with pytest.raises(HardwareError, match="x drive went from quick stop active to fault on "
                       "controlword 0x0000"):
        enable_drives(pdos, SteppedDrives(pdos, [], faults), [], 10)


def test_a_fault_that_clears_while_its_reset_bit_is_cleared_is_no_error(
        pdos: PdoCycle) -> None:
    pdos.drive_states = [DriveState.FAULT, DriveState.SWITCH_ON_DISABLED]
    resets = []

    def clears_late(axis: int, before: DriveState, word: int, after: DriveState) -> DriveState:
        if axis == 0 and word == cia402.CW_FAULT_RESET:
            resets.append(word)
            return DriveState.FAULT  # the reset is not taken at once
        if axis == 0 and before is DriveState.FAULT:
            return DriveState.SWITCH_ON_DISABLED  # it clears on the drive's own time
        return after

    drives = SteppedDrives(pdos, [], clears_late)
    enable_drives(pdos, drives, [], 10)
    assert pdos.drive_states == [DriveState.OPERATION_ENABLED] * 2
    assert resets == [cia402.CW_FAULT_RESET]


def test_an_emcy_stops_the_sequence_and_names_its_code(pdos: PdoCycle) -> None:
    emcy_log = [("y", 0x8130)]  # before the sequence: not its own
    drives = SteppedDrives(pdos, emcy_log, emcy_at=2)
    with pytest.raises(HardwareError) as stopped:
        enable_drives(pdos, drives, emcy_log, 10)
    assert str(stopped.value) == (
        "activation stopped: EMCY during the enable sequence (x: switched on, y: switched on; "
        "EMCY x 0x8611)")
    assert drives.cycles == 2


def test_drives_that_never_get_there_stop_the_sequence_at_its_timeout(
        pdos: PdoCycle) -> None:
    def stuck(axis: int, before: DriveState, word: int, after: DriveState) -> DriveState:
        return before

    drives = SteppedDrives(pdos, [], stuck)
    with pytest.raises(HardwareError, match="drives did not reach operation enabled "
                       r"\(x: switch on disabled, y: switch on disabled; EMCY none\)"):
        enable_drives(pdos, drives, [], 7)
    assert drives.cycles == 7


def test_a_fault_is_reset_at_once_after_an_enable_operation(pdos: PdoCycle) -> None:
    """Bit 7 clear in the last controlword (enable operation, 0x000F, of a run before): the
    reset's rising edge needs no disable voltage first."""
    pdos.drive_states = [DriveState.FAULT, DriveState.OPERATION_ENABLED]
    pdos.last_controlword = [cia402.CW_ENABLE_OPERATION] * 2
    words = []

    def records(axis: int, before: DriveState, word: int, after: DriveState) -> DriveState:
        if axis == 0:
            words.append(word)
        return after

    enable_drives(pdos, SteppedDrives(pdos, [], records), [], 10)
    assert words == [cia402.CW_FAULT_RESET, cia402.CW_SHUTDOWN, cia402.CW_SWITCH_ON,
                     cia402.CW_ENABLE_OPERATION]
