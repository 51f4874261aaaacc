"""One tick of the master, with the I/O passed in: supervise, then the node (or the hold).

The program (master/program.py) and the lockstep simulator (lockstep/simulator.py) both run
their ticks through :class:`MasterTick`, so the simulator that checks the analysis runs the
supervisor and the node exactly as they ship (docs/architecture.md, "one tick"):

    read  -> poll -> supervise -> node -> write / send -> telemetry
    (caller) (caller) MasterTick.supervise  MasterTick.control  (caller)

:meth:`MasterTick.supervise` feeds each lane's :class:`~haptic.master.supervisor.
MasterSupervisor` (watchdog, resync check, fault latch) and (re)activates the node's lanes
whose forces come on. :meth:`MasterTick.control` steps the node's safety layer and Ch1/Ct1
for the lanes whose forces are enabled and returns what the node used
(:class:`MasterTickOutput`): the command, the handle force and the tool force the compensator
used (saturated, scaled by the force ramp), the ramp's scale, and the flags to send. Lanes
whose forces are off hold the supervisor's ``hold_m`` and send no force. What the node takes
from the slave's message and the governor besides the reading (the slave's handed-over
energy, the tool's position as the drift correction's target, k/k0) are
:meth:`MasterTick.control`'s inputs, for the program's lane and the simulator's lanes alike,
so neither writes the node's state itself.

The program has one lane; the simulator one lane per cell of a sweep (the node is one Warp
kernel over every lane; one supervisor per lane). :meth:`MasterTick.supervise` is the one way
in: the simulator's quiet-lane filter (lockstep/quiet_lanes.py) calls it on the lanes whose
supervisor has something to do, the program on its one lane.

One lane's whole tick is one call, :meth:`MasterTick.step_lane` (the programs and the
real-link cells, on the one tick driver: common/runtime/tick_driver.py): its inputs
(:class:`MasterLaneInputs`: the reading, the delivered message, the link's times) in, its
outputs (:class:`MasterLaneOutputs`: what the node used, k, the flags and the energy to send)
out, with the governor, the passivity layer's account of the slave's energy, the drift
correction's target and the flags inside it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from haptic.common.model.block_kernels import write_exchange_inputs
from haptic.common.runtime.lane_tick import UNCONFIGURED_LANE, TickFlags, one_lane_passivity
from haptic.common.wire.lane_flags import lane_flag_values
from haptic.common.wire.messages import FLAGS_BY_VALUE, Flags, ToolState
from haptic.common.wire.passivity_link import PassivityLink
from haptic.master.margin_governor import MarginGovernor
from haptic.master.node import MasterNode, MasterNodeState
from haptic.master.program_governor import governor_step
from haptic.master.supervisor import MasterSupervisor, Transition

#: Flag values (IntFlag arithmetic costs about 1 us per operation, too much per lane and
#: tick in a sweep): the message to the slave carries FORCES_ENABLED or SAFE_STATE, and
#: TDPA_SWITCHED while the governor has the layer switched on.
_FORCES_ENABLED = int(Flags.FORCES_ENABLED)
_SAFE_STATE = int(Flags.SAFE_STATE)
_TDPA_SWITCHED = int(Flags.TDPA_SWITCHED)


def _flag_value(enabled: Any, switched: Any) -> Any:
    """The flags of the program's one lane's message to the slave, as an int (Python bools):
    FORCES_ENABLED where forces are on, else SAFE_STATE, and TDPA_SWITCHED where the governor
    has the layer switched on (the bits are disjoint). Many lanes: ``lane_flag_values``."""
    return (_SAFE_STATE + (_FORCES_ENABLED - _SAFE_STATE) * enabled
            + _TDPA_SWITCHED * switched)


@dataclass
class MasterTickOutput(TickFlags):
    """What one tick decided, per lane (arrays have the lanes first; views the next tick
    overwrites). ``command_m`` (lanes, 2): the handle command, m; ``handle_force_used_N`` and
    ``tool_force_used_N`` (lanes, 2): the forces the compensator used, N (zero where forces
    are off): the first goes to the slave's Ch2, the second is what the operator feels;
    ``force_scale`` (lanes,): the force ramp's factor 0..1; ``enabled`` (lanes,) bool;
    ``flag_values`` (lanes,) int: the flags of the message to the slave (:attr:`flags` as
    ``Flags``)."""

    command_m: np.ndarray
    handle_force_used_N: np.ndarray
    tool_force_used_N: np.ndarray
    force_scale: np.ndarray
    enabled: np.ndarray
    flag_values: np.ndarray


class MasterTick:
    """The master's supervise and node stages for ``len(supervisors)`` lanes."""

    def __init__(self, node: MasterNode, supervisors: Sequence[MasterSupervisor]) -> None:
        if not supervisors:
            raise ValueError("at least one supervisor (lane)")
        self.node = node
        self.supervisors = list(supervisors)
        self.lanes = len(self.supervisors)
        #: the node's state: None until the forces first come on, then the same object for
        #: the rest of the run ((re)activations set it afresh in place)
        self.state: MasterNodeState | None = None
        #: :meth:`prepare`'s state, the first activation's to fill in place
        self._prepared: MasterNodeState | None = None
        #: the tick time (s) at which the node's state last started afresh in every lane: its
        #: events' times count from here
        self.node_offset_s = 0.0
        lanes = self.lanes
        self.enabled = np.zeros(lanes, bool)
        self._command = np.zeros((lanes, 2))
        self._handle_used = np.zeros((lanes, 2))
        self._tool_used = np.zeros((lanes, 2))
        self._scale = np.zeros(lanes)
        #: the newest received tool force per lane (zero before the first message), N
        self.tool_force_N = np.zeros((lanes, 2))
        #: each supervisor's ``hold_m`` (lanes, 2), m
        self._hold = np.zeros((lanes, 2))
        self._flag_values = np.zeros(lanes, np.int64)
        self._pending_events: list[tuple[float, Any]] = []
        self._none_switched = np.zeros(lanes, bool)
        #: (lanes,) where the governor has the standby passivity layer switched on
        self.standby_active = np.zeros(lanes, bool)
        #: the switch's events (``tdpa_on``/``tdpa_off``), for the program's event list
        self.passivity_events: list[dict[str, Any]] = []
        #: Ah1 per lane and axis (lanes, 2): the drift correction's target is the tool's
        #: position over it (the tool in handle coordinates); the program's lane reads its
        #: supervisor's ``ratio_x``/``ratio_y``, the same numbers
        self._position_ratio = np.array([(s.ratio_x, s.ratio_y) for s in self.supervisors])

    #: the one lane's whole-tick setup (:meth:`configure_lane`)
    _lane: _LaneSetup = UNCONFIGURED_LANE

    def start(self, position_m: Any, synced: bool = False) -> None:
        """Hold each lane where its handle is ((lanes, 2) or (2,), m). With ``synced`` the
        link counts as up and in sync before the first tick (the lockstep's warm start): the
        forces are on from tick 0 and the node is activated here (its small-force gate
        applies), as the first ``ACTIVATE`` would."""
        position = np.broadcast_to(np.asarray(position_m, float), (self.lanes, 2))
        for lane, supervisor in enumerate(self.supervisors):
            supervisor.start(position[lane])
            self._hold[lane] = supervisor.hold_m
            if synced:
                supervisor.start_synced()
        if synced:
            self.state = self.node.initial_state(np.nan_to_num(position))
            self.enabled[:] = True

    def prepare(self, position_m: Any) -> None:
        """Make the node state the first activation fills in place, at ``position_m`` ((lanes,
        2) or (2,), m), and launch its kernels once: before the loop, since allocating its
        buffers and recording and first running its launches cost 0.25-1.1 ms, more than a
        tick. Later (re)activations set that same state afresh in place."""
        position = np.nan_to_num(np.broadcast_to(np.asarray(position_m, float), (self.lanes, 2)))
        state = self.node.initial_state(position)
        self.node.step_inputs(state)  # the kernels' first launches, on nothing that is used
        self._prepared = state

    def supervise(self, now_s: float, messages: Sequence[ToolState | None],
                  handle_position_m: np.ndarray, faults: Sequence[Sequence[str]] | None = None,
                  cycle: int = 0, silence_s: Sequence[float] | None = None,
                  peer_alive: Sequence[bool] | None = None,
                  lanes: Sequence[int] | None = None) -> list[Transition]:
        """Feed the supervisors of ``lanes`` (default: every lane; the others are left as they
        are). Per lane: ``messages``, the fresh ``ToolState`` or ``None``;
        ``handle_position_m`` (lanes, 2), m; ``faults``, the hardware's; ``silence_s``, time
        since the last fresh message, s; ``peer_alive``, the slave's liveliness. Lanes whose
        forces come on start the node afresh at their position (``ACTIVATE``: the node's
        small-force gate; ``RESUME``: the forces ramp in). Returns the transition of each lane
        fed, in the order of ``lanes``."""
        position = np.asarray(handle_position_m, float)
        rows = position.tolist()  # floats: the supervisors are plain Python
        supervisors = self.supervisors
        fed = range(self.lanes) if lanes is None else lanes
        transitions = [
            supervisors[lane].update(now_s, messages[lane], rows[lane],
                                     () if faults is None else faults[lane], cycle,
                                     0.0 if silence_s is None else float(silence_s[lane]),
                                     True if peer_alive is None else peer_alive[lane])
            for lane in fed]
        enabled = self.enabled
        renew = False
        for lane, transition in zip(fed, transitions, strict=True):
            supervisor = supervisors[lane]
            enabled[lane] = supervisor.enabled
            tool = supervisor.tool
            if tool is not None:  # element by element: cheaper than a row from a tuple
                tool_force = self.tool_force_N
                tool_force[lane, 0], tool_force[lane, 1] = tool.tool_force_N
            if transition is Transition.HOLD:
                self._hold[lane] = supervisor.hold_m
            elif transition is Transition.ACTIVATE or transition is Transition.RESUME:
                renew = True
        if renew:
            activate = np.zeros(self.lanes, bool)
            resume = np.zeros(self.lanes, bool)
            for lane, transition in zip(fed, transitions, strict=True):
                activate[lane] = transition is Transition.ACTIVATE
                resume[lane] = transition is Transition.RESUME
            self._renew(now_s, np.nan_to_num(position), activate, resume)
        return transitions

    def _supervise_lane(self, now_s: float, message: ToolState | None,
                        handle_position_m: np.ndarray, faults: Sequence[str], cycle: int,
                        silence_s: float, peer_alive: bool) -> Transition:
        """:meth:`supervise` of the one lane (:meth:`step_lane`) without the per-lane lists
        (the same calls in the same order, the same state); returns its transition."""
        position = np.asarray(handle_position_m, float)
        supervisor = self.supervisors[0]
        transition = supervisor.update(now_s, message, position.tolist()[0], faults, cycle,
                                       float(silence_s), peer_alive)
        self.enabled[0] = supervisor.enabled
        tool = supervisor.tool
        if tool is not None:  # element by element: cheaper than a row from a tuple
            tool_force = self.tool_force_N
            tool_force[0, 0], tool_force[0, 1] = tool.tool_force_N
        if transition is Transition.HOLD:
            self._hold[0] = supervisor.hold_m
        elif transition is Transition.ACTIVATE or transition is Transition.RESUME:
            self._renew(now_s, np.nan_to_num(position),
                        np.array([transition is Transition.ACTIVATE]),
                        np.array([transition is Transition.RESUME]))
        return transition

    def _renew(self, now_s: float, position_m: np.ndarray, activate: np.ndarray,
               resume: np.ndarray) -> None:
        """Start the node afresh, in place, in the ``activate`` and ``resume`` lanes at
        ``position_m`` (lanes, 2), m. When every lane starts afresh (or the state is the run's
        first) the whole state does, and its events' times count from ``now_s``; otherwise
        the other lanes carry on and only those lanes' rows are set."""
        node, state = self.node, self.state
        if state is None or activate.all() or resume.all():
            first = state is None
            if first:
                state = self._prepared
                self._prepared = None
                if state is None:  # not prepared: made here (allocates)
                    state = node.initial_state(position_m)
            else:  # its events keep their absolute times
                self._pending_events.extend(self.take_node_events())
            every_lane_resumes = bool(resume.all())
            if every_lane_resumes:
                node.resume(state, position_m, continue_run=not first)
            else:
                node.activate(state, position_m, continue_run=not first)
            if node.passivity_standby:  # switched on stays on
                state.passivity.active[...] = self.standby_active
            self.state = state
            self.node_offset_s = now_s
            if every_lane_resumes or not resume.any():
                return
            activate = np.zeros_like(activate)  # done; the resumed lanes follow
        if activate.any():
            node.activate(state, position_m, activate)
        if resume.any():
            node.resume(state, position_m, resume)

    def control(self, handle_force_N: np.ndarray, handle_position_m: np.ndarray,
                tool_force_N: np.ndarray | None = None, tool_energy_J: Any = None,
                tool_position_m: Any = None, gain_ratio: Any = None) -> MasterTickOutput:
        """The node stage: vh = Ch1 fh - Ct1 ft behind the safety layer for the lanes whose
        forces are on (``tool_force_N`` (lanes, 2), N: the received tool force, by default
        the supervisors' newest ``ToolState``'s); the others hold ``hold_m``. A trip of the
        node's safety layer latches that lane's supervisor. Returns what the node used.

        The node's inputs from the peer and the governor, the same for the program's lane and
        the lockstep's lanes: ``tool_energy_J``, the slave's cumulative handed-over energy, J
        (the passivity layer's account; a node with the layer), with ``tool_position_m``, the
        received tool position, m, whose image in handle coordinates (over Ah1) is the drift
        correction's target; ``gain_ratio``, the governed k/k0. Each is (lanes,) or
        (lanes, 2) arrays, or for a one-lane tick a float and an (x, y) pair; None leaves the
        node's value as it is. Written only where a lane's forces are on (a lane coming on
        starts them afresh)."""
        enabled = self.enabled
        state = self.state
        outputs = None
        if tool_force_N is None:
            tool_force_N = self.tool_force_N
        if self.lanes == 1:  # the program's lane: Python scalars are cheaper than numpy calls
            any_on = all_on = bool(enabled[0])
        else:
            on = np.count_nonzero(enabled)  # one cheap call instead of any() and all()
            any_on, all_on = on > 0, on == self.lanes
        if state is not None and any_on:
            if gain_ratio is not None:  # k on the master now (the slave's with the message)
                state.gain_ratio[...] = gain_ratio
            if tool_energy_J is not None:
                state.peer_energy_J[...] = tool_energy_J
                target = state.peer_target_m
                if isinstance(tool_position_m, np.ndarray):
                    np.divide(tool_position_m, self._position_ratio, out=target)
                else:  # the program's lane, Python floats
                    supervisor = self.supervisors[0]
                    target[0, 0] = tool_position_m[0] / supervisor.ratio_x
                    target[0, 1] = tool_position_m[1] / supervisor.ratio_y
            write_exchange_inputs(state.inputs, handle_force_N, handle_position_m, tool_force_N)
            events_before = len(state.events)
            self.node.step_inputs(state)
            if all_on:  # the node's own arrays, which its next step overwrites
                outputs = (state.command_m, state.handle_force_used_N,
                           state.tool_force_used_N, state.force_scale)
            else:  # the off lanes' steps do not count: they start afresh when forces return
                state.events[events_before:] = [event for event in state.events[events_before:]
                                                if enabled[event.lane]]
                self._command[...] = np.where(enabled[:, None], state.command_m, 0.0)
                self._handle_used[...] = np.where(enabled[:, None], state.handle_force_used_N,
                                                  0.0)
                self._tool_used[...] = np.where(enabled[:, None], state.tool_force_used_N, 0.0)
                self._scale[...] = np.where(enabled, state.force_scale, 0.0)
            faulted = state.faulted
            if faulted[0] if self.lanes == 1 else np.count_nonzero(faulted):
                for lane in np.flatnonzero(enabled & faulted):
                    self.supervisors[lane].note_node_fault()
        else:
            self._handle_used[...] = 0.0
            self._tool_used[...] = 0.0
            self._scale[...] = 0.0
        switched = self._switched()
        if self.lanes == 1:  # the program's lane: Python scalars are cheaper than numpy calls
            on = bool(enabled[0])
            self._flag_values[0] = _flag_value(on, bool(switched[0]))
            if not on:
                self._command[0] = self._hold[0]
        else:
            lane_flag_values(self._flag_values, enabled, ((_TDPA_SWITCHED, switched),))
            if np.count_nonzero(enabled) != self.lanes:
                off = ~enabled
                self._command[off] = self._hold[off]
        if outputs is None:
            outputs = (self._command, self._handle_used, self._tool_used, self._scale)
        return MasterTickOutput(*outputs, enabled, self._flag_values)

    def _switched(self) -> np.ndarray:
        """(lanes,) bool: where the governor has a standby passivity layer switched on."""
        port = self.state.passivity if self.state is not None else None
        if port is None or not self.node.passivity_standby:
            return self._none_switched
        return port.active

    def switched_flags(self) -> list[Flags]:
        """Per lane, :attr:`Flags.TDPA_SWITCHED` where the governor switched the passivity
        layer on (a standby node), else no flag."""
        return [Flags.TDPA_SWITCHED if on else Flags(0) for on in self._switched().tolist()]

    def switch_passivity(self, now_s: float, lanes: np.ndarray, on: bool, reason: str) -> int:
        """Switch the passivity layer on (``on``) or off in ``lanes`` ((lanes,) bool mask) of
        a node built with it on standby (``paper`` mode, the governor's ``tdpa`` action;
        common/model/passivity.py ``PassivityPort.switch``): the messages carry
        :attr:`Flags.TDPA_SWITCHED` while it is on and the slave follows. An event per lane
        that changed (``tdpa_on``/``tdpa_off``, with ``reason``); returns how many did.
        Raises ``RuntimeError`` on a node without a standby layer."""
        if not self.node.passivity_standby:
            raise RuntimeError("the passivity layer can be switched only where it is built "
                               "on standby ([governor] action = \"tdpa\", paper mode)")
        mask = np.asarray(lanes, bool)
        self.standby_active[mask] = on  # a node state made later starts so too
        port = self.state.passivity if self.state is not None else None
        changed = port.switch(mask, on) if port is not None else mask
        for lane in np.flatnonzero(changed):
            self.passivity_events.append({"time_s": now_s, "kind": "tdpa_on" if on else
                                          "tdpa_off", "reason": reason, "lane": int(lane)})
        return int(np.count_nonzero(changed))

    def take_node_events(self) -> list[tuple[float, Any]]:
        """The node's safety events since the last call, each with its absolute tick time
        (s: ``node_offset_s`` plus the event's own time); they are removed from the state."""
        state = self.state
        if not self._pending_events and (state is None or not state.events):
            return []
        taken, self._pending_events = self._pending_events, []
        if state is not None and state.events:
            taken.extend((self.node_offset_s + event.time_s, event) for event in state.events)
            state.events.clear()
        return taken

    def configure_lane(self, nominal_k: float, governor: MarginGovernor | None = None,
                       allow_unstable: bool = False) -> MasterLaneOutputs:
        """Set up :meth:`step_lane` for a tick of one lane (a program's, a real-link cell's):
        ``nominal_k`` the Ch1 gain the compensators were made for; ``governor`` the margin
        governor (None: k stays nominal); ``allow_unstable``: a round trip beyond the margin
        of every k does not trip the node. Returns the outputs record each step refills."""
        link = one_lane_passivity(self.lanes, self.node)
        outputs = MasterLaneOutputs(gain_k=float(nominal_k), flags=FLAGS_BY_VALUE[0])
        self._lane = _LaneSetup(float(nominal_k), governor, allow_unstable, link,
                                int(link.flags), outputs)
        return outputs

    def step_lane(self, inputs: MasterLaneInputs,
                  clock_ns: Callable[[], int] | None = None) -> MasterLaneOutputs:
        """One whole tick of the one lane (:meth:`configure_lane`): the peer's control mode
        checked, the supervisor, the governor (k, the passivity layer's switch, its trip), the
        slave's handed-over energy and the drift correction's target, then the node. Returns
        the outputs record, refilled (``supervised_ns``: ``clock_ns()`` at the end of the
        supervise part, 0 without a clock). Raises ``LinkOpenError`` for a slave in the other
        ``[control]`` mode."""
        lane = self._lane
        outputs = lane.outputs
        message = inputs.message
        if message is not None:  # a peer in the other [control] mode: refused
            lane.passivity.check(message)
        now_s = inputs.now_s
        position = inputs.handle_position_m
        outputs.transition = self._supervise_lane(now_s, message, position, inputs.faults,
                                                  inputs.cycle, inputs.silence_s,
                                                  inputs.peer_alive)
        supervisor = self.supervisors[0]
        outputs.enabled = enabled = supervisor.enabled
        if lane.governor is None:
            outputs.gain_k, gain_ratio = lane.nominal_k, None
        else:
            gain_k = outputs.gain_k = self._govern(lane, inputs, enabled)
            gain_ratio = gain_k / lane.nominal_k
        outputs.supervised_ns = clock_ns() if clock_ns is not None else 0
        state = self.state
        tool = outputs.tool = supervisor.tool
        energy_J = tool_position = None
        if state is not None and state.passivity is not None and tool is not None:
            # the slave's handed-over energy and its tool, which the node takes as the lockstep's
            energy_J = lane.passivity.peer_energy(state.passivity, tool)
            tool_position = tool.tool_position_m
        # the node reports what it used: the slave's Ch2 integrates exactly the handle force
        # Ch1 used; the operator feels the tool force it used
        used = outputs.used = self.control(inputs.handle_force_N, position, None, energy_J,
                                           tool_position, gain_ratio)
        outputs.flags = FLAGS_BY_VALUE[int(used.flag_values[0]) | lane.flag_value]
        outputs.energy_J = lane.passivity.sent_J(self.state)
        return outputs

    def _govern(self, lane: _LaneSetup, inputs: MasterLaneInputs, enabled: bool) -> float:
        """The governor's tick (master/program_governor.py): k from the echoed round trip,
        the standby passivity layer switched as it asks, and a trip beyond every margin.
        Returns k (the node takes k/k0 in :meth:`control`)."""
        governor = lane.governor
        assert governor is not None
        now_s = inputs.now_s
        decision = governor_step(governor, inputs.latest, inputs.first_sent_ns,
                                 inputs.last_sent_ns, inputs.poll_ns, now_s)
        gain_k = decision.gain_k
        if decision.mode_request is not None and self.node.passivity_standby:
            # the passivity layer on or off; the slave follows the flag
            self.switch_passivity(now_s, _ONE_LANE, decision.mode_request == "tdpa",
                                  governor.events[-1]["reason"] if governor.events
                                  else "governor")
        if enabled and decision.beyond_margin and not lane.allow_unstable:
            self.node.trip(self.state, [0], "governor: round trip beyond the delay margin of "
                           "every k")
        return gain_k


