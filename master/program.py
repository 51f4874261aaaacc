"""The networked master: the handle hardware, the master node, the link and the watchdog on
the real-time runner (``haptic-master`` without ``--no-link``).

One tick at Ts (docs/programs.md):

1. ``hardware.read()``: the handle force fh and position yh of this SYNC (on the CAN
   backends the runner sent it ``[master.can] sync_lead_s`` before the tick, while the loop
   waited: ``hardware.sync()``, so the devices' answers are there already);
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
5. ``hardware.write(command)``; ``link.send_handle(fh_used, yh, flags, ..., force_scale)``,
   where fh_used is the force the compensator used as the node reports it (saturated, scaled
   by the force ramp; zero in the safe state), so that Ch2 at the slave sees the same force as
   Ch1 here, and force_scale the ramp's factor, which the slave applies to its Ct2's input as
   Ct1 here had it applied to the received tool force.

Each tick's stages (read, poll, supervise, node, write, send, telemetry) are timed; the
summary's ``stages`` gives their p50/p99 (common/runtime/stage_times.py).
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from haptic.common.model.passivity import passivity_summary
from haptic.common.model.teleop import TeleopModel
from haptic.common.records.run_recording import RunRecording
from haptic.common.records.trace import TraceRecorder
from haptic.common.ros2.options import start_ros2
from haptic.common.runtime.cli_options import RunOptions
from haptic.common.runtime.display import DisplayPublisher
from haptic.common.runtime.inert import InertMonitor
from haptic.common.runtime.program_harness import ProgramHarness, recording_for
from haptic.common.runtime.runner import StopSignals
from haptic.common.runtime.runner_config import place_other_threads
from haptic.common.runtime.stage_times import StageTimes
from haptic.common.runtime.watchdog import DEFAULT_SYNC_TOLERANCE_M
from haptic.common.wire.link import Link
from haptic.common.wire.messages import FLAGS_BY_VALUE, Flags
from haptic.common.wire.passivity_link import PassivityLink
from haptic.master.governor_setup import governor_step
from haptic.master.hardware.interface import HandleHardware, HandleReading, HardwareError
from haptic.master.margin_governor import MarginGovernor
from haptic.master.node import MasterNode
from haptic.master.runner import early_sync
from haptic.master.supervisor import MasterSupervisor, Transition
from haptic.master.tick import MasterTick
from haptic.master.tool_guard import ToolGuardSettings, ToolInputGuard

#: CAN cycles the master runs on its loop's CPU right before the first tick, once the
#: drives are enabled (the command held: what the first ticks do). Without them the loop's
#: second tick waited 0.37-0.53 ms for the drives' answer (the emulated drives, on that CPU,
#: ran cold after the tick before it) and the first ticks overran in every haptic-session
#: run on a 2-core Intel Xeon guest; with one cycle as well; with three, its read 0.24-0.29
#: ms and no overrun at the start in 5 runs (2026-12-05).
WARM_CAN_CYCLES = 3


def _enable_drives(hardware: HandleHardware) -> HandleReading:
    """Enable the drives (``activate``) and run :data:`WARM_CAN_CYCLES` cycles; returns the
    last reading. For the runner's last moment before the first tick: from enable on only
    the loop's reads send the master's heartbeat, and the work before the loop (the heap's
    collection and freeze among it) took 150-215 ms in haptic-session on the 2-core guest,
    against the drives' 0.3 s heartbeat consumer time."""
    hardware.activate()
    reading = hardware.read()
    for _ in range(WARM_CAN_CYCLES - 1):
        reading = hardware.read()
    return reading


#: The stages of one tick, in order (the summary's ``stages``).
TICK_STAGES = ("read", "poll", "supervise", "node", "write", "send", "telemetry")

