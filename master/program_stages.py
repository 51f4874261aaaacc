"""The networked master's tick stages (``haptic-master``), run by the one tick driver
(common/runtime/tick_driver.py)::

    read       hardware.read()                 -> inputs: fh, yh, faults, cycle, time
    poll       link.poll()                     -> inputs: message, newest, silence, peer,
                                                  send and poll times (the governor's echo)
    supervise  MasterTick.step_lane(inputs)    -> outputs: transition, k, energy, flags,
    node                                          what the node used (master/tick.py)
    write      hardware.write(command)         <- outputs (and the transition's drive calls)
    send       link.send_handle(...)           <- outputs
    telemetry  events, inert, trace, recording, display, status, ROS 2

Each stage talks to one thing (the hardware, the link, the tick, the run's records) through
the lane's input and output records (``MasterLaneInputs``, ``MasterLaneOutputs``), filled in
place: nothing is built per tick but what the records, the display and ROS 2 ask for at
their own rates.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from haptic.common.model.passivity import passivity_summary
from haptic.common.records.run_recording import RunRecording
from haptic.common.records.trace import TraceRecorder
from haptic.common.runtime.inert import InertMonitor
from haptic.common.runtime.linked_side import LinkedSide
from haptic.common.runtime.program_harness import ProgramHarness
from haptic.common.runtime.tick_driver import Stage
from haptic.common.wire.link import Link
from haptic.common.wire.messages import Flags
from haptic.master.hardware.interface import HandleHardware, HandleReading
from haptic.master.margin_governor import MarginGovernor
from haptic.master.supervisor import MasterSupervisor, Transition
from haptic.master.tick import MasterLaneInputs, MasterTick

#: The stages of one tick, in order (the summary's ``stages``).
TICK_STAGES = ("read", "poll", "supervise", "node", "write", "send", "telemetry")

MASTER_TRACE_COLUMNS = (
    "time_s", "handle_force_x_N", "handle_force_y_N", "handle_position_x_m",
    "handle_position_y_m", "tool_force_x_N", "tool_force_y_N", "tool_position_x_m",
    "tool_position_y_m", "command_x_m", "command_y_m", "forces_enabled",
)

#: A position nobody measured, m (what the trace and the recording show without a tool).
_NO_POSITION = (math.nan, math.nan)


def position_for_the_wire(position_m: tuple[float, float],
                          last_m: tuple[float, float]) -> tuple[float, float]:
    """The handle position (m) to send: the reading where both axes are finite, else the last
    finite one. A missed PDO reads NaN; the node trips on it (master/node.py) and the message
    says SAFE_STATE, but a NaN can never go on the wire (messages.encode refuses it)."""
    x_m, y_m = position_m
    if math.isfinite(x_m) and math.isfinite(y_m):
        return position_m
    return last_m


class LinkedMasterStages(LinkedSide):
    """The networked master's side of the tick driver (see the module docstring; what both
    sides hold: common/runtime/linked_side.py).

    ``tick``: the master's tick (its lane is configured here: ``nominal_k`` the Ch1 gain,
    ``governor`` the margin governor it steps, None: none, ``allow_unstable``: no trip
    beyond every margin; master/tick.py ``MasterTick.configure_lane``); ``trace``: the
    trace kept every N ticks; ``recording``: the run's MCAP recording or None; ``inert``:
    the monitor of forces that stay off; ``events``: the run's node, hardware and passivity
    events (the summary's); ``ros2``: the ROS 2 publisher or None.
    """

    stage_names = TICK_STAGES
    schedule_shift_ns = 0  # the master follows no peer's phase
    tick: MasterTick
    supervisor: MasterSupervisor

    def __init__(self, hardware: HandleHardware, link: Link, tick: MasterTick,
                 harness: ProgramHarness, nominal_k: float, governor: MarginGovernor | None,
                 allow_unstable: bool, trace: TraceRecorder, recording: RunRecording | None,
                 inert: InertMonitor, events: list[dict[str, Any]], ros2: Any | None,
                 clock_ns: Callable[[], int] = time.perf_counter_ns) -> None:
        super().__init__(link, tick, harness, trace, recording, inert, ros2, clock_ns)
        self.hardware = hardware
        self.governor = governor
        self.events = events
        self.inputs = MasterLaneInputs()
        self.outputs = tick.configure_lane(nominal_k, governor, allow_unstable)
        self.reading: HandleReading | None = None
        self.last_fh = (0.0, 0.0)
        self.last_ft = (0.0, 0.0)
        #: the last handle position measured on both axes, m (what the wire carries while a
        #: reading is missing)
        self.last_yh = (0.0, 0.0)
        #: the handle force sent in the last tick, N
        self.sent = [0.0, 0.0]
        watchdog = self.supervisor.watchdog
        self._event_lists: tuple[list[Any], ...] = (
            watchdog.events, self.supervisor.events, events,
            governor.events if governor is not None else [])
        safety = tick.node.safety
        self._gate_reason = (f"the start-up gate waits for |fh| < "
                             f"{safety.ramp_small_force_N:g} N "
                             f"({safety.ramp_small_samples} samples): the operator pushes")

    def stages(self) -> tuple[Stage, ...]:
        """read, poll, the whole tick (supervise | node), write, send, telemetry."""
        return (self.read, self.poll, self.step_tick, self.write, self.send, self.telemetry)

    def start(self, reading: HandleReading) -> None:
        """Before the first tick: the drives' reading right after their enable (the first
        tick takes it), the loop's hold where they hold the handle."""
        self.reading = reading
        self.tick.start(reading.position_m)
        self.last_yh = position_for_the_wire(
            tuple(reading.position_m.tolist()), tuple(np.nan_to_num(reading.position_m).tolist()))

    def read(self, tick: int, now_ns: int) -> None:
        """This SYNC's handle force and position (tick 0: :meth:`start`'s reading), and the
        tick's time."""
        if tick > 0:
            self.reading = self.hardware.read()
        reading = self.reading
        inputs = self.inputs
        inputs.now_s = self.harness.time_s(now_ns)
        inputs.handle_force_N = reading.force_N[None, :]
        inputs.handle_position_m = reading.position_m[None, :]
        inputs.faults = reading.faults
        inputs.cycle = reading.cycle

    def poll(self, tick: int, now_ns: int) -> None:
        """The newest tool message whose delivery time has come, and what the tick needs of
        the link (silence, the slave's liveliness, the send and poll times for the echo)."""
        link = self.link
        inputs = self.inputs
        inputs.message = link.poll()
        inputs.silence_s = link.silence_s()
        inputs.peer_alive = link.peer_alive
        if self.governor is not None:  # the echo's round trip
            inputs.latest = link.latest
            inputs.first_sent_ns = link.first_sent_ns
            inputs.last_sent_ns = link.last_sent_ns
            inputs.poll_ns = link.last_poll_ns

    def step_tick(self, tick: int, now_ns: int) -> int:
        """The whole tick (master/tick.py); returns the clock at its supervise | node
        boundary."""
        return self.tick.step_lane(self.inputs, self.clock_ns).supervised_ns

    def write(self, tick: int, now_ns: int) -> None:
        """The handle command (and, on a simulated rig, the felt force); on a transition, the
        forces' state shown, the drives' quick stop or their re-enable."""
        outputs = self.outputs
        hardware = self.hardware
        transition = outputs.transition
        if transition is not Transition.NONE:
            hardware.present_forces_enabled(outputs.enabled)
            if transition is Transition.HOLD:  # the drives' quick stop too
                hardware.stop_motion(self.supervisor.stop_reason())
            elif transition is Transition.RESUME:  # re-enabled at actual
                hardware.resume_motion()
        used = outputs.used
        hardware.present_tool_force(used.tool_force_used_N[0])
        hardware.write(used.command_m[0])

    def send(self, tick: int, now_ns: int) -> None:
        """The force the compensator used, the handle position, the flags, k, the energy and
        the force ramp's factor."""
        outputs = self.outputs
        used = outputs.used
        self.last_yh = position_for_the_wire(tuple(self.reading.position_m.tolist()),
                                             self.last_yh)
        self.sent = used.handle_force_used_N[0].tolist()
        self.link.send_handle(self.sent, self.last_yh, outputs.flags, outputs.gain_k,
                              outputs.energy_J, float(used.force_scale[0]))

    def take_events(self) -> None:
        """The node's safety events and the passivity switch's so far into the run's
        events."""
        passivity_events = self.tick.passivity_events
        if passivity_events:
            self.events.extend(passivity_events)
            passivity_events.clear()
        for time_s, event in self.tick.take_node_events():
            axis = f" [{event.axis}]" if event.axis else ""
            self.events.append({"time_s": time_s, "kind": f"node_{event.kind}",
                                "reason": event.reason + axis})

    def telemetry(self, tick: int, now_ns: int) -> None:
        """Events, the inert monitor, the summary's figures, trace, recording, display,
        status and ROS 2 (each at its own rate). One call a tick: its parts are inline, as
        the hand-written ticks had them (a Python call costs a fraction of a microsecond)."""
        reading = self.reading
        inputs = self.inputs
        now_s = inputs.now_s
        if reading.events:  # e.g. a drive's statusword warning bits
            self.events.extend({"time_s": now_s, "kind": "hardware_event", "reason": text}
                               for text in reading.events)
        self.take_events()
        used = self.outputs.used
        enabled = bool(used.enabled[0])
        supervisor = self.supervisor
        self.inert.update(
            now_s, inputs.peer_alive and inputs.silence_s < self._max_age_s,
            enabled and bool(self.tick.state.forces_enabled[0]),
            self._gate_reason if enabled else "node faulted" if supervisor.faulted
            else supervisor.stop_reason() if (supervisor.input_faulted or supervisor.peer_held)
            else f"watchdog {supervisor.watchdog.state.value}: the resync does not complete")
        fhx, fhy = reading.force_N.tolist()
        yhx, yhy = reading.position_m.tolist()
        felt = used.tool_force_used_N[0].tolist()
        magnitude = math.hypot(felt[0], felt[1])
        if magnitude > self.max_force_N:
            self.max_force_N = magnitude
        self.last_fh = (fhx, fhy)
        self.last_ft = felt
        cx, cy = used.command_m[0].tolist()
        tool = self.outputs.tool
        trace = self.trace
        if trace.due():
            tool_pos = tool.tool_position_m if tool is not None else _NO_POSITION
            trace.record((now_s, fhx, fhy, yhx, yhy, felt[0], felt[1], tool_pos[0],
                          tool_pos[1], cx, cy, float(enabled)))
        else:
            trace.skip()
        if self.recording is not None:
            rft, tool_pos = ((tool.tool_force_N, tool.tool_position_m) if tool is not None
                             else (_NO_POSITION, _NO_POSITION))
            sent = self.sent
            self.recording.state(tick, now_ns, (
                now_s, fhx, fhy, yhx, yhy, rft[0], rft[1], felt[0], felt[1],
                tool_pos[0], tool_pos[1], cx, cy, sent[0], sent[1], float(enabled)))
        self.harness.offer_state(tick, lambda: {
            "handle_force_N": [fhx, fhy], "handle_position_m": [yhx, yhy],
            "felt_force_N": [felt[0], felt[1]], "forces_enabled": enabled,
            "safe_state": not enabled})
        governor = self.governor
        if governor is None:
            self.harness.status(tick, now_ns, supervisor.watchdog, self._event_lists,
                                forces_enabled=enabled)
        else:
            self.harness.status(tick, now_ns, supervisor.watchdog, self._event_lists,
                                forces_enabled=enabled, governor_k=governor.gain_k,
                                governor_round_trip_s=governor.rtt_s)
        if self.ros2 is not None:
            self._offer_ros2(tick, now_s, (fhx, fhy), (yhx, yhy), felt, enabled)

    def event_lists(self) -> tuple[list[Any], ...]:
        """The run's event lists: the watchdog's, the supervisor's, the node's and hardware's,
        the governor's (the lists themselves: they grow in place)."""
        return self._event_lists

    def _offer_ros2(self, tick: int, now_s: float, force_N: tuple[float, float],
                    position_m: tuple[float, float], felt: list[float], enabled: bool) -> None:
        """Off the loop: two reference swaps at their rates."""
        supervisor, tick_state = self.supervisor, self.tick.state
        self.ros2.offer(tick, lambda: {
            "time_s": now_s, "force_N": force_N, "position_m": position_m,
            "effort_N": (felt[0], felt[1])}, lambda: {
            **self.link_status(), "forces_enabled": enabled,
            "safe_state": not enabled, "safety_events": len(supervisor.events) + len(
                self.events),
            **(passivity_summary(tick_state.passivity, self.tick.node.passivity_standby)
               if tick_state is not None else {})})

    def gain_k(self) -> float:
        """The Ch1 gain k now (the governor's, else the last tick's, nominal before)."""
        return self.governor.gain_k if self.governor is not None else self.outputs.gain_k

    def stop_safely(self) -> None:
        """Safe state: hold where the handle is, no reflected force, then tell the slave (one
        message with SAFE_STATE | STOPPING: it stops its tool at once and counts no trip)
        before the link closes."""
        hardware = self.hardware
        try:
            final = hardware.read()
            hold = np.nan_to_num(final.position_m)
            hardware.present_tool_force(np.zeros(2))
            hardware.write(hold)
            self.link.send_handle((0.0, 0.0), (float(hold[0]), float(hold[1])),
                                  Flags.SAFE_STATE | Flags.STOPPING
                                  | self.tick.switched_flags()[0],
                                  self.gain_k(), force_scale=0.0)
        except Exception as error:  # noqa: BLE001 - shutting down regardless
            self.harness.say(f"while stopping: {error}")
        self.take_events()

    def status_text(self) -> str:
        """This side's part of the live status line."""
        governor = self.governor
        return self.harness.status_line(
            self.supervisor.watchdog, f"fh {self.last_fh[0]:+.2f} N  ft {self.last_ft[0]:+.2f} "
            f"N{self.inert.status()}{governor.status() if governor is not None else ''}")
