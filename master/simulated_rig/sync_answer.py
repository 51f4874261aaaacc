"""What the simulated devices do at one SYNC, as pure steps over copies of the drives'
runtime state (the rig commits or takes back the whole answer): the SYNC checked against each
drive's counter (0x1019), each drive applying what it latched (CiA 402 transitions, target,
RPDO deadline), then after the model's step its following error check and its TPDOs.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from haptic.master.hardware import cia402
from haptic.master.hardware.cia402 import DriveState
from haptic.master.hardware.drive_device import (
    EMCY_FOLLOWING_ERROR,
    EMCY_RPDO_TIMEOUT,
    EMCY_SYNC_LENGTH,
    SW_FOLLOWING_ERROR,
    SW_WARNING,
    DriveObjects,
    DriveRuntime,
)
from haptic.master.hardware.unix_can import BRS_FLAG, FD_FLAG, RawFrame
from haptic.master.settings import CanSettings
from haptic.master.simulated_rig.rig_block import RigSample, RigState


@dataclass
class SyncAnswer:
    """What the devices do at one SYNC: the drives after it, the sample, the frames to send
    (raw: id, wire flags, data) and the sensor's counters. The model has already stepped;
    ``undo`` holds the rig state's arrays (and ``rng_undo`` the noise generator's state) from
    before the step, so a prepared answer can be taken back (both empty for an answer
    committed at once)."""

    drives: list[DriveRuntime]
    sample: RigSample
    frames: list[RawFrame]
    sensor_counter: int
    drop_sensor: int
    sensor_status_cycles: int
    undo: list[tuple[Any, str, np.ndarray]] = field(default_factory=list)
    rng_undo: dict[str, Any] | None = None


def state_arrays(state: RigState) -> list[tuple[Any, str]]:
    """(holder, attribute) of every array of the rig state and its operator state."""
    return [(holder, item.name) for holder in (state, state.operator)
            for item in fields(holder) if isinstance(getattr(holder, item.name), np.ndarray)]


def check_sync(devices: list[DriveObjects], data: bytes, counter_seen: list[int],
               counter_jumps: list[int], send: Callable[[int, bytes], None]
               ) -> frozenset[int]:
    """Each drive checks a SYNC against its 0x1019 (CiA 301): without a counter it must carry
    no data; with one, one byte. A drive refuses a SYNC of another length (EMCY 0x8240, sent
    at once; it does not act on that SYNC, as CANopen stacks do); a counter that is not
    the last one plus 1 (wrapping to 1 after the overflow value) means SYNCs lost on the bus
    (counted in ``counter_jumps``). Returns the axes that refused it."""
    refused = set()
    for axis, device in enumerate(devices):
        overflow = device.sync_counter_overflow
        if len(data) != (1 if overflow else 0):
            refused.add(axis)
            send(cia402.EMCY_BASE + device.node_id, cia402.emcy_frame(EMCY_SYNC_LENGTH))
            continue
        if overflow:
            last = counter_seen[axis]
            if last and data[0] != last % overflow + 1:
                counter_jumps[axis] += 1
            counter_seen[axis] = data[0]
    return frozenset(refused)


def apply_latched(drives: list[DriveRuntime], devices: list[DriveObjects],
                  refused: frozenset[int], settings: CanSettings,
                  frames: list[tuple[int, bytes]]) -> np.ndarray:
    """Each drive applies the controlword and target it latched (a pending fault first, with
    its EMCY; CiA 402 transitions, quick stop holding the position) and checks its RPDO
    deadline (0x1400:05, in SYNC time); returns the targets the model follows (m, NaN for a
    drive that does not move it)."""
    targets = np.full((1, 2), np.nan)
    for axis, (drive, device) in enumerate(zip(drives, devices, strict=True)):
        if device.sync_cob_id != cia402.SYNC_COB_ID or axis in refused:
            continue  # this drive listens for SYNC elsewhere, or refused this one
        received_rpdo = _apply_controlword(drive, device, frames)
        enabled = drive.state is DriveState.OPERATION_ENABLED and (
            drive.mode == cia402.MODE_CYCLIC_SYNC_POSITION)
        if drive.received_target is not None and enabled:
            drive.target_counts = drive.received_target
        drive.received_controlword = drive.received_target = None
        if enabled or drive.state is DriveState.QUICK_STOP_ACTIVE:
            targets[0, axis] = settings.metres_from_count(drive.target_counts)
        timer_s = device.rpdo_deadline_ms * 1e-3
        if enabled and timer_s > 0.0 and not received_rpdo:
            drive.syncs_without_rpdo += 1
            if drive.syncs_without_rpdo * device.interpolation_period_s > timer_s:
                drive.syncs_without_rpdo = 0
                frames.append((cia402.EMCY_BASE + drive.node_id,
                               cia402.emcy_frame(EMCY_RPDO_TIMEOUT)))
                drive.state, drive.error_code = DriveState.FAULT, EMCY_RPDO_TIMEOUT
                drive.target_counts = drive.position_counts
                targets[0, axis] = settings.metres_from_count(drive.position_counts)
        elif received_rpdo:
            drive.syncs_without_rpdo = 0
    return targets


def _apply_controlword(drive: DriveRuntime, device: DriveObjects,
                       frames: list[tuple[int, bytes]]) -> bool:
    """The drive's pending fault (with its EMCY), the end of a finished quick stop, and the
    CiA 402 transition of the controlword it latched; returns whether an RPDO came."""
    if drive.persistent_fault_code and drive.state is not DriveState.FAULT:
        drive.pending_fault_code = drive.persistent_fault_code
    if drive.pending_fault_code:
        drive.state, drive.error_code = DriveState.FAULT, drive.pending_fault_code
        frames.append((cia402.EMCY_BASE + drive.node_id,
                       cia402.emcy_frame(drive.pending_fault_code)))
        drive.pending_fault_code = 0
    if drive.state is DriveState.QUICK_STOP_ACTIVE and device.quick_stop_option <= 4:
        drive.state = DriveState.SWITCH_ON_DISABLED  # stopped: the power goes off
    received_rpdo = drive.received_controlword is not None or (
        drive.received_target is not None)
    if drive.received_controlword is not None:
        previous = drive.controlword
        drive.controlword = drive.received_controlword
        before = drive.state
        if drive.mode == cia402.MODE_CYCLIC_SYNC_POSITION:  # no mode: no power
            drive.state = cia402.next_drive_state(drive.state, drive.controlword, previous)
        if drive.state is DriveState.SWITCH_ON_DISABLED and before is not drive.state:
            drive.error_code, drive.status_extra = 0, 0
        if drive.state is DriveState.QUICK_STOP_ACTIVE and (
                before is not DriveState.QUICK_STOP_ACTIVE):
            drive.target_counts = drive.position_counts  # stop where it is
    return received_rpdo


def tpdo_frames(drive: DriveRuntime, device: DriveObjects,
                frames: list[tuple[int, bytes]]) -> None:
    """The drive's enabled TPDOs due at this SYNC, as mapped, into ``frames``: every n-th
    SYNC for transmission type n (1-240), on a change of the payload for the others (0
    acyclic synchronous, 254/255 event-driven)."""
    sent = []
    for number, tpdo in enumerate(device.tpdos):
        payload = device.encode_tpdo(drive, drive.position_counts, tpdo)
        kind = tpdo.transmission_type
        last = drive.last_tpdos[number] if number < len(drive.last_tpdos) else b""
        if 1 <= kind <= 240:
            due = drive.sync_count % kind == 0
        else:
            due = payload != last
        sent.append(payload if due else last)
        if due:
            frames.append((tpdo.cob_id, payload))
    drive.last_tpdos = tuple(sent)


def check_following_error(drive: DriveRuntime, device: DriveObjects,
                          frames: list[tuple[int, bytes]]) -> None:
    """Following error (0x6065 window, 0x6066 time out): statusword bit 7 (warning) while
    beyond the window, then bit 13, Fault and EMCY 0x8611 once it lasted the time out."""
    if drive.state is not DriveState.OPERATION_ENABLED:
        drive.following_error_syncs = 0
        drive.status_extra &= ~SW_WARNING
        return
    error = abs(drive.target_counts - drive.position_counts)
    if error <= device.following_error_window_counts:
        drive.following_error_syncs = 0
        drive.status_extra &= ~(SW_WARNING | SW_FOLLOWING_ERROR)
        return
    drive.following_error_syncs += 1
    drive.status_extra |= SW_WARNING
    if drive.following_error_syncs * device.interpolation_period_s > (
            device.following_error_timeout_s):
        drive.status_extra |= SW_FOLLOWING_ERROR
        drive.state, drive.error_code = DriveState.FAULT, EMCY_FOLLOWING_ERROR
        frames.append((cia402.EMCY_BASE + drive.node_id,
                       cia402.emcy_frame(EMCY_FOLLOWING_ERROR)))


def raw_frames(frames: list[tuple[int, bytes]], drives: list[DriveRuntime],
               fd: bool) -> list[RawFrame]:
    """``frames`` as raw frames: CAN FD with bit rate switch where the SYNC came as FD or the
    payload needs it, except the EMCYs (classical CAN always)."""
    emcy_ids = {cia402.EMCY_BASE + drive.node_id for drive in drives}
    fd_flags = FD_FLAG | BRS_FLAG
    return [(frame_id, fd_flags if (fd or len(data) > 8) and frame_id not in emcy_ids
             else 0, data) for frame_id, data in frames]
