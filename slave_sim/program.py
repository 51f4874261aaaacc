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
:data:`WORK_AREA_MARGIN_M` outside the scenario's grid.

At the end (duration, SIGINT or SIGTERM) the tool stops, the summary is printed (and written
with ``--json-summary``), and with ``--out DIR`` the workpiece is saved as ``clay.npz`` and
``clay.png`` (with the tool path) and the trace as ``slave_trace.npz``.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import zenoh

from haptic.common.cli_options import add_run_options, run_options_from_args
from haptic.common.config import ConfigError, exit_on_config_error, load_config, override
from haptic.common.config.scenario import load_scenario, max_block_damping
from haptic.common.cutting import cutting_figures, steady_cut_fields
from haptic.common.display import DisplayPublisher, EventCursor
from haptic.common.failures import exit_on_link_error
from haptic.common.inert import InertMonitor
from haptic.common.link import Link
from haptic.common.messages import Flags
from haptic.common.passivity_link import PassivityLink
from haptic.common.phase_lock import PhaseLock, PhaseLockSettings
from haptic.common.preflight import add_preflight_options, run_preflight
from haptic.common.run_recording import RunRecording
from haptic.common.runner import RealTimeRunner, StopSignals
from haptic.common.runner_config import place_other_threads, prioritise_zenoh_threads
from haptic.common.stage_times import StageTimes
from haptic.common.summary import format_summary, make_summary, write_json_summary
from haptic.common.trace import TraceRecorder
from haptic.slave_sim.input_guard import InputGuard, InputGuardSettings
from haptic.slave_sim.node import SlaveNode
from haptic.slave_sim.resync import ToolResync
from haptic.slave_sim.supervisor import SlaveSupervisor, Transition
from haptic.slave_sim.tool_path import ToolPath

#: The stages of one tick, in order (the summary's ``stages``).
TICK_STAGES = ("poll", "supervise", "node", "send", "telemetry")
#: How far the tool may leave the scenario's grid before the work-area guard stops it, m.
WORK_AREA_MARGIN_M = 0.01
#: Default tolerance of the resync position check, m per axis.
DEFAULT_SYNC_TOLERANCE_M = 0.001

#: The columns of ``/slave/state`` in the recording (``--record``).
SLAVE_RECORD_COLUMNS = (
    "time_s", "handle_force_x_N", "handle_force_y_N", "handle_position_x_m",
    "handle_position_y_m", "tool_position_x_m", "tool_position_y_m", "tool_velocity_x_m_s",
    "tool_velocity_y_m_s", "tool_force_x_N", "tool_force_y_N", "actuator_force_x_N",
    "actuator_force_y_N", "engagement", "cutting", "removed_volume_m3", "running",
)

SLAVE_TRACE_COLUMNS = (
    "time_s", "handle_force_x_N", "handle_force_y_N", "handle_position_x_m",
    "handle_position_y_m", "tool_position_x_m", "tool_position_y_m", "tool_velocity_x_m_s",
    "tool_velocity_y_m_s", "tool_force_x_N", "tool_force_y_N", "engagement", "cutting",
    "forces_enabled",
)


