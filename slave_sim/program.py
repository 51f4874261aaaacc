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

At the end (duration, SIGINT or SIGTERM) the tool stops, the summary is printed (and written
with ``--json-summary``), and with ``--out DIR`` the workpiece is saved as ``clay.npz`` and
``clay.png`` (with the tool path) and the trace as ``slave_trace.npz``.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
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
from haptic.common.runtime.runner import StopSignals
from haptic.common.runtime.stage_times import StageTimes
from haptic.common.wire.link import Link
from haptic.common.wire.messages import FLAGS_BY_VALUE, Flags
from haptic.common.wire.passivity_link import PassivityLink
from haptic.common.wire.phase_lock import PhaseLock, PhaseLockSettings
from haptic.slave_sim.input_guard import InputGuard, InputGuardSettings
from haptic.slave_sim.node import SlaveNode
from haptic.slave_sim.pacing import MasterSamplePacing, PacingSettings
from haptic.slave_sim.resync import ToolResync
from haptic.slave_sim.supervisor import SlaveSupervisor
from haptic.slave_sim.tick import SlaveTick
from haptic.slave_sim.tool_path import ToolPath

#: The stages of one tick, in order (the summary's ``stages``).
TICK_STAGES = ("poll", "supervise", "node", "send", "telemetry")

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

SLAVE_TRACE_COLUMNS = (
    "time_s", "handle_force_x_N", "handle_force_y_N", "handle_position_x_m",
    "handle_position_y_m", "tool_position_x_m", "tool_position_y_m", "tool_velocity_x_m_s",
    "tool_velocity_y_m_s", "tool_force_x_N", "tool_force_y_N", "engagement", "cutting",
    "forces_enabled", "sample_time_s",
)
#: ``time_s`` is the wall time since the loop's start; ``sample_time_s`` the slave's virtual
#: world's own (node steps x Ts, slave_sim/pacing.py): the cut's figures are taken on it, so a
#: master that falls behind real time slows the cut on the wall clock, not in the figures.


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
        return _run_slave(node, options, args, extra_summary, recording)


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