#: one lane, as a mask (MasterTick.switch_passivity)
_ONE_LANE = np.ones(1, bool)


@dataclass(slots=True)
class MasterLaneInputs:
    """One tick's inputs of one lane (:meth:`MasterTick.step_lane`), refilled in place by the
    read and poll stages. ``now_s``: the tick's time, s; ``handle_force_N`` and
    ``handle_position_m`` (1, 2): the handle's reading, N and m; ``faults``: the hardware's;
    ``cycle``: the reading's cycle; ``message``: the fresh ``ToolState`` or None; ``latest``:
    the newest delivered so far (its echo feeds the governor); ``silence_s``: time since the
    last fresh message, s; ``peer_alive``: the slave's liveliness; ``first_sent_ns``,
    ``last_sent_ns``: this side's first and newest handle message's send time, and
    ``poll_ns``: the poll's time (CLOCK_REALTIME ns)."""

    now_s: float = 0.0
    handle_force_N: np.ndarray = field(default_factory=lambda: np.zeros((1, 2)))
    handle_position_m: np.ndarray = field(default_factory=lambda: np.zeros((1, 2)))
    faults: Sequence[str] = ()
    cycle: int = 0
    message: ToolState | None = None
    latest: ToolState | None = None
    silence_s: float = math.inf
    peer_alive: bool = True
    first_sent_ns: int = 0
    last_sent_ns: int = 0
    poll_ns: int = 0