def build_parser() -> argparse.ArgumentParser:
    """The command line."""
    parser = argparse.ArgumentParser(prog="haptic-slave", description=__doc__.split("\n")[0])
    add_run_options(parser)
    parser.add_argument("--scenario", help="scenario name or TOML path ([slave] scenario)")
    add_preflight_options(parser)
    group = parser.add_argument_group("networked run")
    group.add_argument("--out", metavar="DIR", type=Path,
                       help="write clay.npz, clay.png and slave_trace.npz here at the end")
    group.add_argument("--peer-wait", metavar="S", type=float,
                       help="give up (exit 1) when no master appears within S s (default: wait)")
    group.add_argument("--sync-tolerance", metavar="M", type=float,
                       default=DEFAULT_SYNC_TOLERANCE_M,
                       help=f"resync: |tool - Ah1 handle| below this, m "
                       f"(default {DEFAULT_SYNC_TOLERANCE_M:g})")
    group.add_argument("--phase-margin", metavar="S", type=float,
                       help="start the spin before the tick this long after the master's "
                       "message arrives, s (slave.phase_lock.margin_s)")
    group.add_argument("--no-phase-lock", action="store_true",
                       help="let the loop tick free-running (slave.phase_lock.enabled = false)")
    group.add_argument("--trace-every", metavar="N", type=int, default=10,
                       help="keep every Nth tick in the trace (default 10)")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit status: 0; 1 when no master came within --peer-wait;
    2 for a configuration error (one line); 3 when the stability analysis refuses the loop;
    4 when the link cannot open (a port in use, an unreachable router; one line)."""
    args = build_parser().parse_args(argv)
    zenoh.init_log_from_env_or("error")
    with exit_on_config_error():
        config = load_config(args.config)
        if args.scenario is not None:
            config = override(config, "slave.scenario", args.scenario)
        if args.k is not None:
            config = override(config, "model.ch1.gain_k", args.k)
        if args.phase_margin is not None:
            config = override(config, "slave.phase_lock.margin_s", args.phase_margin)
        if args.no_phase_lock:
            config = override(config, "slave.phase_lock.enabled", False)
        options = run_options_from_args(args, "slave", config=config)
        if not args.sync_tolerance > 0.0:
            raise ConfigError("--sync-tolerance", f"must be > 0 m (got {args.sync_tolerance})")
        if args.trace_every < 1:
            raise ConfigError("--trace-every", f"must be >= 1 (got {args.trace_every})")
        if args.record_every < 1:
            raise ConfigError("--record-every", f"must be >= 1 (got {args.record_every})")
        scenario = load_scenario(options.config["slave"]["scenario"])
        phase_lock_from(options.config, options.config["model"]["sample_period_s"])
        InputGuardSettings.from_config(options.config)  # [slave.safety]'s cross-key checks
    # before Warp's, the recorder's and Zenoh's threads start: they inherit these CPUs
    placement = place_other_threads(options.runner)
    with exit_on_config_error():
        analysis, refused = run_preflight(options.config, args, "haptic-slave", side="slave",
                                          clay_damping_N_s_per_m=max_block_damping(scenario))
    if refused is not None:
        return refused
    import warp

    warp.config.log_level = warp.LOG_WARNING  # no start-up banner
    warp.config.quiet = True
    with exit_on_config_error():
        node = SlaveNode.from_config(options.config, scenario)
    with exit_on_link_error("haptic-slave"):
        return run_slave(node, options, args, {"scenario": scenario.name,
                                               "analysis": analysis.as_dict(), **placement})


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
    recorded to MCAP (common/run_recording.py), the file closed properly on every way out."""
    recording = None
    if getattr(args, "record", None):
        recording = RunRecording(args.record, "slave", SLAVE_RECORD_COLUMNS,
                                 node.sample_period_s, state_every=args.record_every)
    try:
        return _run_slave(node, options, args, extra_summary, recording)
    finally:
        if recording is not None:
            recording.close(time.time_ns(), None)


def _record_clay(recording: RunRecording, state: Any, log_time_ns: int,
                 layout: bool) -> None:
    """The workpiece's layout (once) and its reduced height map into the recording."""
    from haptic.common.heightmap_codec import reduction_factors
    from haptic.slave_sim.clay_view import heights_message, workpiece_layout

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
        from haptic.common.heightmap_codec import reduction_factors
        from haptic.slave_sim.clay_view import workpiece_layout

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