def _run_slave(node: SlaveNode, options: Any, args: argparse.Namespace,
               extra_summary: dict[str, Any], recording: RunRecording | None) -> int:
    period_s = node.sample_period_s
    phase_lock = phase_lock_from(options.config, period_s)
    link_config = options.link
    grid = node.scenario.grid
    ratio = node.position_ratio
    supervisor = SlaveSupervisor(
        (float(ratio[0]), float(ratio[1])), args.sync_tolerance,
        slave_work_area_m(grid.x_range_m, grid.y_range_m),
        link_config.max_message_age_s, link_config.resync_messages,
        grid_m=(grid.x_range_m[0], grid.x_range_m[1], grid.y_range_m[0], grid.y_range_m[1]))
    area = work_area_from_config(options.config, grid.x_range_m, grid.y_range_m)
    supervisor.events.append({"time_s": 0.0, "kind": "work_area", "reason": area.describe()})
    watchdog = supervisor.watchdog
    guard = InputGuard(InputGuardSettings.from_config(options.config), period_s,
                       events=supervisor.events)
    inert = InertMonitor(options.config["supervision"]["inert_after_s"],
                         events=supervisor.events)
    max_age_s = link_config.max_message_age_s
    trace = TraceRecorder(SLAVE_TRACE_COLUMNS, args.trace_every)
    state = node.initial_state(1)
    # supervise and node stages (slave_sim/tick.py); the resync moves the tool to the handle
    # through the clay at a bounded speed
    tick_stages = SlaveTick(node, state, [supervisor], [guard], ToolResync(node))
    tick_stages.start()
    # one node step per master sample, not per tick (slave_sim/pacing.py)
    pacing = MasterSamplePacing(PacingSettings.from_config(options.config))
    stages = StageTimes(TICK_STAGES)
    path_every = max(1, args.trace_every)
    tool_path = ToolPath()  # bounded memory (slave_sim/tool_path.py)
    fh = tick_stages.handle_force_N  # the newest bounded handle message, updated in place
    yh = tick_stages.handle_position_m
    flags_box = {"max_force": 0.0, "ft": np.zeros(2), "engagement": 0.0, "removed": 0.0,
                 "running_gap": None}
    # the node's last outputs (sent again while waiting for the master's next sample) and
    # the virtual world's time, s (node steps x Ts)
    last_tick: dict[str, Any] = {"ticked": None, "sample_time_s": 0.0}
    run = None
    with StopSignals() as signals, Link(link_config) as link:
        harness = ProgramHarness("haptic-slave", "master", options, link, period_s, recording)
        on = "" if node.clay_device is None else f" on {node.clay_device}"
        came = harness.wait_for_peer(args.peer_wait, signals, f"{node.scenario.name}, "
                                     f"environment {node.environment_kind}{on}; ")
        if came is not None:
            return came
        harness.start()
        clay_recorded = recording is not None and node.environment_kind == "clay"
        if clay_recorded:
            recording.add_channel("/slave/workpiece")
            recording.add_channel("/slave/clay")
            _record_clay(recording, state, harness.realtime_start_ns, layout=True)
        if getattr(args, "display", False) and link.session is not None:
            harness.attach_display(_display_publisher(link, node, state, recording))
        ros2 = start_ros2(options.config, "slave", period_s, say=harness.say,
                          loop_counts=harness.loop_counts, **_ros2_clay(node, state))

        clock = time.perf_counter_ns
        # the master's governed k (never above ours) and the echo of its send time
        tick_stages.follow_gain(node.model.ch1_gain_k, gain_scalable(node.model))
        echo = tick_stages.echo_send_time_ns
        # energy_J on the wire; the TDPA flag says the configured mode (in paper mode the
        # layer waits on standby for the master's Flags.TDPA_SWITCHED: slave_sim/tick.py)
        tdpa_peer = PassivityLink(node.passivity is not None and not node.passivity_standby)
        tdpa_flag_value = int(tdpa_peer.flags)  # the flags' values or'ed, one lookup a tick

        def step(tick: int, now_ns: int) -> None:
            now_s = harness.time_s(now_ns)
            # poll: the newest handle message whose delivery time has come
            message = link.poll()
            if message is not None:  # a peer in the other [control] mode: refused
                tdpa_peer.check(message)
            poll_ns = clock()
            # supervise: input bounds (slave_sim/input_guard.py), watchdog, resync, work-area
            # guard (slave_sim/supervisor.py), all in slave_sim/tick.py; then the phase lock
            # every message delivered with the newest passes the guard too: each admitted
            # one is a node step with its own force (slave_sim/pacing.py)
            delivered = link.delivered
            fresh = bool(tick_stages.supervise(now_s, (message,), (link.silence_s(),),
                                               (link.peer_alive,),
                                               (delivered[:-1] if delivered else (),))[0])
            if fresh and phase_lock is not None:
                if link.last_delivery_measured:
                    harness.runner.shift_schedule(phase_lock.update(
                        link.receive.last_delivery_ns, link.last_poll_ns))
                else:
                    phase_lock.skip_unmeasured()
            if fresh and state.passivity is not None:  # the master's handed-over energy
                tdpa_peer.receive(state.passivity, message)
            running = supervisor.running
            inert.update(now_s, link.peer_alive and link.silence_s() < max_age_s, running,
                         supervisor.stop_reason())
            supervise_ns = clock()
            # node: Ch2/Ct2, the tool and the clay, once per master sample while the tool
            # runs (none while the master's next sample has not come, more after a gap)
            plan = pacing.plan(running, tick_stages.samples[0])
            ticked = last_tick["ticked"]
            if plan or ticked is None:  # each step with its own sample's force
                ticked = tick_stages.control_samples(plan)
                last_tick["ticked"] = ticked
                last_tick["sample_time_s"] += max(len(plan), 1) * period_s
            out = ticked.out
            if running:  # yt - Ah1 yh while the tool runs (a stopped tool is re-placed)
                flags_box["running_gap"] = out.tracking_error_m[0]
            ft = out.tool_force_N[0]
            position = out.tool_position_m[0]
            velocity = out.tool_velocity_m_s[0]
            engagement = float(out.engagement[0])
            removed = _removed_total_m3(state)
            # FORCES_ENABLED: this side is ready (link in sync, tool at the handle or running);
            # the master enables its forces on it, the slave runs once the master has.
            ready_flag = supervisor.ready
            node_ns = clock()
            # send: the tool force, position and velocity, the clay's status
            link.send_tool((float(ft[0]), float(ft[1])), (float(position[0]), float(position[1])),
                           (float(velocity[0]), float(velocity[1])), engagement, removed,
                           FLAGS_BY_VALUE[int(ticked.flag_values[0]) | tdpa_flag_value],
                           int(echo[0]),
                           tdpa_peer.sent_J(state))
            send_ns = clock()
            # telemetry: summary figures, trace, recording, display
            magnitude = math.hypot(ft[0], ft[1])
            if magnitude > flags_box["max_force"]:
                flags_box["max_force"] = magnitude
            flags_box["ft"] = ft
            flags_box["engagement"] = engagement
            flags_box["removed"] = removed
            if tick % path_every == 0:
                tool_path.add(float(position[0]), float(position[1]))
            if trace.due():
                trace.record((now_s, fh[0, 0], fh[0, 1], yh[0, 0], yh[0, 1], position[0],
                              position[1], velocity[0], velocity[1], ft[0], ft[1], engagement,
                              float(out.cutting[0]), float(running),
                              last_tick["sample_time_s"]))
            else:
                trace.skip()
            if recording is not None:
                vt = out.actuator_force_N[0]
                recording.state(tick, now_ns, (
                    now_s, float(fh[0, 0]), float(fh[0, 1]), float(yh[0, 0]), float(yh[0, 1]),
                    float(position[0]), float(position[1]), float(velocity[0]),
                    float(velocity[1]), float(ft[0]), float(ft[1]), float(vt[0]), float(vt[1]),
                    engagement, float(out.cutting[0]), removed, float(running),
                    last_tick["sample_time_s"]))
            harness.offer_state(tick, lambda: {
                "tool_force_N": [float(ft[0]), float(ft[1])],
                "tool_position_m": [float(position[0]), float(position[1])],
                "tool_velocity_m_s": [float(velocity[0]), float(velocity[1])],
                "clay_engagement": engagement, "removed_volume_m3": removed,
                "in_contact": bool(out.cutting[0]), "forces_enabled": ready_flag,
                "safe_state": not ready_flag})
            harness.status(tick, now_ns, watchdog, (watchdog.events, supervisor.events),
                           running=running)
            if ros2 is not None:  # off the loop: two reference swaps at their rates
                ros2.offer(tick, lambda: {
                    "time_s": now_s, "force_N": (float(ft[0]), float(ft[1])),
                    "position_m": (float(position[0]), float(position[1])),
                    "velocity_m_s": (float(velocity[0]), float(velocity[1]))}, lambda: {
                    **link.summary(), "watchdog_state": watchdog.state.value,
                    "watchdog_trips": watchdog.trips, "running": running,
                    "safe_state": not ready_flag, "safety_events": len(supervisor.events),
                    "clay_engagement": engagement, "removed_volume_m3": removed,
                    **passivity_summary(state.passivity, node.passivity_standby)})
            stages.record(now_ns, (poll_ns, supervise_ns, node_ns, send_ns, clock()))

        def stop_safely() -> None:
            # Safe state: the tool stops; one message with SAFE_STATE | STOPPING before the
            # link closes (the master holds its handle at once and counts no trip)
            node.safe_stop(state)
            position = state.tool_position_m()[0]
            link.send_tool((0.0, 0.0), (float(position[0]), float(position[1])), (0.0, 0.0),
                           0.0, flags_box["removed"], Flags.SAFE_STATE | Flags.STOPPING)

        def first_output() -> None:
            # the node's output before the first tick: the tool at rest, waiting for the
            # master (what the first tick would step), on the loop's CPU; the first tick then
            # sends it. Stepped in the first tick, it took 0.5-0.7 ms (the state's first
            # launches, caches cold) and the slave's first two ticks overran in every run.
            last_tick["ticked"] = tick_stages.control_samples(())
            last_tick["sample_time_s"] += period_s

        run = harness.run(step, lambda: harness.status_line(
            watchdog, f"ft {flags_box['ft'][0]:+.2f} N  engagement "
            f"{flags_box['engagement']:.2f}{inert.status()}"), signals, stop_safely,
            before_loop=first_output)
        if ros2 is not None:  # the tokens withdrawn, the session closed
            ros2.stop()
            extra_summary.update(ros2.figures)
        if node.environment_kind == "ros2":  # the robot plant's counters
            extra_summary.update(node.environment.figures)
        guard_summary = {**guard.summary(), **inert.summary(run.elapsed_s)}
    final = state.tool_position_m()[0]
    # yt - Ah1 yh at the last tick the tool ran: once the master stops (its last message
    # has SAFE_STATE), the stopped tool is re-placed at the handle, which would read 0
    gap = flags_box["running_gap"]
    if gap is None:  # the tool never ran: the gap it was left with
        gap = node.tracking_error_m(state, state.handle_position_m)[0]
    summary = harness.summary(
        run, watchdog, flags_box["max_force"], (watchdog.events, supervisor.events),
        removed_volume_m3=flags_box["removed"],
        final_tool_position_m=[float(final[0]), float(final[1])],
        final_position_gap_m=[float(gap[0]), float(gap[1])], stages=stages.summary(),
        **guard_summary,
        slave_gain_k=node.model.ch1_gain_k * float((state.gain_ratio if state.gain_ratio is
                                                     not None else np.ones(1))[0]),
        **(phase_lock.summary() if phase_lock is not None else {"phase_lock_enabled": False}),
        **pacing.summary(),
        **passivity_summary(state.passivity, node.passivity_standby),
        clay_device=node.clay_device,
        **extra_summary,
    )
    traced = trace.arrays()
    # the cut's figures on the virtual world's clock (SLAVE_TRACE_COLUMNS)
    on_samples = {**traced, "time_s": traced["sample_time_s"]} if traced else traced
    summary.update(cutting_figures(on_samples))
    summary.update(steady_cut_fields(on_samples))
    if args.out is not None:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        trace.save(out / "slave_trace.npz")
        summary["trace"] = str(out / "slave_trace.npz")
        if node.environment_kind == "clay":
            state.environment.save_npz(out / "clay.npz")
            path = tool_path.array()
            state.environment.render_png(
                out / "clay.png", path,
                title=f"{node.scenario.name}: networked run, {run.elapsed_s:.1f} s")
            summary["clay_npz"] = str(out / "clay.npz")
            summary["clay_png"] = str(out / "clay.png")
    harness.finish(summary, (lambda recording, end_ns: _record_clay(
        recording, state, end_ns, layout=False)) if clay_recorded else None)
    cut = summary.get("cut_mean_force_N")
    if cut is not None:
        print(f"haptic-slave: in the clay {summary['cutting_time_s']:.2f} s: mean |ft| "
              f"{cut:.3f} N, mean speed {summary['cut_mean_speed_m_s'] * 1e3:.1f} mm/s",
              file=sys.stderr, flush=True)
    return 0


def _removed_total_m3(state: Any) -> float:
    """Clay removed since the start, m^3 (0 for the linear environment)."""
    total = getattr(state.environment, "removed_total_m3", None)
    return 0.0 if total is None else float(total[0])
