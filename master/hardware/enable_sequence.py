"""The CiA 402 enable sequence of both drives, one step per SYNC, every transition checked;
a drive in Fault is reset once. An EMCY, a new fault or an unexpected transition stops it:
both drives get disable voltage and :class:`HardwareError` names the states and EMCY codes.
"""

from __future__ import annotations

from collections.abc import Callable

from haptic.master.hardware import cia402
from haptic.master.hardware.cia402 import DriveState
from haptic.master.hardware.interface import AXES, HardwareError
from haptic.master.hardware.pdo_cycle import PdoCycle

#: The state each enable-sequence controlword leads to from each state.
EXPECTED_AFTER = {
    (DriveState.SWITCH_ON_DISABLED, cia402.CW_SHUTDOWN): DriveState.READY_TO_SWITCH_ON,
    (DriveState.NOT_READY_TO_SWITCH_ON, cia402.CW_SHUTDOWN): DriveState.READY_TO_SWITCH_ON,
    (DriveState.READY_TO_SWITCH_ON, cia402.CW_SWITCH_ON): DriveState.SWITCHED_ON,
    (DriveState.SWITCHED_ON, cia402.CW_ENABLE_OPERATION): DriveState.OPERATION_ENABLED,
    (DriveState.FAULT, cia402.CW_FAULT_RESET): DriveState.SWITCH_ON_DISABLED,
    (DriveState.QUICK_STOP_ACTIVE, cia402.CW_DISABLE_VOLTAGE): DriveState.SWITCH_ON_DISABLED,
    (DriveState.FAULT_REACTION_ACTIVE, cia402.CW_SHUTDOWN): DriveState.FAULT,
}


def enable_drives(pdos: PdoCycle, read: Callable[[], object],
                  emcy_log: list[tuple[str, int]], timeout_cycles: int) -> None:
    """Run the sequence from the drives' present states, the targets kept at the actual
    positions until both are enabled: each step sends the RPDOs (``pdos``) and takes one
    cycle (``read``, which updates ``pdos``' drive states and appends to ``emcy_log``);
    at most ``timeout_cycles`` steps."""
    emcy_start = len(emcy_log)
    resets = [0, 0]
    states = pdos.drive_states
    for _ in range(timeout_cycles):
        before = list(states)
        commands = [_enable_step(pdos, axis, resets) for axis in range(2)]
        if all(command is None for command in commands):
            return
        for axis, command in enumerate(commands):
            pdos.send_rpdo(axis, pdos.last_controlword[axis] if command is None else command)
        read()
        new_emcy = emcy_log[emcy_start:]
        for axis in range(2):
            _check_transition(pdos, axis, before[axis], commands[axis], new_emcy)
        if new_emcy:
            abort_activation(pdos, "EMCY during the enable sequence", new_emcy)
        if any(state is DriveState.FAULT and resets[axis] > 1
               for axis, state in enumerate(states)):
            abort_activation(pdos, "a drive faulted again after its fault reset", new_emcy)
        if any(state is not DriveState.OPERATION_ENABLED for state in states):
            pdos.hold_targets()
    abort_activation(pdos, "drives did not reach operation enabled", emcy_log[emcy_start:])


def _check_transition(pdos: PdoCycle, axis: int, before: DriveState, command: int | None,
                      emcys: list[tuple[str, int]]) -> None:
    """Stop the sequence when ``axis``'s drive went elsewhere than ``command`` leads."""
    after = pdos.drive_states[axis]
    if command is None or after is before:
        return
    expected = EXPECTED_AFTER.get((before, command))
    if after is not expected and not (
            command == cia402.CW_DISABLE_VOLTAGE and before is DriveState.FAULT):
        abort_activation(pdos, f"{AXES[axis]} drive went from {before.value} to "
                         f"{after.value} on controlword 0x{command:04X}", emcys)


def _enable_step(pdos: PdoCycle, axis: int, resets: list[int]) -> int | None:
    """The controlword of ``axis``'s next step (None: enabled), counting its fault resets."""
    command = cia402.enable_command_for(pdos.drive_states[axis])
    if command == cia402.CW_FAULT_RESET:
        if pdos.last_controlword[axis] & 0x80:
            return cia402.CW_DISABLE_VOLTAGE  # fault reset acts on a rising edge of bit 7
        resets[axis] += 1
    return command


def abort_activation(pdos: PdoCycle, reason: str, emcys: list[tuple[str, int]]) -> None:
    """Disable voltage on both drives, then :class:`HardwareError` with ``reason``, the
    drives' states and the EMCY codes."""
    pdos.send_both(cia402.CW_DISABLE_VOLTAGE)
    states = ", ".join(f"{a}: {s.value}" for a, s in zip(AXES, pdos.drive_states, strict=True))
    codes = ", ".join(f"{axis} 0x{code:04X}" for axis, code in emcys) or "none"
    raise HardwareError(f"activation stopped: {reason} ({states}; EMCY {codes})")
