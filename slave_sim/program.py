"""``haptic-slave``: the slave on the remote host: the slave node (Ch2/Ct2, the virtual tool,
the Warp clay) driven by the handle's messages over the Zenoh link, on the real-time runner.

One tick at Ts (docs/programs.md):

1. ``link.poll()``: the newest ``HandleState`` whose delivery time has come (the handle force
   the master's compensator used, the handle position, the master's flags);
2. the watchdog (fresh? silence? master alive?). In its safe states (``waiting`` at start,
   ``tripped``, ``resyncing``) the node is halted (``SlaveNode.safe_stop``: the tool stops, no
   force goes back) and, on every fresh message, brought towards the received handle
   position (``ToolResync.step``: through the clay at a bounded speed, cutting); ``in_sync``
   is then |yt - Ah1 yh| below the tolerance. Back to ``ok``: ``SlaveNode.resume``;
3. ``node.step(fh_recv, yh_recv)``: the tool moves and cuts the clay;
4. ``link.send_tool(ft, yt, vt, engagement, removed volume, flags)``.

A work-area guard stops the tool (until the next resync) when it gets more than
:data:`~haptic.common.model.work_area.WORK_AREA_MARGIN_M` outside the scenario's grid;
before that, the tool meets the wall of the work area both sides hold
(common/model/work_area.py), where the handle's command is clamped too.

The one tick driver (common/runtime/tick_driver.py) runs the tick's stages (poll, supervise,
node, send, telemetry: slave_sim/program_stages.py) and times them.

At the end (duration, SIGINT or SIGTERM) the tool stops, the summary is printed (and written
with ``--json-summary``), and with ``--out DIR`` the workpiece is saved as ``clay.npz`` and
``clay.png`` (with the tool path) and the trace as ``slave_trace.npz``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

from haptic.common.analysis.margin_table import gain_scalable
from haptic.common.config import ConfigError
from haptic.common.model.passivity import passivity_summary
from haptic.common.model.work_area import slave_work_area_m, work_area_from_config
from haptic.common.records.cutting import cutting_figures, steady_cut_fields
from haptic.common.records.run_recording import RunRecording
from haptic.common.records.trace import TraceRecorder
from haptic.common.ros2.options import start_ros2
from haptic.common.runtime.display import DisplayPublisher
from haptic.common.runtime.inert import InertMonitor
from haptic.common.runtime.program_harness import ProgramHarness, recording_for
from haptic.common.runtime.runner import RunStats, StopSignals
from haptic.common.runtime.tick_driver import TickDriver
from haptic.common.wire.link import Link
from haptic.common.wire.phase_lock import PhaseLock, PhaseLockSettings
from haptic.slave_sim.input_guard import InputGuard, InputGuardSettings
from haptic.slave_sim.node import SlaveNode
from haptic.slave_sim.pacing import MasterSamplePacing, PacingSettings
from haptic.slave_sim.program_stages import (
    SLAVE_TRACE_COLUMNS,
    TICK_STAGES,
    SlaveStages,
)
from haptic.slave_sim.resync import ToolResync
from haptic.slave_sim.supervisor import SlaveSupervisor
from haptic.slave_sim.tick import SlaveTick
from haptic.slave_sim.tool_path import ToolPath

__all__ = ["SLAVE_RECORD_COLUMNS", "SLAVE_TRACE_COLUMNS", "TICK_STAGES", "phase_lock_from",
           "run_slave"]

#: The columns of ``/slave/state`` in the recording (``--record``).
SLAVE_RECORD_COLUMNS = (
    "time_s", "handle_force_x_N", "handle_force_y_N", "handle_position_x_m",
    "handle_position_y_m", "tool_position_x_m", "tool_position_y_m", "tool_velocity_x_m_s",
    "tool_velocity_y_m_s", "tool_force_x_N", "tool_force_y_N", "actuator_force_x_N",
    "actuator_force_y_N", "engagement", "cutting", "removed_volume_m3", "running",
    "sample_time_s",
)
#: ``/slave/state``'s ``time_s`` is the wall time since the loop's start, ``sample_time_s``
#: the virtual world's (node steps x Ts, as in SLAVE_TRACE_COLUMNS): haptic-replay times the
#: cut on it, as the slave's summary does.


def phase_lock_from(config: dict[str, Any], period_s: float) -> PhaseLock | None:
    """The slave's :class:`PhaseLock` (``[slave.phase_lock]``), or ``None`` when it is off.
    Its lag (delivery of the master's message to the tick using it) is the runner's spin plus
    ``margin_s``: the loop starts spinning only after the message is in, so a SCHED_FIFO spin
    never holds up the Zenoh thread receiving it (with the spin over the arrival, the arrival
    waits for the tick and the lock chases it). ``period_s``: Ts, s. Raises ConfigError."""
    section = config["slave"]["phase_lock"]
    if not section["enabled"]:
        return None
    spin_s = float(config["runner"]["spin_s"])
    lag_s = spin_s + float(section["margin_s"])
    if lag_s >= period_s:
        key = "runner.spin_s" if spin_s >= period_s else "slave.phase_lock.margin_s"
        raise ConfigError(key, f"runner.spin_s + slave.phase_lock.margin_s must be below the "
                          f"period Ts = {period_s:g} s for the phase lock (got {lag_s:g})")
    return PhaseLock(period_s, PhaseLockSettings(lag_s=lag_s))


def run_slave(node: SlaveNode, options: Any, args: argparse.Namespace,
              extra_summary: dict[str, Any]) -> int:
    """The networked slave loop; returns the exit status. With ``--record FILE`` the run is
    recorded to MCAP (common/records/run_recording.py), the file closed properly on every way
    out."""
    with recording_for(getattr(args, "record", None), "slave", SLAVE_RECORD_COLUMNS,
                       node.sample_period_s, getattr(args, "record_every", 1)) as recording:
        return _SlaveRun(node, options, args, extra_summary, recording).run()


def _record_clay(recording: RunRecording, state: Any, log_time_ns: int,
                 layout: bool) -> None:
    """The workpiece's layout (once) and its reduced height map into the recording."""
    from haptic.common.records.heightmap_codec import reduction_factors
    from haptic.slave_sim.clay.clay_view import heights_message, workpiece_layout

    clay = state.environment
    grid = clay.workpiece.grid
    factors = reduction_factors(grid.cells_x, grid.cells_y)
    if layout:
        recording.record("/slave/workpiece", log_time_ns,
                         workpiece_layout(clay.workpiece, factors))
    recording.record("/slave/clay", log_time_ns, heights_message(clay.heights_m()[0], factors))


#: Rate of the clay maps in the recording (taken from the display thread), Hz.
RECORD_CLAY_RATE_HZ = 2.0


def _display_publisher(link: Link, node: SlaveNode, state: Any,
                       recording: RunRecording | None) -> DisplayPublisher:
    """The slave's display publications: status, and the clay's height map read off the
    loop (on a CPU clay, a view of the live array); with a recording, the reduced map also
    goes into ``/slave/clay`` at :data:`RECORD_CLAY_RATE_HZ`."""
    clay_source = layout = on_clay = None
    factors = (1, 1)
    if node.environment_kind == "clay":
        from haptic.common.records.heightmap_codec import reduction_factors
        from haptic.slave_sim.clay.clay_view import workpiece_layout

        clay = state.environment
        grid = clay.workpiece.grid
        factors = reduction_factors(grid.cells_x, grid.cells_y)
        layout = workpiece_layout(clay.workpiece, factors)
        heights = clay.heights

        def clay_source() -> np.ndarray:
            view = heights.numpy() if hasattr(heights, "numpy") else heights
            return view[0]

        if recording is not None:
            last = [0]

            def on_clay(time_ns: int, reduced: np.ndarray) -> None:
                if time_ns - last[0] >= 1e9 / RECORD_CLAY_RATE_HZ:
                    last[0] = time_ns
                    recording.record("/slave/clay", time_ns, {
                        "cells_x": int(reduced.shape[1]), "cells_y": int(reduced.shape[0]),
                        "heights_mm": np.round(reduced * 1e3, 4).tolist()})

    return DisplayPublisher(link.session, link.config.key_prefix, "slave",
                            clay_source=clay_source, layout=layout, factors=factors,
                            on_clay=on_clay).start()


def _ros2_clay(node: SlaveNode, state: Any) -> dict[str, Any]:
    """The clay's height map (m, read off the loop: on a CPU clay a view of the live array)
    and its x and y ranges (m) for the ROS 2 point cloud; nothing without clay."""
    if node.environment_kind != "clay":
        return {}
    clay = state.environment
    heights = clay.heights
    grid = clay.workpiece.grid

    def clay_source() -> np.ndarray:
        view = heights.numpy() if hasattr(heights, "numpy") else heights
        return view[0]

    return {"clay_source": clay_source,
            "clay_ranges": (tuple(grid.x_range_m), tuple(grid.y_range_m))}


class _SlaveRun:
    """One run of the networked slave: its supervisor, guard and tick, the peer wait, the tick
    driver over :class:`SlaveStages`, the summary and the run's files."""

    def __init__(self, node: SlaveNode, options: Any, args: argparse.Namespace,
                 extra_summary: dict[str, Any], recording: RunRecording | None) -> None:
        self.node = node
        self.options = options
        self.args = args
        self.extra_summary = extra_summary
        self.recording = recording
        period_s = node.sample_period_s
        self.phase_lock = phase_lock_from(options.config, period_s)
        link_config = options.link
        grid = node.scenario.grid
        ratio = node.position_ratio
        supervisor = self.supervisor = SlaveSupervisor(
            (float(ratio[0]), float(ratio[1])), args.sync_tolerance,
            slave_work_area_m(grid.x_range_m, grid.y_range_m),
            link_config.max_message_age_s, link_config.resync_messages,
            grid_m=(grid.x_range_m[0], grid.x_range_m[1], grid.y_range_m[0], grid.y_range_m[1]))
        area = work_area_from_config(options.config, grid.x_range_m, grid.y_range_m)
        supervisor.events.append({"time_s": 0.0, "kind": "work_area", "reason": area.describe()})
        self.guard = InputGuard(InputGuardSettings.from_config(options.config), period_s,
                                events=supervisor.events)
        self.inert = InertMonitor(options.config["supervision"]["inert_after_s"],
                                  events=supervisor.events)
        self.trace = TraceRecorder(SLAVE_TRACE_COLUMNS, args.trace_every)
        self.state = node.initial_state(1)
        # supervise and node stages (slave_sim/tick.py); the resync moves the tool to the
        # handle through the clay at a bounded speed
        self.tick = SlaveTick(node, self.state, [supervisor], [self.guard], ToolResync(node))
        self.tick.start()
        # one node step per master sample, not per tick (slave_sim/pacing.py)
        self.pacing = MasterSamplePacing(PacingSettings.from_config(options.config))
        self.tool_path = ToolPath()  # bounded memory (slave_sim/tool_path.py)
        self.clay_recorded = recording is not None and node.environment_kind == "clay"
        self.ros2: Any | None = None

    def run(self) -> int:
        """The run; returns the exit status."""
        with StopSignals() as signals, Link(self.options.link) as link:
            try:
                run = self._run_linked(link, signals)
            finally:
                if self.ros2 is not None:  # the tokens withdrawn, the bridge ended
                    self.ros2.stop()
                    self.extra_summary.update(self.ros2.figures)
            if isinstance(run, int):  # the master did not come (or a stop came first)
                return run
            if self.node.environment_kind == "ros2":  # the robot plant's counters
                self.extra_summary.update(self.node.environment.figures)
            guard_summary = {**self.guard.summary(), **self.inert.summary(run.elapsed_s)}
        self._finish(run, guard_summary)
        return 0

    def _run_linked(self, link: Link, signals: StopSignals) -> RunStats | int:
        """The peer wait, the recording's and the display's start, then the loop."""
        node, recording = self.node, self.recording
        period_s = node.sample_period_s
        harness = self.harness = ProgramHarness("haptic-slave", "master", self.options, link,
                                                period_s, recording)
        # the ROS 2 bridge process first: it joins its router while the master comes
        self.ros2 = start_ros2(self.options.config, "slave", period_s, say=harness.say,
                               loop_counts=harness.loop_counts, **_ros2_clay(node, self.state))
        on = "" if node.clay_device is None else f" on {node.clay_device}"
        came = harness.wait_for_peer(self.args.peer_wait, signals, f"{node.scenario.name}, "
                                     f"environment {node.environment_kind}{on}; ")
        if came is not None:
            return came
        harness.start()
        if self.clay_recorded:
            recording.add_channel("/slave/workpiece")
            recording.add_channel("/slave/clay")
            _record_clay(recording, self.state, harness.realtime_start_ns, layout=True)
        if getattr(self.args, "display", False) and link.session is not None:
            harness.attach_display(_display_publisher(link, node, self.state, recording))
        # the master's governed k (never above ours) and the echo of its send time
        self.tick.follow_gain(node.model.ch1_gain_k, gain_scalable(node.model))
        stages = self.stages = SlaveStages(
            link, self.tick, harness, self.pacing, self.phase_lock, self.trace, self.tool_path,
            max(1, self.args.trace_every), recording, self.inert, self.ros2)
        self.driver = TickDriver([stages])
        return harness.run(self.driver, stages.status_text, signals, stages.stop_safely,
                           before_loop=stages.first_output)

    def _finish(self, run: RunStats, guard_summary: dict[str, Any]) -> None:
        """The summary (the cut's figures on the virtual world's clock), the run's files,
        the recording closed."""
        node, state, stages = self.node, self.state, self.stages
        final = state.tool_position_m()[0]
        # yt - Ah1 yh at the last tick the tool ran: once the master stops (its last message
        # has SAFE_STATE), the stopped tool is re-placed at the handle, which would read 0
        gap = stages.running_gap_m
        if gap is None:  # the tool never ran: the gap it was left with
            gap = node.tracking_error_m(state, state.handle_position_m)[0]
        watchdog = self.supervisor.watchdog
        summary = self.harness.summary(
            run, watchdog, stages.max_force_N, (watchdog.events, self.supervisor.events),
            removed_volume_m3=stages.removed_m3,
            final_tool_position_m=[float(final[0]), float(final[1])],
            final_position_gap_m=[float(gap[0]), float(gap[1])],
            stages=self.driver.stage_times[0].summary(), **guard_summary,
            slave_gain_k=node.model.ch1_gain_k * float((state.gain_ratio if state.gain_ratio is
                                                         not None else np.ones(1))[0]),
            **(self.phase_lock.summary() if self.phase_lock is not None
               else {"phase_lock_enabled": False}),
            **self.pacing.summary(),
            node_times=self.tick.node_times.summary(),
            **passivity_summary(state.passivity, node.passivity_standby),
            clay_device=node.clay_device,
            **self.extra_summary,
        )
        traced = self.trace.arrays()
        # the cut's figures on the virtual world's clock (SLAVE_TRACE_COLUMNS)
        on_samples = {**traced, "time_s": traced["sample_time_s"]} if traced else traced
        summary.update(cutting_figures(on_samples))
        summary.update(steady_cut_fields(on_samples))
        if self.args.out is not None:
            self._save_files(Path(self.args.out), summary, run)
        self.harness.finish(summary, (lambda recording, end_ns: _record_clay(
            recording, state, end_ns, layout=False)) if self.clay_recorded else None)
        cut = summary.get("cut_mean_force_N")
        if cut is not None:
            print(f"haptic-slave: in the clay {summary['cutting_time_s']:.2f} s: mean |ft| "
                  f"{cut:.3f} N, mean speed {summary['cut_mean_speed_m_s'] * 1e3:.1f} mm/s",
                  file=sys.stderr, flush=True)

    def _save_files(self, out: Path, summary: dict[str, Any], run: RunStats) -> None:
        """``--out DIR``: the trace, and with clay the workpiece and its picture."""
        out.mkdir(parents=True, exist_ok=True)
        self.trace.save(out / "slave_trace.npz")
        summary["trace"] = str(out / "slave_trace.npz")
        node, state = self.node, self.state
        if node.environment_kind == "clay":
            state.environment.save_npz(out / "clay.npz")
            state.environment.render_png(
                out / "clay.png", self.tool_path.array(),
                title=f"{node.scenario.name}: networked run, {run.elapsed_s:.1f} s")
            summary["clay_npz"] = str(out / "clay.npz")
            summary["clay_png"] = str(out / "clay.png")
