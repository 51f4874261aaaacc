"""The networked master: the handle hardware, the master node, the link and the watchdog on
the real-time runner (``haptic-master`` without ``--no-link``).

One tick at Ts (docs/programs.md):

1. ``hardware.read()``: the handle force fh and position yh of this SYNC;
2. ``link.poll()``: the newest ``ToolState`` whose delivery time has come (tool force ft,
   tool position, the slave's flags);
3. the watchdog: fresh message? silence? peer alive? and, while re-synchronising, ``in_sync``:
   the slave reports forces enabled and |tool position - Ah1 yh| is below the tolerance on
   both axes;
4. forces enabled: the master node steps (vh = Ch1 fh - Ct1 ft behind the safety layer) and
   the simulated operator is shown ft; otherwise the safe state: the handle holds the
   position it had when the watchdog left ``ok`` (or the start position), no reflected force,
   the compensator is not stepped. Back to ``ok``: a fresh node state at the current position
   whose forces ramp in (``MasterNode.resume``; at the very first start the node's own
   small-force gate applies);
5. ``hardware.write(command)``; ``link.send_handle(fh_used, yh, flags)``, where fh_used is the
   force the compensator used as the node reports it (saturated, scaled by the force ramp;
   zero in the safe state), so that Ch2 at the slave sees the same force as Ch1 here.

Each tick's stages (read, poll, supervise, node, write, send, telemetry) are timed; the
summary's ``stages`` gives their p50/p99 (common/stage_times.py).
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from haptic.common.cli_options import RunOptions
from haptic.common.display import DisplayPublisher, EventCursor
from haptic.common.inert import InertMonitor
from haptic.common.link import Link
from haptic.common.messages import Flags
from haptic.common.model import TeleopModel
from haptic.common.passivity_link import PassivityLink
from haptic.common.run_recording import RunRecording
from haptic.common.runner import RealTimeRunner, StopSignals
from haptic.common.runner_config import place_other_threads, prioritise_zenoh_threads
from haptic.common.stage_times import StageTimes
from haptic.common.summary import format_summary, make_summary, write_json_summary
from haptic.common.trace import TraceRecorder
from haptic.master.hardware import HandleHardware, HardwareError
from haptic.master.node import MasterNode, MasterNodeState, SafetyEvent
from haptic.master.supervisor import MasterSupervisor, Transition

#: The stages of one tick, in order (the summary's ``stages``).
TICK_STAGES = ("read", "poll", "supervise", "node", "write", "send", "telemetry")

#: Default tolerance of the resync position check, m per axis.
DEFAULT_SYNC_TOLERANCE_M = 0.001

#: The columns of ``/master/state`` in the recording (``--record``).
MASTER_RECORD_COLUMNS = (
    "time_s", "handle_force_x_N", "handle_force_y_N", "handle_position_x_m",
    "handle_position_y_m", "received_tool_force_x_N", "received_tool_force_y_N",
    "felt_force_x_N", "felt_force_y_N", "tool_position_x_m", "tool_position_y_m",
    "command_x_m", "command_y_m", "sent_handle_force_x_N", "sent_handle_force_y_N",
    "forces_enabled",
)

MASTER_TRACE_COLUMNS = (
    "time_s", "handle_force_x_N", "handle_force_y_N", "handle_position_x_m",
    "handle_position_y_m", "tool_force_x_N", "tool_force_y_N", "tool_position_x_m",
    "tool_position_y_m", "command_x_m", "command_y_m", "forces_enabled",
)


@dataclass
class MasterLoopOptions:
    """What the networked master needs beyond the run options (units in the names)."""

    peer_wait_s: float | None = None  # None: wait for the slave until stopped
    sync_tolerance_m: float = DEFAULT_SYNC_TOLERANCE_M
    trace_every: int = 10
    trace_path: str | None = None
    record_path: str | None = None  # MCAP file of the run (--record)
    record_every: int = 1
    display: bool = True  # publish status at display rates for haptic-view


@dataclass
class _Loop:
    """The mutable state of one run (the tick closure's)."""

    node_state: MasterNodeState | None = None
    node_offset_s: float = 0.0
    max_force_N: float = 0.0
    node_events: list[dict[str, Any]] = field(default_factory=list)
    last_fh: tuple[float, float] = (0.0, 0.0)
    last_ft: tuple[float, float] = (0.0, 0.0)


def _flush_node_events(loop: _Loop) -> None:
    state = loop.node_state
    if state is None:
        return
    for event in state.events:
        loop.node_events.append(_node_event(event, loop.node_offset_s))
    state.events.clear()


def _node_event(event: SafetyEvent, offset_s: float) -> dict[str, Any]:
    axis = f" [{event.axis}]" if event.axis else ""
    return {"time_s": offset_s + event.time_s, "kind": f"node_{event.kind}",
            "reason": event.reason + axis}


def run_linked_master(
    options: RunOptions,
    model: TeleopModel,
    node: MasterNode,
    hardware: HandleHardware,
    loop_options: MasterLoopOptions,
    extra_summary: dict[str, Any] | None = None,
) -> int:
    """Run the master against the slave until the duration ends or SIGINT/SIGTERM; returns
    the exit status (0; 1 for a hardware error, no slave within ``peer_wait_s``, or a fault
    that latched the safe state: a hardware fault or a trip of the node's safety layer).
    With ``loop_options.record_path`` the run is recorded to MCAP (common/run_recording.py);
    the file is closed properly on every way out."""
    # first: the recorder's, the hardware's and Zenoh's threads inherit these CPUs
    extra_summary = {**place_other_threads(options.runner), **(extra_summary or {})}
    recording = None
    if loop_options.record_path:
        recording = RunRecording(loop_options.record_path, "master", MASTER_RECORD_COLUMNS,
                                 model.sample_period_s, state_every=loop_options.record_every)
    try:
        return _run_linked_master(options, model, node, hardware, loop_options, extra_summary,
                                  recording)
    finally:
        if recording is not None:
            recording.close(time.time_ns(), None)


def _run_linked_master(
    options: RunOptions,
    model: TeleopModel,
    node: MasterNode,
    hardware: HandleHardware,
    loop_options: MasterLoopOptions,
    extra_summary: dict[str, Any] | None,
    recording: RunRecording | None,
) -> int:
    period_s = model.sample_period_s
    ratio = np.array([axis.position_ratio_ah1 for axis in model.axes])
    link_config = options.link
    supervisor = MasterSupervisor((float(ratio[0]), float(ratio[1])),
                                  loop_options.sync_tolerance_m, link_config.max_message_age_s,
                                  link_config.resync_messages)
    watchdog = supervisor.watchdog
    trace = TraceRecorder(MASTER_TRACE_COLUMNS, loop_options.trace_every)
    loop = _Loop()
    stages = StageTimes(TICK_STAGES)
    zenoh_threads: dict[str, object] = {}
    felt_array = np.zeros(2)
    realtime_start_ns = 0
    perf_start_ns = 0
    run = None
    status_code = 0
    with StopSignals() as signals:
        try:
            hardware.configure()
        except HardwareError as error:
            print(f"haptic-master: hardware error: {error}", file=sys.stderr)
            return 1
        try:
            with Link(link_config) as link:
                print(f"haptic-master: waiting for the slave on {link_config.key_prefix} "
                      f"(listen {','.join(link_config.listen) or '-'}, connect "
                      f"{','.join(link_config.connect) or '-'})", file=sys.stderr, flush=True)
                if not link.wait_for_peer(loop_options.peer_wait_s, lambda: signals.requested):
                    if signals.requested:
                        print("haptic-master: stopped before the slave came", file=sys.stderr)
                        return 0
                    print(f"haptic-master: no slave after {loop_options.peer_wait_s:g} s",
                          file=sys.stderr)
                    return 1
                zenoh_threads.update(prioritise_zenoh_threads(options.runner))
                hardware.activate()
                reading = hardware.read()
                supervisor.start(reading.position_m)
                realtime_start_ns = time.time_ns()
                perf_start_ns = time.perf_counter_ns()
                if recording is not None:
                    recording.start(realtime_start_ns, perf_start_ns, options.config)
                status_every = max(1, round(0.1 / period_s))  # 10 Hz
                cursor = EventCursor()
                display = None
                if loop_options.display and link.session is not None:
                    display = DisplayPublisher(link.session, link_config.key_prefix,
                                               "master").start()
                view_every = display.state_every(period_s) if display is not None else 1

                clock = time.perf_counter_ns
                inert = InertMonitor(options.config["supervision"]["inert_after_s"],
                                     events=loop.node_events)
                max_age_s = link_config.max_message_age_s
                gate_reason = (f"the start-up gate waits for |fh| < "
                               f"{node.safety.ramp_small_force_N:g} N "
                               f"({node.safety.ramp_small_samples} samples): the operator pushes")
                zero_force = (0.0, 0.0)
                tdpa_peer = PassivityLink(node.passivity is not None)

                def step(tick: int, now_ns: int) -> None:
                    nonlocal reading
                    # read: this SYNC's handle force and position
                    if tick > 0:
                        reading = hardware.read()
                    fhx, fhy = reading.force_N.tolist()
                    yhx, yhy = reading.position_m.tolist()
                    read_ns = clock()
                    # poll: the newest tool message whose delivery time has come
                    message = link.poll()
                    if message is not None:  # a peer in the other [control] mode: refused
                        tdpa_peer.check(message)
                    poll_ns = clock()
                    # supervise: watchdog, resync check, fault latch (master/supervisor.py)
                    now_s = (now_ns - perf_start_ns) * 1e-9
                    if reading.events:  # e.g. a drive's statusword warning bits
                        loop.node_events.extend({"time_s": now_s, "kind": "hardware_event",
                                                 "reason": text} for text in reading.events)
                    transition = supervisor.update(now_s, message, (yhx, yhy), reading.faults,
                                                   reading.cycle, link.silence_s(),
                                                   link.peer_alive)
                    if transition is not Transition.NONE:
                        hardware.present_forces_enabled(supervisor.enabled)
                    if transition is Transition.ACTIVATE or transition is Transition.RESUME:
                        _flush_node_events(loop)
                        position = np.nan_to_num(reading.position_m)[None, :]
                        previous = loop.node_state
                        loop.node_state = (node.activate(position)
                                           if transition is Transition.ACTIVATE
                                           else node.resume(position))
                        if previous is not None and previous.passivity is not None:
                            loop.node_state.passivity.continue_from(previous.passivity)
                        loop.node_offset_s = now_s
                    enabled = supervisor.enabled
                    tool = supervisor.tool
                    supervise_ns = clock()
                    # node: vh = Ch1 fh - Ct1 ft behind the safety layer, or the safe state
                    if enabled:
                        state = loop.node_state
                        ftx, fty = tool.tool_force_N if tool is not None else zero_force
                        state.inputs[0] = (fhx, fhy, yhx, yhy, ftx, fty)
                        if state.passivity is not None and tool is not None:
                            state.peer_energy_J[0] = tdpa_peer.peer_energy(state.passivity,
                                                                           tool)
                        command = node.step_inputs(state)[0]
                        if state.faulted[0]:
                            supervisor.note_node_fault()
                        # what the compensator used: saturated, scaled by the force ramp (the
                        # slave's Ch2 integrates exactly this force)
                        sent = state.handle_force_used_N[0].tolist()
                        felt = state.tool_force_used_N[0].tolist()
                        flags = Flags.FORCES_ENABLED
                    else:
                        command = supervisor.hold_m
                        sent = felt = zero_force
                        flags = Flags.SAFE_STATE
                    node_ns = clock()
                    # write: the handle command (and, on a simulated rig, the felt force)
                    felt_array[0] = felt[0]
                    felt_array[1] = felt[1]
                    hardware.present_tool_force(felt_array)
                    hardware.write(command)
                    write_ns = clock()
                    # send: the force the compensator used and the handle position
                    link.send_handle(sent, (yhx, yhy), flags | tdpa_peer.flags,
                                     tdpa_peer.sent_J(loop.node_state))
                    send_ns = clock()
                    # telemetry: summary figures, trace, recording, display
                    inert.update(now_s, link.peer_alive and link.silence_s() < max_age_s,
                                 enabled and bool(loop.node_state.forces_enabled[0]),
                                 gate_reason if enabled else "node faulted" if supervisor.faulted
                                 else f"watchdog {supervisor.watchdog.state.value}: the resync "
                                 "does not complete")
                    magnitude = math.hypot(felt[0], felt[1])
                    if magnitude > loop.max_force_N:
                        loop.max_force_N = magnitude
                    loop.last_fh = (fhx, fhy)
                    loop.last_ft = felt
                    cx, cy = command.tolist()
                    if trace.due():
                        tool_pos = (tool.tool_position_m if tool is not None
                                    else (math.nan, math.nan))
                        trace.record((now_s, fhx, fhy, yhx, yhy, felt[0], felt[1], tool_pos[0],
                                      tool_pos[1], cx, cy, float(enabled)))
                    else:
                        trace.skip()
                    if recording is not None:
                        if tool is not None:
                            rft = tool.tool_force_N
                            tool_pos = tool.tool_position_m
                        else:
                            rft = tool_pos = (math.nan, math.nan)
                        recording.state(tick, now_ns, (
                            now_s, fhx, fhy, yhx, yhy, rft[0], rft[1], felt[0], felt[1],
                            tool_pos[0], tool_pos[1], cx, cy, sent[0], sent[1], float(enabled)))
                    if display is not None and tick % view_every == 0:
                        display.offer_state({
                            "handle_force_N": [fhx, fhy], "handle_position_m": [yhx, yhy],
                            "felt_force_N": [felt[0], felt[1]], "forces_enabled": enabled,
                            "safe_state": not enabled})
                    if tick % status_every == 0 and (recording is not None
                                                     or display is not None):
                        figures = link.summary()
                        figures["watchdog_state"] = watchdog.state.value
                        figures["watchdog_trips"] = watchdog.trips
                        figures["forces_enabled"] = enabled
                        new_events = cursor.new((watchdog.events, supervisor.events,
                                                 loop.node_events))
                        if recording is not None:
                            recording.status(now_ns, figures, new_events)
                        if display is not None:
                            display.offer_status(figures, new_events)
                    stages.record(now_ns, (read_ns, poll_ns, supervise_ns, node_ns, write_ns,
                                           send_ns, clock()))

                def status() -> str:
                    stats = link.stats()
                    return (f"link p50 {stats.one_way_delay_p50_s * 1e3:.3f} ms  loss "
                            f"{stats.loss_ratio * 100:.2f} %  {watchdog.state.value}  fh "
                            f"{loop.last_fh[0]:+.2f} N  ft {loop.last_ft[0]:+.2f} N"
                            f"{inert.status()}")

                runner = RealTimeRunner(
                    period_s, step, duration_s=options.duration_s,
                    spin_s=options.runner.spin_s, realtime=options.runner.realtime,
                    status=status, show_status=options.show_status, stop_signals=signals,
                )
                try:
                    run = runner.run()
                finally:
                    # Safe state: hold where the handle is, no reflected force, then tell the
                    # slave (one message with SAFE_STATE) before the link closes.
                    try:
                        final = hardware.read()
                        hold = np.nan_to_num(final.position_m)
                        hardware.present_tool_force(np.zeros(2))
                        hardware.write(hold)
                        link.send_handle((0.0, 0.0), (float(hold[0]), float(hold[1])),
                                         Flags.SAFE_STATE)
                    except Exception as error:  # noqa: BLE001 - shutting down regardless
                        print(f"haptic-master: while stopping: {error}", file=sys.stderr)
                    _flush_node_events(loop)
                    if display is not None:
                        display.stop()
                link_summary = link.summary()
                presence = [e.as_dict() for e in link.presence_events]
                inert_summary = inert.summary(run.elapsed_s)
        except HardwareError as error:
            print(f"haptic-master: hardware error: {error}", file=sys.stderr)
            status_code = 1
        finally:
            try:
                hardware.deactivate()
            except Exception:  # noqa: BLE001 - best effort; cleanup follows
                pass
            hardware.cleanup()
    if run is None:
        return status_code or 1
    for event in presence:
        event["time_s"] = event["time_s"] - realtime_start_ns * 1e-9
    events = ([e.as_dict() for e in watchdog.events] + supervisor.events + loop.node_events
              + presence)
    events.sort(key=lambda e: e["time_s"])
    if supervisor.faulted:
        status_code = 1
    summary = make_summary(
        run.as_summary(), link_summary, max_abs_force_N=loop.max_force_N,
        watchdog_trips=watchdog.trips, events=events, side="master",
        watchdog_state=watchdog.state.value, loop_start_time_s=realtime_start_ns * 1e-9,
        hardware_faults=supervisor.hardware_faults[:50],
        node_faulted=supervisor.faulted, stages=stages.summary(), **zenoh_threads,
        **inert_summary,
        **(extra_summary or {}),
    )
    if display is not None:
        summary.update(display.figures)
    if loop_options.trace_path:
        trace.save(loop_options.trace_path)
        summary["trace"] = str(loop_options.trace_path)
    if recording is not None:
        summary.update(recording.close(time.time_ns(), summary))
    if options.json_summary is not None:
        write_json_summary(options.json_summary, summary)
    print(f"haptic-master: {format_summary(summary)}", file=sys.stderr, flush=True)
    return status_code
