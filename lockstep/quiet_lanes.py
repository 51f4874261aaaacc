"""The lockstep's quiet lanes: a filter in front of each side's one way in, its tick's
``supervise``, which it calls on the lanes that need their objects.

The supervisors and guards are plain Python, one object per lane, which is what a program's
one-lane tick wants but costs a sweep about 25 us per lane and tick. Most lanes, most ticks,
would change nothing in them: a lane in its supervisor's steady state whose message the guard
takes as it is. For those one Warp kernel per side and tick (master/quiet_kernel.py,
slave_sim/quiet_kernel.py) does what the tick would: it stores the message and the bounded
values the node reads (the tick's own arrays), and the lane's objects are told later, when
the lane next needs them or after the run (:meth:`sync`). Every other lane goes through its
tick's :meth:`~haptic.master.tick.MasterTick.supervise` as the program's lane does.

What the kernels read of the objects (steady states, the guards' clocks, the newest message's
flags) is kept here, read back from the objects of every lane fed. The predicates mirror the
objects comparison by comparison; tests/lockstep/test_quiet_lanes.py holds a run through
these filters to one that feeds every lane's objects, bit for bit (docs/lockstep.md, "Quiet
lanes").
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from haptic.common.wire.messages import Flags, HandleState, ToolState
from haptic.common.wire.send_clock import SendClock, receive_time_ns
from haptic.lockstep.message_lines import HandleLine, ToolLine
from haptic.master.quiet_kernel import QuietLanes as MasterQuietKernel
from haptic.master.tick import MasterTick
from haptic.slave_sim.quiet_kernel import QuietLanes as SlaveQuietKernel
from haptic.slave_sim.quiet_kernel import guard_limits
from haptic.slave_sim.tick import SlaveTick

_TDPA_SWITCHED = int(Flags.TDPA_SWITCHED)


class MasterQuietLanes:
    """The master's filter over ``tick`` (started) and the tool ``line`` it reads: a lane
    whose supervisor is steady, whose link is not silent and whose newest message carries
    FORCES_ENABLED without WORK_AREA_STOP only stores its message; the slave counts as alive
    and the hardware as fault-free. Supervisors with a tool guard are refused (their messages
    go one by one)."""

    def __init__(self, tick: MasterTick, line: ToolLine) -> None:
        supervisors = tick.supervisors
        if any(supervisor.tool_guard is not None for supervisor in supervisors):
            raise ValueError("quiet lanes: supervisors with a tool guard take their messages "
                             "one by one (MasterTick.supervise)")
        self.tick = tick
        self.line = line
        lanes = tick.lanes
        self.steady = np.array([supervisor.steady() for supervisor in supervisors], bool)
        self.max_age_s = np.array([s.watchdog.max_age_s for s in supervisors], float)
        #: each lane's newest message's flags and row (``line.columns``)
        self.newest_flags = np.array([0 if s.tool is None else int(s.tool.flags)
                                      for s in supervisors], np.int64)
        self.newest_rows = np.zeros_like(line.columns, dtype=float)
        #: where the supervisor's stored message is older than the newest row
        self.stale = np.zeros(lanes, bool)
        self.kernel = MasterQuietKernel(lanes, {
            "steady": self.steady, "max_age_s": self.max_age_s,
            "newest_flags": self.newest_flags, "newest_rows": self.newest_rows,
            "tool_force_N": tick.tool_force_N, "stale": self.stale})
        self._messages: list[ToolState | None] = [None] * lanes
        #: lane-ticks fed to their supervisor, and all
        self.lane_ticks_fed = 0
        self.lane_ticks = 0

    def supervise(self, now_s: float, handle_position_m: np.ndarray) -> None:
        """One tick: the quiet lanes store the line's fresh messages, the others go through
        the tick's ``supervise`` (``handle_position_m`` (lanes, 2), m)."""
        tick, line = self.tick, self.line
        state = tick.state
        if state is not None and np.count_nonzero(state.faulted):
            # the node's trips the last control noted in the supervisors: no longer steady
            self.steady[tick.enabled & state.faulted] = False
        received = line.received
        fed = self.kernel.run(line.fresh, line.flags, line.columns, received.force_N,
                              line.silence_s)
        self.lane_ticks += tick.lanes
        if fed is None:  # every lane quiet
            return
        lanes = np.flatnonzero(fed).tolist()
        self.lane_ticks_fed += len(lanes)
        supervisors, messages, fresh = tick.supervisors, self._messages, line.fresh
        for lane in lanes:
            if fresh[lane]:
                messages[lane] = line.message(lane)
            elif self.stale[lane]:
                supervisors[lane].tool = line.message_of(self.newest_rows[lane])
            self.stale[lane] = False
        tick.supervise(now_s, messages, handle_position_m, silence_s=line.silence_s,
                       lanes=lanes)
        for lane in lanes:
            self.steady[lane] = supervisors[lane].steady()
            messages[lane] = None

    def sync(self) -> None:
        """Give every supervisor the newest message its lane took as quiet (after a run,
        before the supervisors are read)."""
        for lane in np.flatnonzero(self.stale).tolist():
            self.tick.supervisors[lane].tool = self.line.message_of(self.newest_rows[lane])
        self.stale[...] = False