#: the program's one lane, as a mask (MasterTick.switch_passivity)
_ONE_LANE = np.ones(1, bool)

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
    governor: MarginGovernor | None = None  # the margin governor (master/margin_governor.py)
    allow_unstable: bool = False  # governor beyond every margin: keep running (else trip)


@dataclass
class _Loop:
    """The mutable state of one run (the tick closure's)."""

    max_force_N: float = 0.0
    node_events: list[dict[str, Any]] = field(default_factory=list)
    last_fh: tuple[float, float] = (0.0, 0.0)
    last_ft: tuple[float, float] = (0.0, 0.0)
    #: the last handle position measured on both axes, m (what the wire carries while a
    #: reading is missing)
    last_yh: tuple[float, float] = (0.0, 0.0)


def position_for_the_wire(position_m: tuple[float, float],
                          last_m: tuple[float, float]) -> tuple[float, float]:
    """The handle position (m) to send: the reading where both axes are finite, else the last
    finite one. A missed PDO reads NaN; the node trips on it (master/node.py) and the message
    says SAFE_STATE, but a NaN can never go on the wire (messages.encode refuses it)."""
    x_m, y_m = position_m
    if math.isfinite(x_m) and math.isfinite(y_m):
        return position_m
    return last_m


def device_process_cpu(start_s: float | None, end_s: float | None,
                       elapsed_s: float) -> dict[str, float]:
    """The summary's ``rig_emulator_cpu_s`` (CPU time the devices' own process used over the
    loop, s) and ``rig_emulator_cpu_cores`` (that over the loop's wall time): nothing where
    the devices are not another process of this host, or a reading is missing."""
    if start_s is None or end_s is None or not elapsed_s > 0.0:
        return {}
    used_s = max(end_s - start_s, 0.0)
    return {"rig_emulator_cpu_s": used_s, "rig_emulator_cpu_cores": used_s / elapsed_s}


def emulator_placement(hardware: Any) -> dict[str, Any]:
    """The summary's ``rig_emulator_cpus`` (the CPUs the emulated drives' process was put on:
    the loop's, master/simulated_rig/rig_emulator.py; None: anywhere) and its warning where the
    placement
    was refused (also printed); nothing for hardware without an emulator process."""
    if not hasattr(hardware, "emulator_cpus"):
        return {}
    warning = getattr(hardware, "emulator_cpu_warning", None)
    if warning:
        print(f"haptic-master: {warning}", file=sys.stderr)
    cpus = hardware.emulator_cpus
    return {"rig_emulator_cpus": list(cpus) if cpus is not None else None,
            "rig_emulator_cpu_warning": warning}


