"""The heartbeats between the master and its drives (CiA 301): the master's own (sent by the
cycle while active, by a background task while inactive), the node guarding requests of the
drives guarded instead, and the supervision of each drive's heartbeat (its last time, its
loss reported once, the NMT state it reports).
"""

from __future__ import annotations

import threading
import time
from typing import Any

import can
from can.broadcastmanager import ThreadBasedCyclicSendTask

from haptic.master.hardware.cia402 import HEARTBEAT_BASE
from haptic.master.hardware.frame_sender import FrameSender
from haptic.master.hardware.interface import AXES

#: The NMT states a drive's heartbeat may report other than operational (0x05).
NMT_STATE_NAMES = {0x00: "boot-up", 0x04: "stopped", 0x7F: "pre-operational"}
NMT_OPERATIONAL = 0x05


class Heartbeats:
    """The master's heartbeat and the drives' heartbeat supervision.

    Parameters
    ----------
    frames:
        The driver's sender.
    master_node_id:
        The master's node id: its heartbeat's COB-ID is 0x700 + it.
    period_s:
        The master's heartbeat period, s.
    timeout_s:
        A drive's heartbeat older than this is lost, s.
    """

    def __init__(self, frames: FrameSender, master_node_id: int, period_s: float,
                 timeout_s: float) -> None:
        self.frames = frames
        self.master_id = HEARTBEAT_BASE + master_node_id
        self.period_s = period_s
        self.timeout_s = timeout_s
        self.payload = bytes([NMT_OPERATIONAL])
        #: the master's next heartbeat (time.monotonic(), s)
        self.due_s = 0.0
        #: per axis: the drive's last heartbeat (time.monotonic(), s), its loss reported
        self.seen_s = [0.0, 0.0]
        self.lost = [False, False]
        #: per axis: whether the master watches the drive's heartbeat (or its answers to
        #: node guarding), whether it is guarded; the guarding requests sent with the
        #: master's heartbeat
        self.supervised = [True, True]
        self.guarded = [False, False]
        self.guard_requests: list[can.Message] = []
        #: the master's heartbeat while inactive (a python-can periodic task): configured and
        #: waiting (e.g. for the slave), the loop does not run, but the node is alive and the
        #: disabled drives must not fault; while active, the cycle sends it, so a stalled loop
        #: stops the drives by their heartbeat consumer
        self.idle_task: Any = None
        self.idle_guards: list[Any] = []
        #: errors that stopped the idle heartbeat task (bus gone), for diagnosis
        self.idle_errors: list[str] = []

    def expect(self, now: float) -> None:
        """Supervise the heartbeats from ``now`` (time.monotonic(), s): each drive's counts as
        heard then, none lost, and the master's own is due."""
        self.seen_s = [now, now]
        self.lost = [False, False]
        self.due_s = now

    def watch(self, axis: int, node: int, supervised: bool, guarded: bool) -> None:
        """How ``axis``'s drive (``node``) shows it is alive: its heartbeat watched or not
        (then its TPDO at each SYNC shows it), node guarding or not."""
        self.supervised[axis] = supervised
        self.guarded[axis] = guarded
        if guarded:
            self.guard_requests.append(can.Message(
                arbitration_id=HEARTBEAT_BASE + node, is_remote_frame=True, dlc=1,
                is_extended_id=False))

    def send_if_due(self, now: float) -> None:
        """Send the master's heartbeat, and the node guarding requests of the drives guarded
        instead of consuming it, when it is due (``now``: time.monotonic(), s)."""
        if now >= self.due_s:
            frames = self.frames
            frames.send(self.master_id, self.payload)
            if self.guard_requests:
                frames.put_all(self.guard_requests)
            self.due_s = max(self.due_s + self.period_s, now)

    def heard(self, axis: int, data: bytes, configured: bool, faults: list[str],
              drive_fault: list[bool]) -> None:
        """A heartbeat (or node guarding answer) of ``axis``'s drive; once ``configured``, a
        state other than operational is a fault."""
        self.seen_s[axis] = time.monotonic()
        self.lost[axis] = False
        state = data[0] if data else -1
        if self.guarded[axis] and state > 0:
            state &= 0x7F  # bit 7 of a node guarding answer: its toggle bit
        if configured and state != NMT_OPERATIONAL:
            faults.append(f"{AXES[axis]} drive heartbeat reports NMT state "
                          f"{NMT_STATE_NAMES.get(state, hex(state))}, not operational")
            drive_fault[axis] = True

    def check_lost(self, axis: int, node: int, now: float, faults: list[str],
                   drive_fault: list[bool]) -> None:
        """A fault, once per loss, when ``axis``'s watched drive has sent no heartbeat for
        longer than the timeout at ``now`` (time.monotonic(), s)."""
        silent_s = now - self.seen_s[axis]
        if silent_s > self.timeout_s and not self.lost[axis] and self.supervised[axis]:
            self.lost[axis] = True
            drive_fault[axis] = True
            faults.append(f"no heartbeat from the {AXES[axis]} drive (node {node}) for "
                          f"{silent_s:.3f} s (timeout {self.timeout_s:g} s)")

    def start_idle(self) -> None:
        """The master's heartbeat (and the guarding requests) from a background task, while
        the cycle does not run; nothing when the bus is closed or the task runs."""
        bus = self.frames.bus
        if bus is None or self.idle_task is not None:
            return
        message = can.Message(arbitration_id=self.master_id, data=self.payload,
                              is_extended_id=False)

        def stop_on_error(error: Exception) -> bool:
            # the bus went away (its peer ended, or it is closing): stop, and let the next
            # read() report the bus; never an exception in a background thread
            self.idle_errors.append(f"{type(error).__name__}: {error}")
            return False

        self.idle_task = ThreadBasedCyclicSendTask(
            bus, threading.Lock(), message, self.period_s, on_error=stop_on_error)
        # the guarded drives' requests, each a task of its own (a task with several
        # messages sends one of them per period)
        self.idle_guards = [ThreadBasedCyclicSendTask(
            bus, threading.Lock(), request, self.period_s,
            on_error=stop_on_error) for request in self.guard_requests]

    def stop_idle(self) -> None:
        """Stop the background task, waiting for a send in progress."""
        tasks = [self.idle_task, *self.idle_guards]
        self.idle_task, self.idle_guards = None, []
        for task in tasks:
            if task is None:
                continue
            task.stop()
            # stop() only flags the thread: wait for a send in progress to finish, so the
            # bus is never shut down under it (python-can would log a traceback)
            thread = getattr(task, "thread", None)
            if thread is not None and thread is not threading.current_thread():
                thread.join(timeout=self.period_s + 0.5)
