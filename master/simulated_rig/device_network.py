"""The simulated drives as CANopen network nodes (CiA 301): NMT commands (start, stop,
pre-operational, the resets), the heartbeat each drive produces and the one it consumes,
and node guarding with life guarding. A drive that loses its master (heartbeat consumer or
life guarding timed out) is reported to the rig, which sends the EMCY and applies the drive's
reaction. All of it runs under the rig's lock.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from haptic.master.hardware import cia402
from haptic.master.hardware.cia402 import HEARTBEAT_BASE, DriveState
from haptic.master.hardware.drive_device import EMCY_HEARTBEAT, DriveObjects, DriveRuntime

NMT_PRE_OPERATIONAL_STATE = "pre-operational"
NMT_OPERATIONAL_STATE = "operational"
NMT_STOPPED_STATE = "stopped"


class DeviceNetwork:
    """The drives' NMT state machine and error control.

    Parameters
    ----------
    drives, devices:
        Each drive's runtime state and its object dictionary, x then y.
    send:
        Sends one frame (id, data) on the rig's bus.
    connection_lost:
        Called with the axis and the EMCY code when a drive loses its master.
    sync_counter_seen:
        The rig's per-drive last SYNC counter, cleared when a drive is reset.
    """

    def __init__(self, drives: list[DriveRuntime], devices: list[DriveObjects],
                 send: Callable[[int, bytes], None],
                 connection_lost: Callable[[int, int], None],
                 sync_counter_seen: list[int]) -> None:
        self.drives = drives
        self.devices = devices
        self.send = send
        self.connection_lost = connection_lost
        self.sync_counter_seen = sync_counter_seen
        #: When each drive last heard the heartbeat it consumes (monotonic s; None: not yet).
        self.heard_at: list[float | None] = [None, None]
        #: When each drive last got a node guarding request (monotonic s; None: not yet) and
        #: the toggle bit of its next answer.
        self.guarded_at: list[float | None] = [None, None]
        self.guard_toggle = [0, 0]
        #: When each drive's next heartbeat is due (monotonic s).
        self.heartbeat_due = [0.0, 0.0]
        #: When the serving loop next looks at the timers (0: at once), s.
        self.timers_due_s = 0.0

    def boot_up(self) -> None:
        """Each drive's boot-up message."""
        for drive in self.drives:
            self.send(HEARTBEAT_BASE + drive.node_id, b"\x00")

    def heard(self, axis: int) -> None:
        """``axis``'s drive heard the heartbeat it consumes (changes no input)."""
        if self.heard_at[axis] is None:
            self.timers_due_s = 0.0  # its consumer starts now
        self.heard_at[axis] = time.monotonic()

    def answer_guarding(self, axis: int) -> None:
        """A node guarding request to ``axis``'s drive: the answer (toggle bit 7 and the NMT
        state) and, with a guard time and life time factor set, life guarding from now on
        (changes no input)."""
        drive, device = self.drives[axis], self.devices[axis]
        toggle = self.guard_toggle[axis]
        self.guard_toggle[axis] ^= 0x80
        self.send(HEARTBEAT_BASE + drive.node_id, bytes([toggle | device.heartbeat_payload()[0]]))
        if self.guarded_at[axis] is None:
            self.timers_due_s = 0.0  # its life guarding starts now
        self.guarded_at[axis] = time.monotonic()

    def poll(self, now_s: float) -> float:
        """Send the drives' heartbeats that are due and report a drive whose heartbeat
        consumer timed out; returns the time to the next heartbeat or check, s."""
        next_s = 1.0
        for axis, (drive, device) in enumerate(zip(self.drives, self.devices, strict=True)):
            period_s = device.heartbeat_producer_ms * 1e-3
            if period_s > 0.0:
                if now_s >= self.heartbeat_due[axis]:
                    self.send(HEARTBEAT_BASE + drive.node_id, device.heartbeat_payload())
                    self.heartbeat_due[axis] = max(self.heartbeat_due[axis] + period_s, now_s)
                next_s = min(next_s, self.heartbeat_due[axis] - now_s)
            heard = self.heard_at[axis]
            timeout_s = device.heartbeat_consumer_ms * 1e-3
            if heard is not None and timeout_s > 0.0:
                if now_s - heard > timeout_s:
                    self.heard_at[axis] = None  # one trip per loss
                    self.connection_lost(axis, EMCY_HEARTBEAT)
                else:
                    next_s = min(next_s, heard + timeout_s - now_s)
            next_s = min(next_s, self._life_guard(axis, device, now_s))
        return next_s

    def _life_guard(self, axis: int, device: DriveObjects, now_s: float) -> float:
        """Life guarding: once guarded, a drive whose next request is later than guard time x
        life time factor has lost its master; returns the time to look again, s."""
        guarded = self.guarded_at[axis]
        lifetime_s = device.guard_time_ms * device.life_time_factor * 1e-3
        if guarded is None or lifetime_s <= 0.0:
            return 1.0
        if now_s - guarded > lifetime_s:
            self.guarded_at[axis] = None  # one trip per loss
            self.connection_lost(axis, EMCY_HEARTBEAT)
            return 1.0
        return guarded + lifetime_s - now_s

    def on_nmt(self, command: int, node: int) -> None:
        """An NMT command to ``node`` (0: all)."""
        for axis, drive in enumerate(self.drives):
            if node not in (0, drive.node_id):
                continue
            if command == cia402.NMT_START:
                drive.nmt_state = NMT_OPERATIONAL_STATE
            elif command == cia402.NMT_STOP:
                drive.nmt_state = NMT_STOPPED_STATE
            elif command == cia402.NMT_PRE_OPERATIONAL:
                drive.nmt_state = NMT_PRE_OPERATIONAL_STATE
            elif command in (cia402.NMT_RESET_NODE, cia402.NMT_RESET_COMMUNICATION):
                self._reset(axis, node_too=command == cia402.NMT_RESET_NODE)

    def _reset(self, axis: int, node_too: bool) -> None:
        """Back to the power-on values: the communication objects (0x1000-0x1FFF), and on a
        node reset the application's too; then pre-operational and a boot-up."""
        drive, device = self.drives[axis], self.devices[axis]
        store = device.node.data_store
        for index in list(store):
            if node_too or index < 0x2000:
                del store[index]
        device.refresh()
        if node_too:
            drive.state, drive.mode, drive.error_code = DriveState.SWITCH_ON_DISABLED, 0, 0
        drive.nmt_state = NMT_PRE_OPERATIONAL_STATE
        self.heard_at[axis] = None
        self.guarded_at[axis] = None
        self.guard_toggle[axis] = 0
        self.sync_counter_seen[axis] = 0
        self.send(HEARTBEAT_BASE + drive.node_id, b"\x00")