@dataclass(slots=True)
class MasterLaneOutputs:
    """One tick's outputs of one lane (:meth:`MasterTick.step_lane`), refilled in place:
    ``transition``: the supervisor's; ``used``: what the node used (command, forces, scale;
    None before the first tick); ``gain_k``: the Ch1 gain k of this tick; ``flags``: the
    message's to the slave (the mode's TDPA flag included); ``energy_J``: this side's
    handed-over energy to send, J; ``tool``: the supervisor's newest ``ToolState``;
    ``enabled``: the supervisor's forces on after its update (before a trip in the node
    part); ``supervised_ns``: the clock at the end of the supervise part, ns (0: not
    taken)."""

    transition: Transition = Transition.NONE
    enabled: bool = False
    used: MasterTickOutput | None = None
    gain_k: float = 0.0
    flags: Flags = Flags(0)
    energy_J: float = 0.0
    tool: ToolState | None = None
    supervised_ns: int = 0


@dataclass(frozen=True, slots=True)
class _LaneSetup:
    """:meth:`MasterTick.configure_lane`'s: the nominal k, the governor and its trip, the
    passivity layer's wire side (its mode's flag as an int: or'ed, one lookup a tick) and
    the outputs record."""

    nominal_k: float
    governor: MarginGovernor | None
    allow_unstable: bool
    passivity: PassivityLink
    flag_value: int
    outputs: MasterLaneOutputs
