"""The slave's supervisor: a pure state machine that decides, each tick, whether the tool
runs, follows the handle or stops, from the time, the master's newest message and the tool's
position. It holds no clock, no link and no node; the program feeds it and acts on what it
returns (docs/architecture.md, "one tick").

Per tick, in two steps (the tool may be moved to the handle between them):

1. :meth:`follows_handle` (fresh message?): while the tool is not running and not stopped by
   the work-area guard, every fresh message re-places it at the handle (``SlaveNode.resync``);
2. :meth:`update` (time, fresh?, the tool's position, the link's silence, the master's
   liveliness): the watchdog (``common/runtime/watchdog.py``) with ``in_sync`` = |yt - Ah1 yh| below
   the tolerance on both axes; the tool runs only with the watchdog ``ok`` and the master's
   forces enabled; the work-area guard stops the tool (until the next resync cycle) when it
   gets more than the margin outside the work area; with ``grid_m`` given, once the handle is
   back over that area (no margin) the stop ends and the tool rejoins the handle (the resync
   policy); an input fault (slave_sim/input_guard.py) stops the tool too. Returns a
   :class:`Transition` (``RESUME``: ``SlaveNode.resume``; ``STOP``: ``SlaveNode.safe_stop``),
   with :attr:`running` and
   :attr:`ready` (this side's FORCES_ENABLED flag) for the tick.
"""

from __future__ import annotations

from haptic.common.runtime.supervision import (
    FORCES_ENABLED,
    STOPPING,
    SupervisionCore,
    Transition,
)
from haptic.common.runtime.watchdog import WatchdogState
from haptic.common.wire.messages import HandleState