class SlaveQuietLanes:
    """The slave's filter over ``tick`` (started) and the handle ``line`` it reads: a lane
    whose guard takes its fresh message as it is (with FORCES_ENABLED) and whose supervisor is
    steady, its link not silent and its tool inside the work area, only takes the message's
    bounded values; the master counts as alive. The guards must share their settings and
    period, and the tick must not follow the master's gain (refused otherwise)."""

    def __init__(self, tick: SlaveTick, line: HandleLine) -> None:
        guards, supervisors = tick.guards, tick.supervisors
        first = guards[0]
        if any((guard.settings, guard.period_s) != (first.settings, first.period_s)
               for guard in guards):
            raise ValueError("quiet lanes: the lanes' input guards must share their settings "
                             "and period")
        if tick.follows_gain:
            raise ValueError("quiet lanes: a tick that follows the master's gain takes its "
                             "messages one by one (SlaveTick.supervise)")
        self.tick = tick
        self.line = line
        lanes = tick.lanes
        self.steady = np.zeros(lanes, bool)
        self.max_age_s = np.array([s.watchdog.max_age_s for s in supervisors], float)
        self.work_area_m = np.array([(s.x_low_m, s.x_high_m, s.y_low_m, s.y_high_m)
                                     for s in supervisors], float)
        self.guard_faulted = np.zeros(lanes, bool)
        self.guard_has_last = np.zeros(lanes, bool)
        # the guards' SendClock
        self.guard_epoch = np.zeros(lanes, np.int64)
        self.guard_credited_ns = np.zeros(lanes, np.int64)
        self.guard_received_ns = np.zeros(lanes, np.int64)
        self.guard_lead_ns = np.zeros(lanes, np.int64)
        #: per lane, the messages taken as quiet that its guard has not seen
        self.unseen = np.zeros(lanes, np.int64)
        self._pull(range(lanes))
        self.kernel = SlaveQuietKernel(lanes, guard_limits(first.settings, first.period_s), {
            "guard_faulted": self.guard_faulted, "guard_has_last": self.guard_has_last,
            "steady": self.steady, "max_age_s": self.max_age_s, "tool": tick.state.tool,
            "work_area_m": self.work_area_m, "handle_force_N": tick.handle_force_N,
            "handle_position_m": tick.handle_position_m, "guard_epoch": self.guard_epoch,
            "guard_credited_ns": self.guard_credited_ns,
            "guard_received_ns": self.guard_received_ns, "guard_lead_ns": self.guard_lead_ns,
            "echo_send_time_ns": tick.echo_send_time_ns,
            "force_scale": tick.force_scale, "unseen": self.unseen, "admitted": tick.fresh})
        self._messages: list[HandleState | None] = [None] * lanes
        #: lane-ticks fed to their guard and supervisor, and all
        self.lane_ticks_fed = 0
        self.lane_ticks = 0

    def supervise(self, now_s: float) -> None:
        """One tick: the quiet lanes take the line's fresh messages (a standby passivity
        layer follows their flag), the others go through the tick's ``supervise``."""
        tick, line = self.tick, self.line
        received = line.received
        fed = self.kernel.run(receive_time_ns(now_s), line.fresh, received.force_N,
                              received.position_m, line.flags, line.epoch, line.send_time_ns,
                              received.force_scale, line.silence_s)
        self.lane_ticks += tick.lanes
        self.lane_ticks_fed += len(fed)
        port = tick.state.passivity
        if tick.node.passivity_standby and port is not None:
            flags = line.flags
            switched = tick.fresh & (((flags & _TDPA_SWITCHED) != 0) != port.active)
            if switched.any():
                lanes = np.flatnonzero(switched).tolist()
                tick.follow_switch(now_s, lanes, flags[lanes].tolist())
        if not fed:
            return
        messages, fresh = self._messages, line.fresh
        for lane in fed:
            self._tell(lane)
            if fresh[lane]:
                messages[lane] = line.message(lane)
        tick.supervise(now_s, messages, line.silence_s, lanes=fed)
        self._pull(fed)
        for lane in fed:
            messages[lane] = None

    def _tell(self, lane: int) -> None:
        """Tell ``lane``'s guard and supervisor the messages the lane took as quiet since
        they last saw one (their latest one's values)."""
        count = int(self.unseen[lane])
        if not count:
            return
        tick = self.tick
        position = (float(tick.handle_position_m[lane, 0]),
                    float(tick.handle_position_m[lane, 1]))
        guard = tick.guards[lane]
        clock = SendClock(guard.settings.jitter_allowance_ns, int(self.guard_epoch[lane]),
                          int(self.guard_credited_ns[lane]), int(self.guard_received_ns[lane]),
                          int(self.guard_lead_ns[lane]))
        guard.take_plain(count, (float(tick.handle_force_N[lane, 0]),
                                 float(tick.handle_force_N[lane, 1])), position, clock)
        tick.supervisors[lane].handle_position_m = position
        self.unseen[lane] = 0

    def _pull(self, lanes: Sequence[int]) -> None:
        """Read ``lanes``' guards and supervisors into what the kernel reads."""
        tick = self.tick
        for lane in lanes:
            guard, supervisor = tick.guards[lane], tick.supervisors[lane]
            self.steady[lane] = supervisor.steady()
            self.guard_faulted[lane] = guard.faulted
            clock = guard.clock
            epoch = clock.epoch
            self.guard_has_last[lane] = epoch is not None and guard.position_m is not None
            self.guard_epoch[lane] = 0 if epoch is None else epoch
            self.guard_credited_ns[lane] = clock.credited_ns
            self.guard_received_ns[lane] = clock.received_ns
            self.guard_lead_ns[lane] = clock.lead_ns

    def sync(self) -> None:
        """Tell every guard and supervisor what its lane took as quiet (after a run, before
        their counters are read)."""
        for lane in np.flatnonzero(self.unseen).tolist():
            self._tell(lane)
