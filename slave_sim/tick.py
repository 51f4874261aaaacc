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
outputs with the flags to send. The master's handed-over energy enters the passivity layer
through :meth:`SlaveTick.receive_peer_energy`, for the program's lane (a fresh message's) and
the simulator's lanes (the line's newest) alike.

:meth:`SlaveTick.supervise` is the one way in: the simulator's quiet-lane filter
(lockstep/quiet_lanes.py) calls it on the lanes whose guard or supervisor has something to
do, the program on its one lane.

One lane's whole tick is one call, :meth:`SlaveTick.step_lane` (the program and the real-link
cells, on the one tick driver: common/runtime/tick_driver.py): its inputs
(:class:`SlaveLaneInputs`: the delivered messages, the link's silence) in, its outputs
(:class:`SlaveLaneOutputs`: the node's outputs, the flags, the echo and the energy to send)
out, with the pacing (one node step per master sample), the passivity layer's account of the
master's energy and the flags inside it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from haptic.common.analysis.margin_table import follow_gain
from haptic.common.runtime.lane_tick import UNCONFIGURED_LANE, TickFlags, one_lane_passivity
from haptic.common.runtime.stage_times import StepSplitTimes
from haptic.common.wire.lane_flags import lane_flag_values
from haptic.common.wire.messages import FLAGS_BY_VALUE, Flags, HandleState
from haptic.common.wire.passivity_link import PassivityLink
from haptic.slave_sim.catch_up import CatchUpStep
from haptic.slave_sim.input_guard import InputGuard
from haptic.slave_sim.node import SlaveNode, SlaveOutputs, SlaveState
from haptic.slave_sim.pacing import MasterSamplePacing, Sample, Step
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
class SlaveTickOutput(TickFlags):
    """What one tick produced: the node's outputs (``out``), which lanes ran (``running``,
    (lanes,) bool), and per lane the flags of the message to the master (``flag_values``
    (lanes,) int, :attr:`flags` as ``Flags``: FORCES_ENABLED when this side is ready,
    IN_CONTACT while cutting)."""

    out: SlaveOutputs
    running: np.ndarray
    flag_values: np.ndarray


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
        #: the one lane's received energy as an array (:meth:`receive_peer_energy`), J
        self._peer_energy_J = np.zeros(1)
        self._gain: tuple[float, bool] | None = None
        #: each supervisor's ``ready`` and ``outside`` (the flags of :meth:`control`)
        self._ready = np.zeros(lanes, bool)
        self._outside = np.zeros(lanes, bool)
        self._flag_values = np.zeros(lanes, np.int64)
        self._none_switched = np.zeros(lanes, bool)
        #: the one lane's node part per tick by its node steps (:meth:`note_node_time`)
        self.node_times = StepSplitTimes()
        #: the program's lane's node steps in one launch where they can run so
        #: (slave_sim/catch_up.py); None: stepped apart
        self._catch_up = CatchUpStep.of(node, state)

    #: the one lane's whole-tick setup (:meth:`configure_lane`)
    _lane: _LaneSetup = UNCONFIGURED_LANE

    def follow_gain(self, nominal_k: float, scalable: bool) -> None:
        """Follow the master's governed k (``HandleState.gain_k``, never above
        ``nominal_k``): the node's inputs are scaled by k/k0 per lane (``state.gain_ratio``);
        ``scalable``: the model's compensators are linear in k (common/analysis/margin_table.py)."""
        self._gain = (float(nominal_k), bool(scalable))
        self.state.gain_ratio = np.ones(self.lanes)

    @property
    def follows_gain(self) -> bool:
        """Whether :meth:`follow_gain` was called (the messages' k scales the node)."""
        return self._gain is not None

    def start(self, synced: bool = False) -> None:
        """Before the first tick: the tool stops and waits for the master; with ``synced``
        the link counts as up and in sync (the lockstep's warm start) and the tool runs from
        tick 0 with the handle at :attr:`handle_position_m`."""
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
                  earlier: Sequence[Sequence[HandleState]] | None = None,
                  lanes: Sequence[int] | None = None) -> np.ndarray:
        """Feed the guards and supervisors of ``lanes`` (default: every lane; the others are
        left as they are). Per lane: ``messages``, the fresh ``HandleState`` or ``None``;
        ``silence_s``, time since the last fresh message, s; ``peer_alive``, the master's
        liveliness; ``earlier``, the older messages delivered with it, in order: each passes
        the guard before it, and the admitted ones go into :attr:`samples`. Re-place, stop or
        resume the tool as they say. Returns :attr:`fresh`: the lanes whose message was an
        input (fresh and admitted)."""
        guards, supervisors = self.guards, self.supervisors
        fed = range(self.lanes) if lanes is None else lanes
        fresh = self.fresh
        admitted_lanes = []
        follow = [False] * self.lanes
        for lane in fed:
            guard = guards[lane]
            message = messages[lane]
            if earlier is not None:
                samples = self.samples[lane]
                samples.clear()
                for older in earlier[lane]:  # a fault among them latches the guard too
                    if guard.admit(older, now_s):
                        samples.append((older.epoch, older.seq, guard.force_N,
                                        guard.position_m, older.force_scale))
            admitted = message is not None and guard.admit(message, now_s)
            fresh[lane] = admitted
            if admitted:
                admitted_lanes.append(lane)
                if earlier is not None:
                    self.samples[lane].append((message.epoch, message.seq, guard.force_N,
                                               guard.position_m, message.force_scale))
            # a fault is not an input
            follow[lane] = supervisors[lane].receive(message if admitted else None)
        if admitted_lanes:  # lane by lane: the program's one lane takes scalar writes
            gain = self._gain
            force, position = self.handle_force_N, self.handle_position_m
            for lane in admitted_lanes:
                guard = guards[lane]
                force[lane, 0], force[lane, 1] = guard.force_N  # bounded
                position[lane, 0], position[lane, 1] = guard.position_m
                message = messages[lane]
                self.echo_send_time_ns[lane] = message.send_time_ns
                self.force_scale[lane] = message.force_scale
                if gain is not None:
                    self.state.gain_ratio[lane] = follow_gain(message.gain_k, *gain)
            if self.node.passivity_standby:
                self.follow_switch(now_s, admitted_lanes,
                                   [int(messages[lane].flags) for lane in admitted_lanes])
        state = self.state
        if any(follow):  # to the held handle, cutting (slave_sim/resync.py)
            self.resync.step(state, self.handle_position_m, now_s,
                             None if all(follow) else np.array(follow))
        tool = state.tool[:, 0::2].tolist()  # (x, y) per lane, floats
        running, ready, outside = self.running, self._ready, self._outside
        resume, stop = [False] * self.lanes, [False] * self.lanes
        # a plant with a watchdog of its own (slave_sim/robot_plant.py) reports its trip
        plant_fault = bool(getattr(self.node.environment, "tripped", False))
        for lane in fed:
            supervisor = supervisors[lane]
            transition = supervisor.update(now_s, bool(fresh[lane]), tool[lane],
                                           0.0 if silence_s is None else float(silence_s[lane]),
                                           True if peer_alive is None else peer_alive[lane],
                                           guards[lane].faulted, plant_fault)
            running[lane] = supervisor.running
            ready[lane] = supervisor.ready
            outside[lane] = supervisor.outside
            resume[lane] = transition is Transition.RESUME
            stop[lane] = transition is Transition.STOP
        if any(resume):
            self.node.resume(state, None if all(resume) else np.array(resume))
        if any(stop):
            self.node.safe_stop(state, None if all(stop) else np.array(stop))
        return fresh

    def _supervise_lane(self, now_s: float, message: HandleState | None, silence_s: float,
                        peer_alive: bool, earlier: Sequence[HandleState] | None) -> bool:
        """:meth:`supervise` of the one lane (:meth:`step_lane`) with Python scalars instead
        of per-lane lists (the same calls in the same order, the same state); returns
        whether the message was an input."""
        guard, supervisor = self.guards[0], self.supervisors[0]
        samples = self.samples[0]
        if earlier is not None:
            samples.clear()
            for older in earlier:  # a fault among them latches the guard too
                if guard.admit(older, now_s):
                    samples.append((older.epoch, older.seq, guard.force_N, guard.position_m,
                                    older.force_scale))
        admitted = message is not None and guard.admit(message, now_s)
        self.fresh[0] = admitted
        if admitted and earlier is not None:
            samples.append((message.epoch, message.seq, guard.force_N, guard.position_m,
                            message.force_scale))
        follow = supervisor.receive(message if admitted else None)  # a fault is not an input
        if admitted:
            self._take_lane_input(now_s, message)
        state = self.state
        if follow:  # to the held handle, cutting (slave_sim/resync.py)
            self.resync.step(state, self.handle_position_m, now_s, None)
        tool = state.tool
        transition = supervisor.update(
            now_s, admitted, (float(tool[0, 0]), float(tool[0, 2])), float(silence_s),
            peer_alive, guard.faulted, bool(getattr(self.node.environment, "tripped", False)))
        self.running[0] = supervisor.running
        self._ready[0] = supervisor.ready
        self._outside[0] = supervisor.outside
        if transition is Transition.RESUME:
            self.node.resume(state, None)
        elif transition is Transition.STOP:
            self.node.safe_stop(state, None)
        return admitted

    def _take_lane_input(self, now_s: float, message: HandleState) -> None:
        """The one lane's admitted message as the tick's input: the guard's bounded force and
        position, the echo, the force ramp, the governed gain, the passivity layer's switch."""
        guard = self.guards[0]
        force, position = self.handle_force_N, self.handle_position_m
        force[0, 0], force[0, 1] = guard.force_N  # bounded
        position[0, 0], position[0, 1] = guard.position_m
        self.echo_send_time_ns[0] = message.send_time_ns
        self.force_scale[0] = message.force_scale
        gain = self._gain
        if gain is not None:
            self.state.gain_ratio[0] = follow_gain(message.gain_k, *gain)
        port = self.state.passivity
        if port is not None and self.node.passivity_standby:  # follow_switch, for lane 0
            on = bool(int(message.flags) & _TDPA_SWITCHED)
            if on != bool(port.active[0]):
                self._switch(now_s, 0, on)

    def receive_peer_energy(self, energy_J: Any) -> None:
        """The master's cumulative handed-over energy, J, into the passivity layer (a node
        with the layer), the same for the program's lane and the lockstep's lanes: (lanes,)
        (the lockstep's newest handle messages, every tick) or, for a one-lane tick, a fresh
        message's float (``PassivityLink.peer_energy``, which minds the master's restarts).
        An older or non-finite value changes nothing; a lane on standby notes it without
        crediting it (``PassivityPort.receive``)."""
        port = self.state.passivity
        if isinstance(energy_J, np.ndarray):
            port.receive(energy_J)
            return
        if not port.active[0]:  # on standby: the newest value noted, without the numpy calls
            if energy_J > port.peer_sent_J[0]:  # NaN compares False: nothing noted
                port.peer_sent_J[0] = energy_J
            return
        value = self._peer_energy_J
        value[0] = energy_J
        port.receive(value)

    def follow_gain_ratio(self, gain_ratio: np.ndarray) -> None:
        """The master's governed k/k0 per lane ((lanes,)), as the lockstep's handle line
        carries it: the node's inputs are scaled by it from the next step (the program's
        lane follows ``HandleState.gain_k`` in :meth:`supervise` instead, :meth:`follow_gain`)."""
        state = self.state
        if state.gain_ratio is None:
            state.gain_ratio = np.array(gain_ratio, float)  # once: later ticks write in place
        else:
            state.gain_ratio[...] = gain_ratio

    def follow_switch(self, now_s: float, lanes: Sequence[int],
                      flag_values: Sequence[int]) -> None:
        """A standby passivity layer (``paper`` mode) follows the master's
        :attr:`Flags.TDPA_SWITCHED` in the admitted messages of ``lanes`` (their flags as
        ints): on while it is set, off while it is clear (an event ``tdpa_on``/``tdpa_off``
        on the lane's supervisor)."""
        port = self.state.passivity
        if port is None:
            return
        active = port.active
        for lane, flags in zip(lanes, flag_values, strict=True):
            on = bool(int(flags) & _TDPA_SWITCHED)
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
        Returns the last step's output; the earlier steps advance the node without building
        outputs nobody reads (``SlaveNode.advance``: the same state)."""
        steps = plan or (None,)
        catch_up = self._catch_up
        if catch_up is not None and catch_up.applies(self.state):
            return self._catch_up_samples(catch_up, steps)
        fh, yh, scale = self.handle_force_N, self.handle_position_m, self.force_scale
        newest = (fh[0, 0], fh[0, 1], yh[0, 0], yh[0, 1], scale[0])
        for sample in steps[:-1]:
            if sample is not None:
                fh[0, 0], fh[0, 1], yh[0, 0], yh[0, 1], scale[0] = sample
            self.node.advance(self.state, self._force(), yh)
        sample = steps[-1]
        if sample is not None:
            fh[0, 0], fh[0, 1], yh[0, 0], yh[0, 1], scale[0] = sample
        ticked = self.control()
        fh[0, 0], fh[0, 1], yh[0, 0], yh[0, 1], scale[0] = newest
        return ticked

    def _catch_up_samples(self, catch_up: CatchUpStep, steps: Sequence[Step]
                          ) -> SlaveTickOutput:
        """:meth:`control_samples` in one launch (slave_sim/catch_up.py): the same state, the
        same outputs and flags. The samples go to the launch as they are (the tick's own
        arrays keep the newest input throughout: nothing to restore)."""
        if None in steps:  # the tick's own input
            fh, yh, scale = self.handle_force_N, self.handle_position_m, self.force_scale
            newest = (fh[0, 0], fh[0, 1], yh[0, 0], yh[0, 1], scale[0])
            steps = [newest if sample is None else sample for sample in steps]
        return self._ticked(catch_up.step(self.state, steps, not self.running[0],
                                          self.handle_position_m))

    def _force(self) -> np.ndarray:
        """The node's handle force input (lanes, 2), N: the bounded handle force where the
        tool runs, zero elsewhere."""
        running = self.running
        if self.lanes == 1:  # the program's lane: Python scalars are cheaper than numpy calls
            return self.handle_force_N if running[0] else self._zero_force
        if (count := np.count_nonzero(running)) == self.lanes:
            return self.handle_force_N
        if not count:
            return self._zero_force
        return np.where(running[:, None], self.handle_force_N, 0.0)

    def control(self) -> SlaveTickOutput:
        """The node stage: Ch2/Ct2, the tool and the environment, with the bounded handle
        force where the tool runs and zero force elsewhere."""
        return self._ticked(self.node.step(self.state, self._force(), self.handle_position_m))

    def _ticked(self, out: SlaveOutputs) -> SlaveTickOutput:
        """The tick's output of the node's outputs ``out``: the flags to send with them."""
        running = self.running
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

    def configure_lane(self, pacing: MasterSamplePacing | None = None) -> SlaveLaneOutputs:
        """Set up :meth:`step_lane` for a tick of one lane (a program's, a real-link cell's):
        ``pacing``: one node step per master sample (slave_sim/pacing.py; None: one step
        every tick with the tick's own input). Returns the outputs record each step
        refills."""
        link = one_lane_passivity(self.lanes, self.node)
        outputs = SlaveLaneOutputs(flags=FLAGS_BY_VALUE[0])
        self._lane = _LaneSetup(pacing, link, int(link.flags), outputs)
        return outputs

    def first_output(self) -> SlaveLaneOutputs:
        """The node's output before the first tick (one step: the tool at rest, waiting for
        the master), which the first ticks send while no master sample has come."""
        lane = self._lane
        self._node_part(lane, ())
        return lane.outputs

    def step_lane(self, inputs: SlaveLaneInputs,
                  clock_ns: Callable[[], int] | None = None) -> SlaveLaneOutputs:
        """One whole tick of the one lane (:meth:`configure_lane`): the peer's control mode
        checked, the guard and the supervisor (every message delivered with the newest is a
        sample of its own), the master's handed-over energy, then the node: once per master
        sample while the tool runs (none while the master's next sample has not come, more
        after a gap; the last outputs stay), or once a tick without pacing. Returns the
        outputs record, refilled (``supervised_ns``: ``clock_ns()`` at the end of the
        supervise part, 0 without a clock). Raises ``LinkOpenError`` for a master in the
        other ``[control]`` mode."""
        lane = self._lane
        outputs = lane.outputs
        message = inputs.message
        if message is not None:  # a peer in the other [control] mode: refused
            lane.passivity.check(message)
        fresh = outputs.fresh = self._supervise_lane(
            inputs.now_s, message, inputs.silence_s, inputs.peer_alive,
            None if lane.pacing is None else inputs.earlier)
        state = self.state
        if fresh and state.passivity is not None:  # the master's handed-over energy
            self.receive_peer_energy(lane.passivity.peer_energy(state.passivity, message))
        outputs.supervised_ns = clock_ns() if clock_ns is not None else 0
        pacing = lane.pacing
        if pacing is None:
            self._node_part(lane, ())
            outputs.node_steps = 1
        else:
            plan = pacing.plan(bool(self.running[0]), self.samples[0])
            if plan or outputs.ticked is None:  # each step with its own sample's force
                self._node_part(lane, plan)
                outputs.node_steps = max(len(plan), 1)
            else:
                outputs.node_steps = 0
        outputs.node_end_ns = clock_ns() if clock_ns is not None else 0
        return outputs

    def note_node_time(self) -> None:
        """Record the last :meth:`step_lane`'s node part (its steps and its time from
        ``supervised_ns`` to ``node_end_ns``) in :attr:`node_times` (the program's summary's
        ``node_times``); nothing without a clock. Called after the timed stages (the
        program's telemetry), so the record costs none of them."""
        outputs = self._lane.outputs
        if outputs.node_end_ns:
            self.node_times.record(outputs.node_steps,
                                   outputs.node_end_ns - outputs.supervised_ns)

    def _node_part(self, lane: _LaneSetup, plan: Sequence[Step]) -> None:
        """The node stage over ``plan`` (at least one step) into the outputs record, with the
        virtual world's time (node steps x Ts) and the message fields to send."""
        outputs = lane.outputs
        ticked = outputs.ticked = self.control_samples(plan)
        outputs.sample_time_s += max(len(plan), 1) * self.node.sample_period_s
        outputs.flags = FLAGS_BY_VALUE[int(ticked.flag_values[0]) | lane.flag_value]
        outputs.echo_send_time_ns = int(self.echo_send_time_ns[0])
        outputs.energy_J = lane.passivity.sent_J(self.state)


@dataclass(slots=True)
class SlaveLaneInputs:
    """One tick's inputs of one lane (:meth:`SlaveTick.step_lane`), refilled in place by the
    poll stage: ``now_s``: the tick's time, s; ``message``: the fresh ``HandleState`` or
    None; ``earlier``: the older messages delivered with it, in order; ``silence_s``: time
    since the last fresh message, s; ``peer_alive``: the master's liveliness."""

    now_s: float = 0.0
    message: HandleState | None = None
    earlier: Sequence[HandleState] = ()
    silence_s: float = math.inf
    peer_alive: bool = True


@dataclass(slots=True)
class SlaveLaneOutputs:
    """One tick's outputs of one lane (:meth:`SlaveTick.step_lane`), refilled in place:
    ``fresh``: the message was an input; ``ticked``: the node's last outputs (the tool's
    force, position, velocity; None before the first step), sent again while the master's
    next sample has not come; ``sample_time_s``: the virtual world's time, s (node steps x
    Ts); ``flags``: the message's to the master (the mode's TDPA flag included);
    ``echo_send_time_ns``: the newest admitted handle message's send time, ns (0: none);
    ``energy_J``: this side's handed-over energy to send, J; ``supervised_ns``: the clock at
    the end of the supervise part, ns (0: not taken); ``node_steps``: the node steps of the
    tick; ``node_end_ns``: the clock at the end of the node part, ns (0: not taken)."""

    fresh: bool = False
    ticked: SlaveTickOutput | None = None
    sample_time_s: float = 0.0
    flags: Flags = Flags(0)
    echo_send_time_ns: int = 0
    energy_J: float = 0.0
    supervised_ns: int = 0
    node_steps: int = 0
    node_end_ns: int = 0


@dataclass(frozen=True, slots=True)
class _LaneSetup:
    """:meth:`SlaveTick.configure_lane`'s: the pacing, the passivity layer's wire side (its
    mode's flag as an int: or'ed, one lookup a tick) and the outputs record."""

    pacing: MasterSamplePacing | None
    passivity: PassivityLink
    flag_value: int
    outputs: SlaveLaneOutputs