class SlaveSupervisor(SupervisionCore):
    """Watchdog, resync and work-area guard of the slave (see the module docstring; the
    watchdog and the resync check's geometry are the :class:`SupervisionCore`'s).

    ``position_ratio``: Ah1 per axis (x, y), dimensionless; ``sync_tolerance_m``: resync
    tolerance per axis, m; ``work_area_m``: (x_low, x_high, y_low, y_high), the tool's work
    area including its margin, m; ``max_message_age_s``/``resync_messages``: the watchdog's;
    ``grid_m``: (x_low, x_high, y_low, y_high) the handle (times Ah1) must be back over to end
    a work-area stop, m (None: only a resync cycle ends it).
    """

    def __init__(self, position_ratio: tuple[float, float], sync_tolerance_m: float,
                 work_area_m: tuple[float, float, float, float], max_message_age_s: float,
                 resync_messages: int,
                 grid_m: tuple[float, float, float, float] | None = None) -> None:
        super().__init__(position_ratio, sync_tolerance_m, max_message_age_s, resync_messages)
        self.x_low_m, self.x_high_m, self.y_low_m, self.y_high_m = (float(v)
                                                                    for v in work_area_m)
        self.handle_position_m = (0.0, 0.0)
        self.master_enabled = False
        self.running = False
        self.ready = False
        self.outside = False
        #: after a work-area stop, the tool is on its way back to the handle: it runs again
        #: only once in sync (it moves through the clay at a bounded speed)
        self.rejoining = False
        self.input_fault = False
        self.plant_fault = False
        #: the message :meth:`receive` took is the master's last (``Flags.STOPPING``)
        self.peer_stopping = False
        self.grid_m = None if grid_m is None else tuple(float(v) for v in grid_m)

    def start_synced(self, handle_position_m: tuple[float, float]) -> None:
        """Count the link as up and in sync before the first tick, the master's forces on and
        the handle at ``handle_position_m`` (m): the tool runs from tick 0 (the lockstep
        simulator's warm start)."""
        self.watchdog.state = WatchdogState.OK
        self.handle_position_m = (float(handle_position_m[0]), float(handle_position_m[1]))
        self.master_enabled = self.running = self.ready = True

    def receive(self, message: HandleState | None) -> bool:
        """Take the tick's fresh message (or ``None``); returns whether the tool should be
        re-placed at the handle now (it is not running and not stopped by the guard)."""
        self.peer_stopping = False
        if message is not None:
            flags = int(message.flags)
            self.handle_position_m = tuple(message.handle_position_m)  # type: ignore[assignment]
            self.master_enabled = bool(flags & FORCES_ENABLED)
            self.peer_stopping = bool(flags & STOPPING)
        return message is not None and not self.running and not self.outside

    def steady(self) -> bool:
        """The tool runs with the watchdog ``ok``, the master's forces on and nothing
        stopped, rejoining or faulted: while the link stays fresh, every message is admitted
        as it is with FORCES_ENABLED and the tool stays in its work area (the lockstep's
        quiet lanes, slave_sim/quiet_kernel.py), :meth:`receive` only stores the handle's
        position and :meth:`update` changes nothing and returns ``NONE``."""
        return (self.running and self.master_enabled and not self.outside
                and not self.rejoining and not self.input_fault and not self.plant_fault
                and self.watchdog.state is WatchdogState.OK)

    def in_sync(self, tool_x_m: float, tool_y_m: float) -> bool:
        """|yt - Ah1 yh| below the tolerance on both axes."""
        handle_x_m, handle_y_m = self.handle_position_m
        return self.positions_in_sync(tool_x_m, tool_y_m, handle_x_m, handle_y_m)

    def update(self, now_s: float, fresh: bool, tool_position_m: tuple[float, float],
               silence_s: float = 0.0, peer_alive: bool = True,
               input_fault: bool = False, plant_fault: bool = False) -> Transition:
        """One tick, after :meth:`receive` (and the resync it asked for); returns what
        changed (see :class:`Transition`). ``input_fault``: the input guard holds a fault;
        ``plant_fault``: the tool's plant lost its own supervision (a robot over ROS 2 whose
        force stopped coming): the tool stops like on an input fault, so its forces go off
        and the master holds the handle."""
        self.input_fault = input_fault
        was_plant_fault, self.plant_fault = self.plant_fault, plant_fault
        input_fault = input_fault or plant_fault
        tool_x_m, tool_y_m = tool_position_m
        synced = self.in_sync(tool_x_m, tool_y_m)
        stopping = self.peer_stopping
        self.peer_stopping = False
        state = self.watchdog.update(now_s, fresh, silence_s, synced, peer_alive, stopping)
        watchdog_ok = state is WatchdogState.OK
        # the master holds its handle while the tool is stopped (Flags.WORK_AREA_STOP): with
        # a grid the stop lasts until the handle is back over it, not merely while the master
        # holds; a watchdog resync cycle ends it
        held_for_stop = self.outside and self.grid_m is not None
        if not watchdog_ok or not (self.master_enabled or held_for_stop):
            self.outside = self.rejoining = False  # a resync cycle ends the work-area stop
        elif not (self.outside or self.rejoining) and not (
                self.x_low_m <= tool_x_m <= self.x_high_m
                and self.y_low_m <= tool_y_m <= self.y_high_m):
            # the work area's guard: the tool stops at its edge until a resync
            self.outside = True
            self.events.append({"time_s": now_s, "kind": "tool_stopped",
                                "reason": f"tool left the work area at ({tool_x_m:.4f}, "
                                f"{tool_y_m:.4f}) m"})
        elif self.outside and fresh and self.grid_m is not None:
            x_low, x_high, y_low, y_high = self.grid_m
            handle_x_m, handle_y_m = self.handle_position_m
            if (x_low <= self.ratio_x * handle_x_m <= x_high
                    and y_low <= self.ratio_y * handle_y_m <= y_high):
                # resync policy: the handle is back over the work area; the tool rejoins it
                # there (receive() re-places it from the next tick) and runs once in sync
                self.outside = False
                self.rejoining = True
                self.events.append({"time_s": now_s, "kind": "tool_resync",
                                    "reason": "the handle is back over the work area: the "
                                    "tool rejoins it"})
        if self.rejoining and (not watchdog_ok or synced):
            self.rejoining = False  # back at the handle (or a watchdog resync takes over)
        running = (watchdog_ok and self.master_enabled and not self.outside
                   and not self.rejoining and not input_fault)
        self.ready = watchdog_ok and not self.outside and not input_fault
        transition = Transition.NONE
        if running and not self.running:
            transition = Transition.RESUME
            self.events.append({"time_s": now_s, "kind": "tool_resumed",
                                "reason": "positions in sync and the master's forces enabled"})
        elif self.running and not running:
            transition = Transition.STOP
            if not (self.outside or self.rejoining):
                reason = (self.watchdog.state_text() if not watchdog_ok
                          else "the robot plant's watchdog tripped" if plant_fault
                          else "input fault" if input_fault
                          else "the master is in its safe state")
                self.events.append({"time_s": now_s, "kind": "tool_stopped",
                                    "reason": f"{reason}: the tool stops"})
        if plant_fault and not was_plant_fault and not (
                self.events and self.events[-1]["time_s"] == now_s
                and "robot plant" in self.events[-1]["reason"]):
            # said even when the tool stopped for another cause: it now stays stopped for good
            self.events.append({"time_s": now_s, "kind": "tool_stopped",
                                "reason": "the robot plant's watchdog tripped: the tool stays "
                                "stopped"})
        self.running = running
        return transition

    def stop_reason(self) -> str:
        """Why the tool is not running now (for the inert monitor, common/runtime/inert.py)."""
        if self.outside:
            return "the tool is stopped by the work-area guard"
        if self.rejoining:
            return "the tool rejoins the handle after a work-area stop"
        if self.plant_fault:
            return "the robot plant's watchdog tripped"
        if self.input_fault:
            return "input fault"
        state = self.watchdog.state
        if state is not WatchdogState.OK:
            return self.watchdog.state_text()
        return "the master's forces are off"
