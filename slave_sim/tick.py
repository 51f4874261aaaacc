"""One tick of the slave, with the I/O passed in: supervise, then the node.

The program (slave_sim/program.py) and the lockstep simulator (lockstep/simulator.py) both
run their ticks through :class:`SlaveTick`, so the simulator that checks the analysis runs
the input guard, the supervisor, the resync and the node exactly as they ship
(docs/architecture.md, "one tick"):

    poll -> supervise -> node -> send -> telemetry
    (caller) SlaveTick.supervise  SlaveTick.control  (caller)

:meth:`SlaveTick.supervise`, per lane: the input guard bounds a fresh ``HandleState``
(slave_sim/input_guard.py; a fault is not an input), and, where the caller passes them, every
older message delivered in the same tick before it (the program steps each admitted one with
its own force: :attr:`SlaveTick.samples`, slave_sim/pacing.py); the supervisor (watchdog, resync,
work-area guard; slave_sim/supervisor.py) says whether the tool follows the handle
(``ToolResync``: through the clay at a bounded speed) and whether it runs, stops or resumes.
:meth:`SlaveTick.control` steps the node (Ch2/Ct2, the tool, the environment) with the
bounded handle force where the tool runs and zero force elsewhere, and returns the node's
outputs with the flags to send.

The simulator feeds its messages as columns (:meth:`SlaveTick.supervise_columns`): a lane
whose guard takes its message as it is and whose supervisor is in its steady state with
nothing to change (one Warp kernel for all lanes, slave_sim/quiet_kernel.py) only stores the
message, and every other lane goes through its guard and supervisor as the program's does.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from haptic.common.analysis.margin_table import follow_gain
from haptic.common.wire.lane_flags import lane_flag_values
from haptic.common.wire.messages import FLAGS_BY_VALUE, Flags, HandleState
from haptic.common.wire.send_clock import SendClock, receive_time_ns
from haptic.slave_sim.input_guard import InputGuard
from haptic.slave_sim.node import SlaveNode, SlaveOutputs, SlaveState
from haptic.slave_sim.pacing import Sample, Step
from haptic.slave_sim.quiet_kernel import QuietLanes, guard_limits
from haptic.slave_sim.resync import ToolResync
from haptic.slave_sim.supervisor import SlaveSupervisor, Transition

#: Flag values (IntFlag arithmetic costs about 1 us per operation, too much per lane and
#: tick in a sweep).
_FORCES_ENABLED, _SAFE_STATE = int(Flags.FORCES_ENABLED), int(Flags.SAFE_STATE)
_IN_CONTACT, _WORK_AREA_STOP = int(Flags.IN_CONTACT), int(Flags.WORK_AREA_STOP)
_TDPA_SWITCHED = int(Flags.TDPA_SWITCHED)


def _flag_value(ready: Any, cutting: Any, outside: Any, switched: Any) -> Any:
    """The flags of the program's one lane's message to the master, as an int (Python
    bools; many lanes: ``lane_flag_values``): FORCES_ENABLED when this side is ready, else
    SAFE_STATE; IN_CONTACT while cutting; WORK_AREA_STOP while the work-area guard holds the
    tool; TDPA_SWITCHED while a standby passivity layer is switched on (the bits are disjoint)."""
    return (_SAFE_STATE + (_FORCES_ENABLED - _SAFE_STATE) * ready + _IN_CONTACT * cutting
            + _WORK_AREA_STOP * outside + _TDPA_SWITCHED * switched)


@dataclass
class SlaveTickOutput:
    """What one tick produced: the node's outputs (``out``), which lanes ran (``running``,
    (lanes,) bool), and per lane the flags of the message to the master (``flag_values``
    (lanes,) int, :attr:`flags` as ``Flags``: FORCES_ENABLED when this side is ready,
    IN_CONTACT while cutting)."""

    out: SlaveOutputs
    running: np.ndarray
    flag_values: np.ndarray

    @property
    def flags(self) -> list[Flags]:
        """Per lane, the flags of the message to the master."""
        return [FLAGS_BY_VALUE[value] for value in self.flag_values.tolist()]


@dataclass
class HandleColumns:
    """A tick's handle messages as columns (the lockstep's lanes): ``fresh`` (lanes,) bool
    where a new message came; each lane's message's ``force_N`` and ``position_m``
    ((lanes, 2), N and m), ``flags``, ``epoch`` and ``send_time_ns`` ((lanes,) int, ns) and
    ``force_scale`` ((lanes,), 0..1), read where fresh; ``rows`` (lanes, C): what
    ``build(lane, row)`` needs to make that lane's ``HandleState`` for its guard and
    supervisor."""

    fresh: np.ndarray
    force_N: np.ndarray
    position_m: np.ndarray
    flags: np.ndarray
    epoch: np.ndarray
    send_time_ns: np.ndarray
    force_scale: np.ndarray
    rows: np.ndarray
    build: Callable[[int, np.ndarray], HandleState]


class SlaveTick:
    """The slave's supervise and node stages for ``len(supervisors)`` lanes.

    ``state``: the node's state (the caller made it, e.g. ``node.initial_state(lanes)``);
    ``guards``: one :class:`InputGuard` per lane; ``resync``: the tool's way back to the
    handle. The newest bounded handle force and position per lane are :attr:`handle_force_N`
    and :attr:`handle_position_m` ((lanes, 2), N and m).
    """

    def __init__(self, node: SlaveNode, state: SlaveState,
                 supervisors: Sequence[SlaveSupervisor], guards: Sequence[InputGuard],
                 resync: ToolResync | None = None) -> None:
        lanes = len(supervisors)
        if lanes != state.lanes or len(guards) != lanes:
            raise ValueError(f"one supervisor and one guard per lane ({state.lanes} lanes)")
        self.node = node
        self.state = state
        self.supervisors = list(supervisors)
        self.guards = list(guards)
        self.resync = resync if resync is not None else ToolResync(node)
        self.lanes = lanes
        self.handle_force_N = np.zeros((lanes, 2))
        #: per lane, every message of the last :meth:`supervise` the guard admitted, in order,
        #: as (epoch, seq, (fx, fy) N bounded, (x, y) m, force scale); filled only where
        #: ``earlier`` was passed (the program: slave_sim/pacing.py)
        self.samples: list[list[Sample]] = [[] for _ in range(lanes)]
        #: (lanes,) the newest admitted message's force ramp (HandleState.force_scale), which
        #: scales the node's Ct2 input ft as the master's scaled its Ct1 input
        self.force_scale = np.ones(lanes)
        state.tool_force_scale = self.force_scale
        self.handle_position_m = state.handle_position_m.copy()
        self.fresh = np.zeros(lanes, bool)
        self.running = np.zeros(lanes, bool)
        self._zero_force = np.zeros((lanes, 2))
        #: per lane, the send time of the newest admitted handle message (ns, 0: none yet),
        #: echoed to the master for its round-trip estimate (master/margin_governor.py)
        self.echo_send_time_ns = np.zeros(lanes, np.int64)
        #: (lanes,) the master's cumulative handed-over energy, J, as last received (the
        #: passivity layer, ``tdpa`` mode; None otherwise)
        self.peer_energy_J: np.ndarray | None = None
        self._gain: tuple[float, bool] | None = None
        #: each supervisor's ``ready`` and ``outside`` (the flags of :meth:`control`)
        self._ready = np.zeros(lanes, bool)
        self._outside = np.zeros(lanes, bool)
        self._flag_values = np.zeros(lanes, np.int64)
        self._none_switched = np.zeros(lanes, bool)
        # supervise_columns' view of the guards and supervisors, made afresh after a
        # supervise(): each supervisor's steady() and work area, each guard's fault and
        # its latest accepted message (its force and position are handle_force_N and
        # handle_position_m), and the messages a quiet lane took that its guard and
        # supervisor have not seen (stale)
        self._columns_current = False
        self._steady = np.zeros(lanes, bool)
        self._max_age_s = np.array([s.watchdog.max_age_s for s in self.supervisors], float)
        self._work_area_m = np.array([(s.x_low_m, s.x_high_m, s.y_low_m, s.y_high_m)
                                      for s in self.supervisors], float)
        self._guard_faulted = np.zeros(lanes, bool)
        self._guard_has_last = np.zeros(lanes, bool)
        self._guard_epoch = np.zeros(lanes, np.int64)
        self._guard_credited_ns = np.zeros(lanes, np.int64)  # the guards' SendClock
        self._guard_received_ns = np.zeros(lanes, np.int64)
        self._guard_lead_ns = np.zeros(lanes, np.int64)
        self._unseen = np.zeros(lanes, np.int64)
        #: the quiet lanes' kernel over these arrays (slave_sim/quiet_kernel.py), bound at
        #: the first supervise_columns
        self._quiet_lanes: QuietLanes | None = None
        #: lane-ticks of supervise_columns that went through their guard and supervisor,
        #: and all
        self.lane_ticks_fed = 0
        self.lane_ticks = 0

    def follow_gain(self, nominal_k: float, scalable: bool) -> None:
        """Follow the master's governed k (``HandleState.gain_k``, never above
        ``nominal_k``): the node's inputs are scaled by k/k0 per lane (``state.gain_ratio``);
        ``scalable``: the model's compensators are linear in k (common/analysis/margin_table.py)."""
        self._gain = (float(nominal_k), bool(scalable))
        self.state.gain_ratio = np.ones(self.lanes)

    def start(self, synced: bool = False) -> None:
        """Before the first tick: the tool stops and waits for the master; with ``synced``
        the link counts as up and in sync (the lockstep's warm start) and the tool runs from
        tick 0 with the handle at :attr:`handle_position_m`."""
        self._columns_current = False
        if not synced:
            self.node.safe_stop(self.state)
            return
        for lane, supervisor in enumerate(self.supervisors):
            supervisor.start_synced(tuple(self.handle_position_m[lane]))
            self.guards[lane].position_m = (float(self.handle_position_m[lane, 0]),
                                            float(self.handle_position_m[lane, 1]))
        self.running[:] = True
        self._ready[:] = [supervisor.ready for supervisor in self.supervisors]

    def supervise(self, now_s: float, messages: Sequence[HandleState | None],
                  silence_s: Sequence[float] | None = None,
                  peer_alive: Sequence[bool] | None = None,
                  earlier: Sequence[Sequence[HandleState]] | None = None) -> np.ndarray:
        """Feed every lane's guard and supervisor (``messages``: the fresh ``HandleState``
        per lane or ``None``; ``silence_s``: time since the last fresh message per lane, s;
        ``peer_alive``: the master's liveliness per lane; ``earlier``: per lane, the older
        messages delivered with it, in order: each passes the guard before it, and the
        admitted ones go into :attr:`samples`); re-place, stop or resume the tool as they
        say. Returns the lanes whose message was an input (fresh and admitted)."""
        guards, supervisors = self.guards, self.supervisors
        if self._columns_current:
            self.sync_supervisors()
            self._columns_current = False
        admitted_lanes = []
        follow = []
        for lane, message in enumerate(messages):
            guard = guards[lane]
            if earlier is not None:
                samples = self.samples[lane]
                samples.clear()
                for older in earlier[lane]:  # a fault among them latches the guard too
                    if guard.admit(older, now_s):
                        samples.append((older.epoch, older.seq, guard.force_N,
                                        guard.position_m, older.force_scale))
            admitted = message is not None and guard.admit(message, now_s)
            if admitted:
                admitted_lanes.append(lane)
                if earlier is not None:
                    self.samples[lane].append((message.epoch, message.seq, guard.force_N,
                                               guard.position_m, message.force_scale))
            # a fault is not an input
            follow.append(supervisors[lane].receive(message if admitted else None))
        fresh = self.fresh
        fresh[...] = False
        if admitted_lanes:  # lane by lane: the program's one lane takes scalar writes
            gain = self._gain
            for lane in admitted_lanes:
                fresh[lane] = True
                self.handle_force_N[lane] = guards[lane].force_N  # bounded
                self.handle_position_m[lane] = guards[lane].position_m
                message = messages[lane]
                self.echo_send_time_ns[lane] = message.send_time_ns
                self.force_scale[lane] = message.force_scale
                if gain is not None:
                    self.state.gain_ratio[lane] = follow_gain(message.gain_k, *gain)
            if self.node.passivity_standby:
                self._follow_switch(now_s, messages, admitted_lanes)
        state = self.state
        if any(follow):  # to the held handle, cutting (slave_sim/resync.py)
            self.resync.step(state, self.handle_position_m, now_s,
                             None if all(follow) else np.array(follow))
        tool = state.tool[:, 0::2].tolist()  # (x, y) per lane, floats
        fresh_list = fresh.tolist()
        running, ready, outside = self.running, self._ready, self._outside
        resume, stop = [], []
        # a plant with a watchdog of its own (slave_sim/robot_plant.py) reports its trip
        plant_fault = bool(getattr(self.node.environment, "tripped", False))
        for lane, supervisor in enumerate(supervisors):
            transition = supervisor.update(now_s, fresh_list[lane], tool[lane],
                                           0.0 if silence_s is None else silence_s[lane],
                                           True if peer_alive is None else peer_alive[lane],
                                           guards[lane].faulted, plant_fault)
            running[lane] = supervisor.running
            ready[lane] = supervisor.ready
            outside[lane] = supervisor.outside
            resume.append(transition is Transition.RESUME)
            stop.append(transition is Transition.STOP)
        if any(resume):
            self.node.resume(state, None if all(resume) else np.array(resume))
        if any(stop):
            self.node.safe_stop(state, None if all(stop) else np.array(stop))
        return fresh

    def supervise_columns(self, now_s: float, messages: HandleColumns,
                          silence_s: np.ndarray) -> np.ndarray:
        """:meth:`supervise` for messages given as columns and the master alive (the
        lockstep's lanes; no ``earlier`` messages, no :meth:`follow_gain`): a quiet lane
        (slave_sim/quiet_kernel.py) only takes its message's bounded values;
        every other lane's guard and supervisor are fed as :meth:`supervise` feeds them,
        after they have been told what the lane took meanwhile. ``silence_s`` (lanes,), s.
        Returns the lanes whose message was an input, as :meth:`supervise` does."""
        if self._gain is not None:
            raise ValueError("supervise_columns: a tick that follows the master's gain takes "
                             "its messages one by one (supervise)")
        guards, supervisors = self.guards, self.supervisors
        guard = guards[0]
        if not self._columns_current:
            if any((other.settings, other.period_s) != (guard.settings, guard.period_s)
                   for other in guards):
                raise ValueError("supervise_columns: the lanes' input guards must share "
                                 "their settings and period")
            self._pull(range(self.lanes))
            self._columns_current = True
        quiet_lanes = self._quiet_lanes
        if quiet_lanes is None:
            quiet_lanes = self._quiet_lanes = self._bind_quiet_lanes()
        fresh = messages.fresh
        # one kernel: the quiet lanes' messages taken, the others' lanes returned
        fed = quiet_lanes.run(receive_time_ns(now_s), fresh, messages.force_N,
                              messages.position_m, messages.flags, messages.epoch,
                              messages.send_time_ns, messages.force_scale, silence_s)
        state = self.state
        admitted = self.fresh
        self.lane_ticks_fed += len(fed)
        self.lane_ticks += self.lanes
        follow = np.zeros(self.lanes, bool)
        for lane in fed:
            self._tell(lane)
            guard, supervisor = guards[lane], supervisors[lane]
            message = messages.build(lane, messages.rows[lane]) if fresh[lane] else None
            if message is not None and guard.admit(message, now_s):
                admitted[lane] = True
                self.handle_force_N[lane] = guard.force_N
                self.handle_position_m[lane] = guard.position_m
                self.echo_send_time_ns[lane] = message.send_time_ns
                self.force_scale[lane] = message.force_scale
                follow[lane] = supervisor.receive(message)
            else:
                follow[lane] = supervisor.receive(None)
        port = state.passivity
        if self.node.passivity_standby and port is not None:
            switched = admitted & (((messages.flags & _TDPA_SWITCHED) != 0) != port.active)
            for lane in np.flatnonzero(switched).tolist():
                self._switch(now_s, lane, not bool(port.active[lane]))
        following = np.count_nonzero(follow)
        if following:  # to the held handle, cutting (slave_sim/resync.py)
            self.resync.step(state, self.handle_position_m, now_s,
                             None if following == self.lanes else follow)
        if fed:
            tool = state.tool[:, 0::2].tolist()
            resume = np.zeros(self.lanes, bool)
            stop = np.zeros(self.lanes, bool)
            for lane in fed:
                transition = supervisors[lane].update(now_s, bool(admitted[lane]), tool[lane],
                                                      float(silence_s[lane]), True,
                                                      guards[lane].faulted)
                resume[lane] = transition is Transition.RESUME
                stop[lane] = transition is Transition.STOP
            self._pull(fed)
            if resume.any():
                self.node.resume(state, None if resume.all() else resume)
            if stop.any():
                self.node.safe_stop(state, None if stop.all() else stop)
        return admitted

    def _bind_quiet_lanes(self) -> QuietLanes:
        """The quiet lanes' kernel over this tick's arrays (the guards share their settings
        and period: :meth:`supervise_columns` checked)."""
        guard = self.guards[0]
        return QuietLanes(self.lanes, guard_limits(guard.settings, guard.period_s), {
            "guard_faulted": self._guard_faulted, "guard_has_last": self._guard_has_last,
            "steady": self._steady, "max_age_s": self._max_age_s, "tool": self.state.tool,
            "work_area_m": self._work_area_m, "handle_force_N": self.handle_force_N,
            "handle_position_m": self.handle_position_m, "guard_epoch": self._guard_epoch,
            "guard_credited_ns": self._guard_credited_ns,
            "guard_received_ns": self._guard_received_ns, "guard_lead_ns": self._guard_lead_ns,
            "echo_send_time_ns": self.echo_send_time_ns,
            "force_scale": self.force_scale, "unseen": self._unseen, "admitted": self.fresh})

    def _tell(self, lane: int) -> None:
        """Tell ``lane``'s guard and supervisor the messages the lane took as quiet since
        they last saw one (their latest one's values)."""
        count = int(self._unseen[lane])
        if not count:
            return
        position = (float(self.handle_position_m[lane, 0]),
                    float(self.handle_position_m[lane, 1]))
        guard = self.guards[lane]
        clock = SendClock(guard.settings.jitter_allowance_ns, int(self._guard_epoch[lane]),
                          int(self._guard_credited_ns[lane]),
                          int(self._guard_received_ns[lane]), int(self._guard_lead_ns[lane]))
        guard.take_plain(count, (float(self.handle_force_N[lane, 0]),
                                 float(self.handle_force_N[lane, 1])), position, clock)
        self.supervisors[lane].handle_position_m = position
        self._unseen[lane] = 0

    def _pull(self, lanes: Sequence[int]) -> None:
        """Read ``lanes``' guards and supervisors into the columns' view."""
        for lane in lanes:
            guard, supervisor = self.guards[lane], self.supervisors[lane]
            self.running[lane] = supervisor.running
            self._ready[lane] = supervisor.ready
            self._outside[lane] = supervisor.outside
            self._steady[lane] = supervisor.steady()
            self._guard_faulted[lane] = guard.faulted
            clock = guard.clock
            epoch = clock.epoch
            self._guard_has_last[lane] = epoch is not None and guard.position_m is not None
            self._guard_epoch[lane] = 0 if epoch is None else epoch
            self._guard_credited_ns[lane] = clock.credited_ns
            self._guard_received_ns[lane] = clock.received_ns
            self._guard_lead_ns[lane] = clock.lead_ns

    def sync_supervisors(self) -> None:
        """Tell every guard and supervisor what its lane took as quiet in
        :meth:`supervise_columns` (after a run, before their counters are read)."""
        for lane in np.flatnonzero(self._unseen).tolist():
            self._tell(lane)

    def _follow_switch(self, now_s: float, messages: Sequence[HandleState | None],
                       admitted_lanes: list[int]) -> None:
        """A standby passivity layer (``paper`` mode) follows the master's
        :attr:`Flags.TDPA_SWITCHED` in every admitted message: on while it is set, off while
        it is clear (an event ``tdpa_on``/``tdpa_off`` on the lane's supervisor)."""
        port = self.state.passivity
        if port is None:
            return
        active = port.active
        for lane in admitted_lanes:
            on = bool(int(messages[lane].flags) & _TDPA_SWITCHED)
            if on != bool(active[lane]):
                self._switch(now_s, lane, on)

    def _switch(self, now_s: float, lane: int, on: bool) -> None:
        """Switch ``lane``'s standby passivity layer on or off, with its event, which says how
        far apart the sides were (``position_gap_m`` = yt - Ah1 yh, m)."""
        mask = np.zeros(self.lanes, bool)
        mask[lane] = True
        state = self.state
        gap_m = self.node.tracking_error_m(state, state.handle_position_m)[lane]
        state.passivity.switch(mask, on)
        self.supervisors[lane].events.append({
            "time_s": now_s, "kind": "tdpa_on" if on else "tdpa_off",
            "reason": "the master's governor switched the passivity layer "
            + ("on" if on else "off")
            + f" (the sides {float(np.hypot(*gap_m)) * 1e3:.2f} mm apart)",
            "position_gap_m": [float(gap_m[0]), float(gap_m[1])]})

    def control_samples(self, plan: Sequence[Step]) -> SlaveTickOutput:
        """The node stage once per entry of ``plan`` (slave_sim/pacing.py; lane 0: the
        program's one lane): each step with its sample's bounded force (fx, fy) N, position
        (x, y) m and force scale, or the tick's own input where the entry is None (at least
        one step). Afterwards :attr:`handle_force_N`, :attr:`handle_position_m` and
        :attr:`force_scale` hold the tick's own input again (the newest admitted message).
        Returns the last step's output."""
        fh, yh, scale = self.handle_force_N, self.handle_position_m, self.force_scale
        newest = (fh[0, 0], fh[0, 1], yh[0, 0], yh[0, 1], scale[0])
        ticked = None
        for sample in plan or (None,):
            if sample is not None:
                fh[0, 0], fh[0, 1], yh[0, 0], yh[0, 1], scale[0] = sample
            ticked = self.control()
        fh[0, 0], fh[0, 1], yh[0, 0], yh[0, 1], scale[0] = newest
        assert ticked is not None
        return ticked

    def control(self) -> SlaveTickOutput:
        """The node stage: Ch2/Ct2, the tool and the environment, with the bounded handle
        force where the tool runs and zero force elsewhere."""
        running = self.running
        if self.lanes == 1:  # the program's lane: Python scalars are cheaper than numpy calls
            force = self.handle_force_N if running[0] else self._zero_force
        elif (count := np.count_nonzero(running)) == self.lanes:
            force = self.handle_force_N
        elif not count:
            force = self._zero_force
        else:
            force = np.where(running[:, None], self.handle_force_N, 0.0)
        out = self.node.step(self.state, force, self.handle_position_m, self.peer_energy_J)
        port = self.state.passivity
        switched = (port.active if port is not None and self.node.passivity_standby
                    else self._none_switched)
        values = self._flag_values
        if self.lanes == 1:  # the program's lane: Python scalars are cheaper than numpy calls
            values[0] = _flag_value(bool(self._ready[0]), bool(out.cutting[0]),
                                    bool(self._outside[0]), bool(switched[0]))
        else:
            lane_flag_values(values, self._ready, ((_IN_CONTACT, out.cutting),
                                                   (_WORK_AREA_STOP, self._outside),
                                                   (_TDPA_SWITCHED, switched)))
        return SlaveTickOutput(out, running, values)
