"""The master's supervisor: a pure state machine that decides, each tick, whether the
master node may apply forces, from the time, the slave's newest message and the handle's
reading. It holds no clock, no link and no node; the program feeds it and acts on what it
returns (docs/architecture.md, "one tick").

Inputs per tick: the time (s), the fresh ``ToolState`` (or ``None``), the handle position (m),
the hardware's faults, the link's silence (s) and the slave's liveliness. Decisions:

- the watchdog (``common/runtime/watchdog.py``): forces only in ``ok``; leaving ``ok`` is a trip;
- ``in_sync`` for the resync: the slave reports its forces enabled and |yt - Ah1 yh| is below
  the tolerance on both axes;
- a hardware fault, or a trip of the node's safety layer (:meth:`note_node_fault`), latches
  the safe state for the rest of the run;
- with a ``tool_guard`` (master/tool_guard.py), an implausible ``ToolState`` is not an input
  (the tick sees no message) and its fault turns forces off until it clears and the tool is
  in sync with the handle again;
- the slave's work-area guard (``Flags.WORK_AREA_STOP``) holds the handle too (an event
  ``handle_held`` and :attr:`peer_stops`), so the handle does not run on while the tool
  stands; forces come back once the flag clears and the tool is in sync again;
  so does any other stop of the slave's tool while forces are on here (``FORCES_ENABLED``
  gone from its messages: its watchdog tripped, an input fault), until it reports its forces
  enabled and its tool in sync again;
- the safe state holds the handle where it was when forces went off (or at the start).

:meth:`update` returns a :class:`Transition`: ``ACTIVATE`` the first time forces come on (the
node's own small-force gate applies), ``RESUME`` when they come back after a safe state,
``HOLD`` when they go off, ``NONE`` otherwise; :attr:`enabled` and :attr:`hold_m` say what
to do this tick.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from haptic.common.runtime.supervision import (
    FORCES_ENABLED,
    STOPPING,
    WORK_AREA_STOP,
    SupervisionCore,
    Transition,
)
from haptic.common.runtime.watchdog import WatchdogState
from haptic.common.wire.messages import ToolState
from haptic.master.tool_guard import ToolInputGuard


class MasterSupervisor(SupervisionCore):
    """Watchdog, resync check and fault latch of the master (see the module docstring;
    the watchdog and the resync check's geometry are the :class:`SupervisionCore`'s).

    ``position_ratio``: Ah1 per axis (x, y), dimensionless; ``sync_tolerance_m``: the resync
    position tolerance per axis, m; ``max_message_age_s``/``resync_messages``: the watchdog's;
    ``tool_guard``: the bounds on the received tool messages (None: none; its events go to
    :attr:`events`).
    """

    def __init__(self, position_ratio: tuple[float, float], sync_tolerance_m: float,
                 max_message_age_s: float, resync_messages: int,
                 tool_guard: ToolInputGuard | None = None) -> None:
        super().__init__(position_ratio, sync_tolerance_m, max_message_age_s, resync_messages)
        self.tool: ToolState | None = None
        self.enabled = False
        self.ever_enabled = False
        self.faulted = False
        self.hold_m = np.zeros(2)
        self.hardware_faults: list[str] = []
        self.tool_guard = tool_guard
        if tool_guard is not None:
            tool_guard.events = self.events
        self._await_sync = False  # after a tool input fault: forces wait for the resync check
        #: the slave's work-area guard stopped the tool: forces wait for the flag to clear
        #: and the tool to be in sync again
        self._await_peer = False
        self._peer_reason = ""
        #: how many times a stop of the slave's tool held the handle, and how many of them
        #: were its work-area guard's
        self.peer_stops = 0
        self.work_area_stops = 0

    def start(self, position_m: Any) -> None:
        """Hold the handle where it is at the start (m; non-finite values read as 0)."""
        self.hold_m = np.nan_to_num(np.asarray(position_m, dtype=float)).copy()

    def start_synced(self) -> None:
        """Count the link as up and in sync before the first tick: the watchdog is ``ok``
        and the forces are on (the lockstep simulator's warm start; the node is activated by
        the caller as for ``ACTIVATE``)."""
        self.watchdog.state = WatchdogState.OK
        self.enabled = self.ever_enabled = True

    def steady(self) -> bool:
        """Forces on with nothing latched, awaited or guarded: while the link stays fresh
        (the silence within ``max_message_age_s``), the slave alive, no hardware fault and
        the newest tool message without ``WORK_AREA_STOP`` (the lockstep's quiet lanes,
        master/quiet_kernel.py), :meth:`update` changes nothing but the stored message and
        returns ``NONE``."""
        return (self.enabled and not self.faulted and not self._await_sync
                and not self._await_peer and self.tool_guard is None
                and self.watchdog.state is WatchdogState.OK)

    def in_sync(self, handle_x_m: float, handle_y_m: float) -> bool:
        """The slave reports its forces enabled and its tool is at Ah1 yh within the
        tolerance on both axes."""
        tool = self.tool
        if tool is None or not int(tool.flags) & FORCES_ENABLED:
            return False
        tool_x_m, tool_y_m = tool.tool_position_m
        return self.positions_in_sync(tool_x_m, tool_y_m, handle_x_m, handle_y_m)

    def update(self, now_s: float, message: ToolState | None, handle_position_m: Any,
               faults: tuple[str, ...] | list[str] = (), cycle: int = 0,
               silence_s: float = 0.0, peer_alive: bool = True) -> Transition:
        """One tick; returns what changed (see :class:`Transition`)."""
        guard = self.tool_guard
        if message is not None and guard is not None and not guard.admit(message, now_s):
            message = None  # a fault is not an input
            self._await_sync = True
        if message is not None:
            self.tool = message
        x_m, y_m = handle_position_m
        handle_x_m, handle_y_m = float(x_m), float(y_m)  # no generator: cheaper per tick
        synced = self.in_sync(handle_x_m, handle_y_m)
        stopping = message is not None and bool(int(message.flags) & STOPPING)
        state = self.watchdog.update(now_s, message is not None, silence_s, synced, peer_alive,
                                     stopping)
        input_fault = guard is not None and guard.faulted
        if self._await_sync and not input_fault and synced:
            self._await_sync = False
        tool = self.tool
        flags = 0 if tool is None else int(tool.flags)  # int arithmetic: IntFlag's costs 1 us
        work_area_stop = bool(flags & WORK_AREA_STOP)
        # the slave stopped its tool while this side applies forces (its watchdog, an input
        # fault): FORCES_ENABLED gone from its messages
        # (its last message is the watchdog's: an orderly end, not a stop to wait out)
        slave_stopped = (tool is not None and self.enabled and not flags & FORCES_ENABLED
                         and not stopping)
        peer_stop = work_area_stop or slave_stopped
        if peer_stop and not self._await_peer:
            self._await_peer = True
            self.peer_stops += 1
            self.work_area_stops += work_area_stop
            self._peer_reason = (_WORK_AREA_REASON if work_area_stop
                                 else _SLAVE_STOPPED_REASON)
            self.events.append({"time_s": now_s, "kind": "handle_held",
                                "reason": f"{self._peer_reason}: the handle is held until "
                                "the tool is back in sync"})
        elif self._await_peer and not peer_stop and synced:
            self._await_peer = False
        if faults:
            self.hardware_faults.extend(f"cycle {cycle}: {fault}" for fault in faults)
            if not self.faulted:
                self._latch(now_s, "hardware: " + "; ".join(faults))
        enabled = (state is WatchdogState.OK and not self.faulted and not self._await_sync
                   and not self._await_peer)
        if enabled == self.enabled:
            return Transition.NONE
        self.enabled = enabled
        if enabled:
            transition = Transition.RESUME if self.ever_enabled else Transition.ACTIVATE
            self.ever_enabled = True
            return transition
        position = np.array([handle_x_m, handle_y_m])
        self.hold_m = np.where(np.isfinite(position), position, 0.0)
        return Transition.HOLD

    def note_node_fault(self) -> None:
        """The node's safety layer tripped: the safe state latches (the node reported the
        event itself); forces go off at the next :meth:`update`."""
        self.faulted = True

    def _latch(self, now_s: float, reason: str) -> None:
        self.faulted = True
        self.events.append({"time_s": now_s, "kind": "node_trip", "reason": reason})

    @property
    def input_faulted(self) -> bool:
        """A tool input fault holds the forces off (or its resync is still waiting)."""
        return self._await_sync

    @property
    def peer_held(self) -> bool:
        """A stop of the slave's tool holds the handle (until the tool is back in sync)."""
        return self._await_peer

    def stop_reason(self) -> str:
        """Why forces are off (for the hardware's quick stop and the events)."""
        if self.faulted:
            return "node or hardware fault: " + (self.hardware_faults[-1] if
                                                 self.hardware_faults else "safety layer trip")
        if self.tool_guard is not None and self.tool_guard.faulted:
            return "tool input fault"
        if self._await_sync:
            return "tool input fault: waiting for the tool at the handle"
        if self._await_peer:
            return f"{self._peer_reason}: waiting for it at the handle"
        return self.watchdog.state_text()

    def state_name(self) -> str:
        """The watchdog's state, for the status line and the summary."""
        return self.watchdog.state.value


_WORK_AREA_REASON = "the slave's work-area guard stopped the tool"
_SLAVE_STOPPED_REASON = ("the slave stopped its tool (its forces are off: its watchdog or an "
                         "input fault)")