def _run_slave(node: SlaveNode, options: Any, args: argparse.Namespace,
               extra_summary: dict[str, Any], recording: RunRecording | None) -> int:
    period_s = node.sample_period_s
    phase_lock = phase_lock_from(options.config, period_s)
    link_config = options.link
    grid = node.scenario.grid
    margin = WORK_AREA_MARGIN_M
    ratio = node.position_ratio
    supervisor = SlaveSupervisor(
        (float(ratio[0]), float(ratio[1])), args.sync_tolerance,
        (grid.x_range_m[0] - margin, grid.x_range_m[1] + margin,
         grid.y_range_m[0] - margin, grid.y_range_m[1] + margin),
        link_config.max_message_age_s, link_config.resync_messages,
        grid_m=(grid.x_range_m[0], grid.x_range_m[1], grid.y_range_m[0], grid.y_range_m[1]))
    watchdog = supervisor.watchdog
    guard = InputGuard(InputGuardSettings.from_config(options.config), period_s,
                       events=supervisor.events)
    inert = InertMonitor(options.config["supervision"]["inert_after_s"],
                         events=supervisor.events)
    max_age_s = link_config.max_message_age_s
    trace = TraceRecorder(SLAVE_TRACE_COLUMNS, args.trace_every)
    state = node.initial_state(1)
    node.safe_stop(state)
    resync = ToolResync(node)  # to the handle through the clay at a bounded speed
    stages = StageTimes(TICK_STAGES)
    zero_force = np.zeros((1, 2))
    path_every = max(1, args.trace_every)
    tool_path = ToolPath()  # bounded memory (slave_sim/tool_path.py)
    fh = np.zeros((1, 2))
    yh = state.handle_position_m.copy()
    flags_box = {"max_force": 0.0, "ft": np.zeros(2), "engagement": 0.0, "removed": 0.0}
    run = None
    zenoh_threads: dict[str, object] = {}
    with StopSignals() as signals, Link(link_config) as link:
        print(f"haptic-slave: {node.scenario.name}, environment {node.environment_kind}; "
              f"waiting for the master on {link_config.key_prefix} (connect "
              f"{','.join(link_config.connect) or '-'}, listen "
              f"{','.join(link_config.listen) or '-'})", file=sys.stderr, flush=True)
        if not link.wait_for_peer(args.peer_wait, lambda: signals.requested):
            if signals.requested:
                print("haptic-slave: stopped before the master came", file=sys.stderr)
                return 0
            print(f"haptic-slave: no master after {args.peer_wait:g} s", file=sys.stderr)
            return 1
        zenoh_threads.update(prioritise_zenoh_threads(options.runner))
        realtime_start_ns = time.time_ns()
        perf_start_ns = time.perf_counter_ns()
        clay_recorded = recording is not None and node.environment_kind == "clay"
        if recording is not None:
            recording.start(realtime_start_ns, perf_start_ns, options.config)
            if clay_recorded:
                recording.add_channel("/slave/workpiece")
                recording.add_channel("/slave/clay")
                _record_clay(recording, state, realtime_start_ns, layout=True)
        status_every = max(1, round(0.1 / period_s))  # 10 Hz
        cursor = EventCursor()
        display = None
        if getattr(args, "display", False) and link.session is not None:
            display = _display_publisher(link, node, state, recording)
        view_every = display.state_every(period_s) if display is not None else 1

        clock = time.perf_counter_ns
        fh_row, yh_row = fh, yh  # the newest handle message, updated in place
        tdpa_peer = PassivityLink(node.passivity is not None)  # energy_J on the wire

        def step(tick: int, now_ns: int) -> None:
            now_s = (now_ns - perf_start_ns) * 1e-9
            # poll: the newest handle message whose delivery time has come
            message = link.poll()
            if message is not None:  # a peer in the other [control] mode: refused
                tdpa_peer.check(message)
            poll_ns = clock()
            # supervise: input bounds (slave_sim/input_guard.py), phase lock, watchdog, resync,
            # work-area guard (slave_sim/supervisor.py)
            fresh = message is not None and guard.admit(message, now_s)
            if not fresh:
                message = None  # a fault is not an input
            if fresh and phase_lock is not None:
                if link.last_delivery_measured:
                    runner.shift_schedule(phase_lock.update(link.receive.last_delivery_ns,
                                                            link.last_poll_ns))
                else:
                    phase_lock.skip_unmeasured()
            if fresh:
                fh_row[0] = guard.force_N  # bounded
                yh_row[0] = guard.position_m
                if state.passivity is not None:
                    tdpa_peer.receive(state.passivity, message)
            if supervisor.receive(message):
                resync.step(state, yh, now_s)  # to the held handle, cutting (resync.py)
            tool_row = state.tool[0]
            transition = supervisor.update(now_s, fresh, (tool_row[0], tool_row[2]),
                                           link.silence_s(), link.peer_alive, guard.faulted)
            if transition is Transition.RESUME:
                node.resume(state)
            elif transition is Transition.STOP:
                node.safe_stop(state)
            running = supervisor.running
            inert.update(now_s, link.peer_alive and link.silence_s() < max_age_s, running,
                         supervisor.stop_reason())
            supervise_ns = clock()
            # node: Ch2/Ct2, the tool and the clay
            out = node.step(state, fh if running else zero_force, yh)
            ft = out.tool_force_N[0]
            position = out.tool_position_m[0]
            velocity = out.tool_velocity_m_s[0]
            engagement = float(out.engagement[0])
            removed = _removed_total_m3(state)
            # FORCES_ENABLED: this side is ready (link in sync, tool at the handle or running);
            # the master enables its forces on it, the slave runs once the master has.
            ready_flag = supervisor.ready
            flags = Flags.FORCES_ENABLED if ready_flag else Flags.SAFE_STATE
            if out.cutting[0]:
                flags |= Flags.IN_CONTACT
            node_ns = clock()
            # send: the tool force, position and velocity, the clay's status
            link.send_tool((float(ft[0]), float(ft[1])), (float(position[0]), float(position[1])),
                           (float(velocity[0]), float(velocity[1])), engagement, removed,
                           flags | tdpa_peer.flags, tdpa_peer.sent_J(state))
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
                              float(out.cutting[0]), float(running)))
            else:
                trace.skip()
            if recording is not None:
                vt = out.actuator_force_N[0]
                recording.state(tick, now_ns, (
                    now_s, float(fh[0, 0]), float(fh[0, 1]), float(yh[0, 0]), float(yh[0, 1]),
                    float(position[0]), float(position[1]), float(velocity[0]),
                    float(velocity[1]), float(ft[0]), float(ft[1]), float(vt[0]), float(vt[1]),
                    engagement, float(out.cutting[0]), removed, float(running)))
            if display is not None and tick % view_every == 0:
                display.offer_state({
                    "tool_force_N": [float(ft[0]), float(ft[1])],
                    "tool_position_m": [float(position[0]), float(position[1])],
                    "tool_velocity_m_s": [float(velocity[0]), float(velocity[1])],
                    "clay_engagement": engagement, "removed_volume_m3": removed,
                    "in_contact": bool(out.cutting[0]), "forces_enabled": ready_flag,
                    "safe_state": not ready_flag})
            if tick % status_every == 0 and (recording is not None or display is not None):
                figures = link.summary()
                figures["watchdog_state"] = watchdog.state.value
                figures["watchdog_trips"] = watchdog.trips
                figures["running"] = running
                new_events = cursor.new((watchdog.events, supervisor.events))
                if recording is not None:
                    recording.status(now_ns, figures, new_events)
                if display is not None:
                    display.offer_status(figures, new_events)
            stages.record(now_ns, (poll_ns, supervise_ns, node_ns, send_ns, clock()))

        def status() -> str:
            stats = link.stats()
            return (f"link p50 {stats.one_way_delay_p50_s * 1e3:.3f} ms  loss "
                    f"{stats.loss_ratio * 100:.2f} %  {watchdog.state.value}  ft "
                    f"{flags_box['ft'][0]:+.2f} N  engagement {flags_box['engagement']:.2f}"
                    f"{inert.status()}")

        runner = RealTimeRunner(
            period_s, step, duration_s=options.duration_s, spin_s=options.runner.spin_s,
            realtime=options.runner.realtime, status=status,
            show_status=options.show_status, stop_signals=signals,
        )
        try:
            run = runner.run()
        finally:
            # Safe state: the tool stops; one message with SAFE_STATE before the link closes.
            node.safe_stop(state)
            position = state.tool_position_m()[0]
            link.send_tool((0.0, 0.0), (float(position[0]), float(position[1])), (0.0, 0.0),
                           0.0, flags_box["removed"], Flags.SAFE_STATE)
            if display is not None:
                display.stop()
        link_summary = link.summary()
        presence = [e.as_dict() for e in link.presence_events]
        guard_summary = {**guard.summary(), **inert.summary(run.elapsed_s)}
    for event in presence:
        event["time_s"] = event["time_s"] - realtime_start_ns * 1e-9
    all_events = [e.as_dict() for e in watchdog.events] + supervisor.events + presence
    all_events.sort(key=lambda e: e["time_s"])
    final = state.tool_position_m()[0]
    summary = make_summary(
        run.as_summary(), link_summary, max_abs_force_N=flags_box["max_force"],
        watchdog_trips=watchdog.trips, events=all_events, side="slave",
        watchdog_state=watchdog.state.value, loop_start_time_s=realtime_start_ns * 1e-9,
        removed_volume_m3=flags_box["removed"],
        final_tool_position_m=[float(final[0]), float(final[1])], stages=stages.summary(),
        **zenoh_threads, **guard_summary,
        **(phase_lock.summary() if phase_lock is not None else {"phase_lock_enabled": False}),
        **extra_summary,
    )
    if display is not None:
        summary.update(display.figures)
    traced = trace.arrays()
    summary.update(cutting_figures(traced))
    summary.update(steady_cut_fields(traced))
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
    if recording is not None:
        end_ns = time.time_ns()
        if clay_recorded:
            _record_clay(recording, state, end_ns, layout=False)
        summary.update(recording.close(end_ns, summary))
    if options.json_summary is not None:
        write_json_summary(options.json_summary, summary)
    print(f"haptic-slave: {format_summary(summary)}", file=sys.stderr, flush=True)
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


if __name__ == "__main__":
    sys.exit(main())