def _flush_node_events(loop: _Loop, tick: MasterTick) -> None:
    """The node's safety events so far into the run's events."""
    for time_s, event in tick.take_node_events():
        axis = f" [{event.axis}]" if event.axis else ""
        loop.node_events.append({"time_s": time_s, "kind": f"node_{event.kind}",
                                 "reason": event.reason + axis})


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
    With ``loop_options.record_path`` the run is recorded to MCAP (common/records/run_recording.py);
    the file is closed properly on every way out."""
    # first: the recorder's, the hardware's and Zenoh's threads inherit these CPUs
    extra_summary = {**place_other_threads(options.runner), **(extra_summary or {})}
    with recording_for(loop_options.record_path, "master", MASTER_RECORD_COLUMNS,
                       model.sample_period_s, loop_options.record_every) as recording:
        return _run_linked_master(options, model, node, hardware, loop_options, extra_summary,
                                  recording)


def _run_linked_master(
    options: RunOptions,
    model: TeleopModel,
    node: MasterNode,
    hardware: HandleHardware,
    loop_options: MasterLoopOptions,
    extra_summary: dict[str, Any],
    recording: RunRecording | None,
) -> int:
    period_s = model.sample_period_s
    ratio = np.array([axis.position_ratio_ah1 for axis in model.axes])
    link_config = options.link
    tool_guard = ToolInputGuard(ToolGuardSettings.from_config(options.config), period_s)
    supervisor = MasterSupervisor((float(ratio[0]), float(ratio[1])),
                                  loop_options.sync_tolerance_m, link_config.max_message_age_s,
                                  link_config.resync_messages, tool_guard)
    watchdog = supervisor.watchdog
    tick_stages = MasterTick(node, [supervisor])  # supervise and node (master/tick.py)
    trace = TraceRecorder(MASTER_TRACE_COLUMNS, loop_options.trace_every)
    loop = _Loop()
    stages = StageTimes(TICK_STAGES)
    run = None
    ros2 = None
    status_code = 0
    with StopSignals() as signals:
        try:
            hardware.configure()
        except HardwareError as error:
            print(f"haptic-master: hardware error: {error}", file=sys.stderr)
            return 1
        extra_summary.update(emulator_placement(hardware))
        extra_summary.update(hardware.summary())  # e.g. the CAN drives' fallbacks
        try:
            with Link(link_config) as link:
                harness = ProgramHarness("haptic-master", "slave", options, link, period_s,
                                         recording)
                came = harness.wait_for_peer(loop_options.peer_wait_s, signals)
                if came is not None:
                    return came
                # the node state the loop's ACTIVATE fills in place, made and first launched
                # here (at the handle's position, the drives still disabled): made in the
                # tick, its supervise stage took 0.7-0.8 ms in haptic-session (1.4-1.5 ms with
                # the kernels' first launches), more than the period
                reading = hardware.read()
                tick_stages.prepare(reading.position_m)
                harness.start()
                if loop_options.display and link.session is not None:
                    harness.attach_display(DisplayPublisher(
                        link.session, link_config.key_prefix, "master").start())
                ros2 = start_ros2(options.config, "master", period_s, say=harness.say,
                                  loop_counts=harness.loop_counts)

                clock = time.perf_counter_ns
                inert = InertMonitor(options.config["supervision"]["inert_after_s"],
                                     events=loop.node_events)
                max_age_s = link_config.max_message_age_s
                gate_reason = (f"the start-up gate waits for |fh| < "
                               f"{node.safety.ramp_small_force_N:g} N "
                               f"({node.safety.ramp_small_samples} samples): the operator pushes")
                governor = loop_options.governor
                governor_events = governor.events if governor is not None else []
                nominal_k = model.ch1_gain_k
                # energy_J on the wire; the TDPA flag says the configured mode (a standby
                # layer's run-time switch is Flags.TDPA_SWITCHED, master/tick.py)
                tdpa_peer = PassivityLink(node.passivity is not None
                                          and not node.passivity_standby)
                tdpa_flag_value = int(tdpa_peer.flags)  # or'ed as ints: one lookup a tick

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
                    now_s = harness.time_s(now_ns)
                    if reading.events:  # e.g. a drive's statusword warning bits
                        loop.node_events.extend({"time_s": now_s, "kind": "hardware_event",
                                                 "reason": text} for text in reading.events)
                    transitions = tick_stages.supervise(
                        now_s, (message,), reading.position_m[None, :], (reading.faults,),
                        reading.cycle, (link.silence_s(),), (link.peer_alive,))
                    if transitions[0] is not Transition.NONE:
                        hardware.present_forces_enabled(supervisor.enabled)
                        if transitions[0] is Transition.HOLD:  # the drives' quick stop too
                            hardware.stop_motion(supervisor.stop_reason())
                        elif transitions[0] is Transition.RESUME:  # re-enabled at actual
                            hardware.resume_motion()
                    tool = supervisor.tool
                    gain_k = nominal_k
                    if governor is not None:  # k from the echoed round trip (governor.md)
                        decision = governor_step(governor, link, now_s)
                        gain_k = decision.gain_k
                        if decision.mode_request is not None and node.passivity_standby:
                            # the passivity layer on or off; the slave follows the flag
                            tick_stages.switch_passivity(
                                now_s, _ONE_LANE, decision.mode_request == "tdpa",
                                governor.events[-1]["reason"] if governor.events else "governor")
                            loop.node_events.extend(tick_stages.passivity_events)
                            tick_stages.passivity_events.clear()
                        if supervisor.enabled:
                            tick_stages.state.gain_ratio[0] = gain_k / nominal_k
                            if decision.beyond_margin and not loop_options.allow_unstable:
                                node.trip(tick_stages.state, [0], "governor: round trip beyond "
                                          "the delay margin of every k")
                    supervise_ns = clock()
                    node_state = tick_stages.state
                    if (node_state is not None and node_state.passivity is not None
                            and tool is not None):  # the slave's handed-over energy
                        node_state.peer_energy_J[0] = tdpa_peer.peer_energy(
                            node_state.passivity, tool)
                        # the drift correction's target: the tool in handle coordinates
                        node_state.peer_target_m[0, 0] = (tool.tool_position_m[0]
                                                          / supervisor.ratio_x)
                        node_state.peer_target_m[0, 1] = (tool.tool_position_m[1]
                                                          / supervisor.ratio_y)
                    # node: vh = Ch1 fh - Ct1 ft behind the safety layer, or the safe state;
                    # the node reports what it used (the slave's Ch2 integrates exactly the
                    # handle force Ch1 used; the operator feels the tool force it used)
                    used = tick_stages.control(reading.force_N[None, :],
                                               reading.position_m[None, :])
                    enabled = bool(used.enabled[0])
                    command = used.command_m[0]
                    sent = used.handle_force_used_N[0].tolist()
                    felt = used.tool_force_used_N[0].tolist()
                    node_ns = clock()
                    # write: the handle command (and, on a simulated rig, the felt force)
                    hardware.present_tool_force(used.tool_force_used_N[0])
                    hardware.write(command)
                    write_ns = clock()
                    # send: the force the compensator used and the handle position
                    loop.last_yh = position_for_the_wire((yhx, yhy), loop.last_yh)
                    link.send_handle(sent, loop.last_yh,
                                     FLAGS_BY_VALUE[int(used.flag_values[0]) | tdpa_flag_value],
                                     gain_k,
                                     tdpa_peer.sent_J(tick_stages.state),
                                     float(used.force_scale[0]))
                    send_ns = clock()
                    # telemetry: summary figures, trace, recording, display
                    _flush_node_events(loop, tick_stages)
                    inert.update(now_s, link.peer_alive and link.silence_s() < max_age_s,
                                 enabled and bool(tick_stages.state.forces_enabled[0]),
                                 gate_reason if enabled else "node faulted" if supervisor.faulted
                                 else supervisor.stop_reason() if (supervisor.input_faulted
                                                                   or supervisor.peer_held)
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
                    harness.offer_state(tick, lambda: {
                        "handle_force_N": [fhx, fhy], "handle_position_m": [yhx, yhy],
                        "felt_force_N": [felt[0], felt[1]], "forces_enabled": enabled,
                        "safe_state": not enabled})
                    governed = ({} if governor is None else {
                        "governor_k": governor.gain_k, "governor_round_trip_s": governor.rtt_s})
                    harness.status(tick, now_ns, watchdog, (watchdog.events, supervisor.events,
                                                            loop.node_events, governor_events),
                                   forces_enabled=enabled, **governed)
                    if ros2 is not None:  # off the loop: two reference swaps at their rates
                        ros2.offer(tick, lambda: {
                            "time_s": now_s, "force_N": (fhx, fhy), "position_m": (yhx, yhy),
                            "effort_N": (felt[0], felt[1])}, lambda: {
                            **link.summary(), "watchdog_state": watchdog.state.value,
                            "watchdog_trips": watchdog.trips, "forces_enabled": enabled,
                            "safe_state": not enabled, "safety_events": len(
                                supervisor.events) + len(loop.node_events),
                            **(passivity_summary(tick_stages.state.passivity,
                                                 node.passivity_standby)
                               if tick_stages.state is not None else {})})
                    stages.record(now_ns, (read_ns, poll_ns, supervise_ns, node_ns, write_ns,
                                           send_ns, clock()))

                def gain_k_now() -> float:
                    return governor.gain_k if governor is not None else nominal_k

                def start_drives() -> None:
                    # the drives enabled right before the first tick (_enable_drives), the
                    # loop's hold at where they hold the handle; the first tick takes this
                    # reading
                    nonlocal reading
                    reading = _enable_drives(hardware)
                    tick_stages.start(reading.position_m)
                    loop.last_yh = position_for_the_wire(
                        tuple(reading.position_m.tolist()), tuple(
                            np.nan_to_num(reading.position_m).tolist()))

                def stop_safely() -> None:
                    # Safe state: hold where the handle is, no reflected force, then tell the
                    # slave (one message with SAFE_STATE | STOPPING: it stops its tool at once
                    # and counts no trip) before the link closes.
                    try:
                        final = hardware.read()
                        hold = np.nan_to_num(final.position_m)
                        hardware.present_tool_force(np.zeros(2))
                        hardware.write(hold)
                        link.send_handle((0.0, 0.0), (float(hold[0]), float(hold[1])),
                                         Flags.SAFE_STATE | Flags.STOPPING
                                         | tick_stages.switched_flags()[0],
                                         gain_k_now(), force_scale=0.0)
                    except Exception as error:  # noqa: BLE001 - shutting down regardless
                        print(f"haptic-master: while stopping: {error}", file=sys.stderr)
                    _flush_node_events(loop, tick_stages)

                device_cpu_start_s = hardware.device_process_cpu_s()
                run = harness.run(step, lambda: harness.status_line(
                    watchdog, f"fh {loop.last_fh[0]:+.2f} N  ft {loop.last_ft[0]:+.2f} N"
                    f"{inert.status()}"
                    f"{governor.status() if governor is not None else ''}"), signals,
                    stop_safely, lead=early_sync(hardware),
                    lead_s=options.config["master"]["can"]["sync_lead_s"],
                    before_loop=start_drives)
                inert_summary = inert.summary(run.elapsed_s)
                extra_summary.update(device_process_cpu(
                    device_cpu_start_s, hardware.device_process_cpu_s(), run.elapsed_s))
        except HardwareError as error:
            print(f"haptic-master: hardware error: {error}", file=sys.stderr)
            status_code = 1
        finally:
            try:
                hardware.deactivate()
            except Exception:  # noqa: BLE001 - best effort; cleanup follows
                pass
            hardware.cleanup()
            if ros2 is not None:  # the tokens withdrawn, the session closed
                ros2.stop()
                extra_summary.update(ros2.figures)
    if run is None:
        return status_code or 1
    if supervisor.faulted:
        status_code = 1
    governor = loop_options.governor
    summary = harness.summary(
        run, watchdog, loop.max_force_N, (watchdog.events, supervisor.events, loop.node_events,
                                          governor.events if governor is not None else []),
        hardware_faults=supervisor.hardware_faults[:50], node_faulted=supervisor.faulted,
        stages=stages.summary(), work_area_holds=supervisor.work_area_stops,
        slave_stop_holds=supervisor.peer_stops - supervisor.work_area_stops,
        stepped_time_s=run.steps * model.sample_period_s,
        **tool_guard.summary(), **inert_summary,
        **(governor.summary() if governor is not None else {}),
        **passivity_summary(tick_stages.state.passivity if tick_stages.state is not None
                            else None, node.passivity_standby),
        **extra_summary)
    if loop_options.trace_path:
        trace.save(loop_options.trace_path)
        summary["trace"] = str(loop_options.trace_path)
    harness.finish(summary)
    return status_code
