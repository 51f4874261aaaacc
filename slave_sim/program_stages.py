"""The networked slave's tick stages (``haptic-slave``), run by the one tick driver
(common/runtime/tick_driver.py)::

    poll       link.poll()                     -> inputs: message, the older ones delivered
                                                  with it, silence, peer; the delivery time
    supervise  SlaveTick.step_lane(inputs)     -> outputs: fresh, the node's outputs, flags,
    node                                          echo, energy (slave_sim/tick.py); the phase
                                                  lock's schedule shift (an output for the
                                                  runner)
    send       link.send_tool(...)             <- outputs
    telemetry  inert, trace, tool path, recording, display, status, ROS 2

Each stage talks to one thing (the link, the tick, the run's records) through the lane's input
and output records (``SlaveLaneInputs``, ``SlaveLaneOutputs``), filled in place.
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
from haptic.common.wire.phase_lock import PhaseLock
from haptic.slave_sim.pacing import MasterSamplePacing
from haptic.slave_sim.supervisor import SlaveSupervisor
from haptic.slave_sim.tick import SlaveLaneInputs, SlaveTick
from haptic.slave_sim.tool_path import ToolPath

#: The stages of one tick, in order (the summary's ``stages``).
TICK_STAGES = ("poll", "supervise", "node", "send", "telemetry")

SLAVE_TRACE_COLUMNS = (
    "time_s", "handle_force_x_N", "handle_force_y_N", "handle_position_x_m",
    "handle_position_y_m", "tool_position_x_m", "tool_position_y_m", "tool_velocity_x_m_s",
    "tool_velocity_y_m_s", "tool_force_x_N", "tool_force_y_N", "engagement", "cutting",
    "forces_enabled", "sample_time_s",
)
#: ``time_s`` is the wall time since the loop's start; ``sample_time_s`` the slave's virtual
#: world's own (node steps x Ts, slave_sim/pacing.py): the cut's figures are taken on it, so a
#: master that falls behind real time slows the cut on the wall clock, not in the figures.


def removed_total_m3(state: Any) -> float:
    """Clay removed since the start, m^3 (0 for the linear environment)."""
    total = getattr(state.environment, "removed_total_m3", None)
    return 0.0 if total is None else float(total[0])


class SlaveStages(LinkedSide):
    """The networked slave's side of the tick driver (see the module docstring; what both
    sides hold: common/runtime/linked_side.py).

    ``tick``: the slave's tick (its lane is configured here with ``pacing``: one node step
    per master sample; slave_sim/tick.py ``SlaveTick.configure_lane``); ``phase_lock``: the
    slave's phase lock or None; ``trace``, ``tool_path``: what the run keeps every N ticks
    (``path_every``); ``recording``: the run's MCAP recording or None; ``inert``: the
    monitor of a tool that stays stopped; ``ros2``: the ROS 2 publisher or None.
    """

    stage_names = TICK_STAGES
    tick: SlaveTick
    supervisor: SlaveSupervisor

    def __init__(self, link: Link, tick: SlaveTick, harness: ProgramHarness,
                 pacing: MasterSamplePacing, phase_lock: PhaseLock | None,
                 trace: TraceRecorder, tool_path: ToolPath, path_every: int,
                 recording: RunRecording | None, inert: InertMonitor, ros2: Any | None,
                 clock_ns: Callable[[], int] = time.perf_counter_ns) -> None:
        super().__init__(link, tick, harness, trace, recording, inert, ros2, clock_ns)
        self.phase_lock = phase_lock
        self.tool_path = tool_path
        self.path_every = path_every
        self.inputs = SlaveLaneInputs()
        self.outputs = tick.configure_lane(pacing)
        #: the phase lock's correction of the runner's schedule, ns (the driver hands it on)
        self.schedule_shift_ns = 0
        #: the newest delivery's time and the poll's (CLOCK_REALTIME ns), and whether the
        #: delivery time is a measurement (Link.last_delivery_measured)
        self.last_delivery_ns: int | None = None
        self.poll_ns = 0
        self.delivery_measured = False
        self.tool_force_N = np.zeros(2)
        self.engagement = 0.0
        self.removed_m3 = 0.0
        #: yt - Ah1 yh at the last tick the tool ran, m (None: it never ran)
        self.running_gap_m: np.ndarray | None = None
        self._event_lists = (self.supervisor.watchdog.events, self.supervisor.events)
        #: the newest bounded handle force and position, (1, 2) N and m (updated in place)
        self.fh = tick.handle_force_N
        self.yh = tick.handle_position_m

    def stages(self) -> tuple[Stage, ...]:
        """poll, the whole tick (supervise | node), send, telemetry."""
        return (self.poll, self.step_tick, self.send, self.telemetry)

    def first_output(self) -> None:
        """The node's output before the first tick: the tool at rest, waiting for the master
        (what the first tick would step), on the loop's CPU; the first tick then sends it.
        Stepped in the first tick instead, the state's first launches (caches cold) made the
        first ticks overrun."""
        self.tick.first_output()

    def poll(self, tick: int, now_ns: int) -> None:
        """The newest handle message whose delivery time has come, every older one delivered
        with it (each a node step with its own force: slave_sim/pacing.py), and what the tick
        and the phase lock need of the link."""
        link = self.link
        inputs = self.inputs
        inputs.now_s = self.harness.time_s(now_ns)
        inputs.message = link.poll()
        delivered = link.delivered
        inputs.earlier = delivered[:-1] if delivered else ()
        inputs.silence_s = link.silence_s()
        inputs.peer_alive = link.peer_alive
        if inputs.message is not None and self.phase_lock is not None:
            self.delivery_measured = link.last_delivery_measured
            self.last_delivery_ns = link.last_delivery_ns
            self.poll_ns = link.last_poll_ns

    def step_tick(self, tick: int, now_ns: int) -> int:
        """The whole tick (slave_sim/tick.py), then the phase lock on a fresh message;
        returns the clock at the tick's supervise | node boundary."""
        outputs = self.tick.step_lane(self.inputs, self.clock_ns)
        phase_lock = self.phase_lock
        if outputs.fresh and phase_lock is not None:
            if self.delivery_measured:
                self.schedule_shift_ns = phase_lock.update(self.last_delivery_ns, self.poll_ns)
            else:
                phase_lock.skip_unmeasured()
        return outputs.supervised_ns

    def send(self, tick: int, now_ns: int) -> None:
        """The tool force, position and velocity, the clay's status, the flags, the echo and
        the energy."""
        outputs = self.outputs
        out = outputs.ticked.out
        ft = out.tool_force_N[0]
        position = out.tool_position_m[0]
        velocity = out.tool_velocity_m_s[0]
        self.removed_m3 = removed_total_m3(self.tick.state)
        self.link.send_tool((float(ft[0]), float(ft[1])), (float(position[0]), float(position[1])),
                            (float(velocity[0]), float(velocity[1])), float(out.engagement[0]),
                            self.removed_m3, outputs.flags, outputs.echo_send_time_ns,
                            outputs.energy_J)

    def telemetry(self, tick: int, now_ns: int) -> None:
        """The inert monitor, the summary's figures, tool path, trace, recording, display,
        status and ROS 2 (each at its own rate). One call a tick: its parts are inline, as
        the hand-written tick had them (a Python call costs a fraction of a microsecond)."""
        supervisor = self.supervisor
        inputs, outputs = self.inputs, self.outputs
        now_s = inputs.now_s
        running = supervisor.running
        self.inert.update(now_s, inputs.peer_alive and inputs.silence_s < self._max_age_s,
                          running, supervisor.stop_reason())
        out = outputs.ticked.out
        if running:  # yt - Ah1 yh while the tool runs (a stopped tool is re-placed)
            self.running_gap_m = out.tracking_error_m[0]
        ft = out.tool_force_N[0]
        position = out.tool_position_m[0]
        velocity = out.tool_velocity_m_s[0]
        engagement = self.engagement = float(out.engagement[0])
        removed = self.removed_m3
        magnitude = math.hypot(ft[0], ft[1])
        if magnitude > self.max_force_N:
            self.max_force_N = magnitude
        self.tool_force_N = ft
        if tick % self.path_every == 0:
            self.tool_path.add(float(position[0]), float(position[1]))
        fh, yh = self.fh, self.yh
        sample_time_s = outputs.sample_time_s
        if self.trace.due():
            self.trace.record((now_s, fh[0, 0], fh[0, 1], yh[0, 0], yh[0, 1], position[0],
                               position[1], velocity[0], velocity[1], ft[0], ft[1], engagement,
                               float(out.cutting[0]), float(running), sample_time_s))
        else:
            self.trace.skip()
        if self.recording is not None:
            vt = out.actuator_force_N[0]
            self.recording.state(tick, now_ns, (
                now_s, float(fh[0, 0]), float(fh[0, 1]), float(yh[0, 0]), float(yh[0, 1]),
                float(position[0]), float(position[1]), float(velocity[0]),
                float(velocity[1]), float(ft[0]), float(ft[1]), float(vt[0]), float(vt[1]),
                engagement, float(out.cutting[0]), removed, float(running), sample_time_s))
        ready = supervisor.ready
        self.harness.offer_state(tick, lambda: {
            "tool_force_N": [float(ft[0]), float(ft[1])],
            "tool_position_m": [float(position[0]), float(position[1])],
            "tool_velocity_m_s": [float(velocity[0]), float(velocity[1])],
            "clay_engagement": engagement, "removed_volume_m3": removed,
            "in_contact": bool(out.cutting[0]), "forces_enabled": ready, "safe_state": not ready})
        self.harness.status(tick, now_ns, supervisor.watchdog, self._event_lists,
                            running=running)
        if self.ros2 is not None:
            self._offer_ros2(tick, now_s, out, running, ready)
        self.tick.note_node_time()  # the node part per node step (the summary's node_times)

    def _offer_ros2(self, tick: int, now_s: float, out: Any, running: bool,
                    ready: bool) -> None:
        """Off the loop: two reference swaps at their rates."""
        supervisor, node = self.supervisor, self.tick.node
        ft, position, velocity = out.tool_force_N[0], out.tool_position_m[0], \
            out.tool_velocity_m_s[0]
        engagement, removed = self.engagement, self.removed_m3
        state = self.tick.state
        self.ros2.offer(tick, lambda: {
            "time_s": now_s, "force_N": (float(ft[0]), float(ft[1])),
            "position_m": (float(position[0]), float(position[1])),
            "velocity_m_s": (float(velocity[0]), float(velocity[1]))}, lambda: {
            **self.link_status(), "running": running,
            "safe_state": not ready, "safety_events": len(supervisor.events),
            "clay_engagement": engagement, "removed_volume_m3": removed,
            **passivity_summary(state.passivity, node.passivity_standby)})

    def stop_safely(self) -> None:
        """Safe state: the tool stops; one message with SAFE_STATE | STOPPING before the link
        closes (the master holds its handle at once and counts no trip)."""
        state = self.tick.state
        self.tick.node.safe_stop(state)
        position = state.tool_position_m()[0]
        self.link.send_tool((0.0, 0.0), (float(position[0]), float(position[1])), (0.0, 0.0),
                            0.0, self.removed_m3, Flags.SAFE_STATE | Flags.STOPPING)

    def status_text(self) -> str:
        """This side's part of the live status line."""
        return self.harness.status_line(
            self.supervisor.watchdog, f"ft {self.tool_force_N[0]:+.2f} N  engagement "
            f"{self.engagement:.2f}{self.inert.status()}")
