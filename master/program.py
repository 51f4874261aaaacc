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

The one tick driver (common/runtime/tick_driver.py) runs the tick's stages (read, poll,
supervise, node, write, send, telemetry: master/program_stages.py) and times them; the
summary's ``stages`` gives their p50/p99 (common/runtime/stage_times.py).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from typing import Any

from haptic.common.model.passivity import passivity_summary
from haptic.common.model.teleop import TeleopModel
from haptic.common.records.run_recording import RunRecording
from haptic.common.records.trace import TraceRecorder
from haptic.common.ros2.options import start_ros2
from haptic.common.runtime.cli_options import RunOptions
from haptic.common.runtime.display import DisplayPublisher
from haptic.common.runtime.inert import InertMonitor
from haptic.common.runtime.program_harness import ProgramHarness, recording_for
from haptic.common.runtime.runner import RunStats, StopSignals
from haptic.common.runtime.runner_config import place_other_threads
from haptic.common.runtime.tick_driver import TickDriver
from haptic.common.runtime.watchdog import DEFAULT_SYNC_TOLERANCE_M
from haptic.common.wire.link import Link
from haptic.master.hardware.interface import HandleHardware, HandleReading, HardwareError
from haptic.master.margin_governor import MarginGovernor
from haptic.master.node import MasterNode
from haptic.master.program_stages import (
    MASTER_TRACE_COLUMNS,
    TICK_STAGES,
    LinkedMasterStages,
    position_for_the_wire,
)
from haptic.master.standalone import early_sync
from haptic.master.supervisor import MasterSupervisor
from haptic.master.tick import MasterTick
from haptic.master.tool_guard import ToolGuardSettings, ToolInputGuard

__all__ = ["MASTER_RECORD_COLUMNS", "MASTER_TRACE_COLUMNS", "TICK_STAGES", "WARM_CAN_CYCLES",
           "MasterLoopOptions", "configure_hardware", "device_process_cpu", "emulator_placement",
           "enable_drives",
           "position_for_the_wire", "run_linked_master"]

#: CAN cycles the master runs on its loop's CPU right before the first tick, once the
#: drives are enabled (the command held: what the first ticks do): run cold, the emulated
#: drives made the loop's first ticks wait for their answer and overrun
#: (docs/measurements/master_start.md).
WARM_CAN_CYCLES = 3


def enable_drives(hardware: HandleHardware) -> HandleReading:
    """Enable the drives (``activate``) and run :data:`WARM_CAN_CYCLES` cycles; returns the
    last reading. For the runner's last moment before the first tick: from enable on only
    the loop's reads send the master's heartbeat, and the work before the loop (the heap's
    collection and freeze among it) can take a good part of the drives' 0.3 s heartbeat
    consumer time (docs/measurements/master_start.md)."""
    hardware.activate()
    reading = hardware.read()
    for _ in range(WARM_CAN_CYCLES - 1):
        reading = hardware.read()
    return reading


def configure_hardware(hardware: HandleHardware) -> bool:
    """``hardware.configure()``; False (the error said on stderr) when it fails."""
    try:
        hardware.configure()
    except HardwareError as error:
        print(f"haptic-master: hardware error: {error}", file=sys.stderr)
        return False
    return True


#: The columns of ``/master/state`` in the recording (``--record``).
MASTER_RECORD_COLUMNS = (
    "time_s", "handle_force_x_N", "handle_force_y_N", "handle_position_x_m",
    "handle_position_y_m", "received_tool_force_x_N", "received_tool_force_y_N",
    "felt_force_x_N", "felt_force_y_N", "tool_position_x_m", "tool_position_y_m",
    "command_x_m", "command_y_m", "sent_handle_force_x_N", "sent_handle_force_y_N",
    "forces_enabled",
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
        return _LinkedMaster(options, model, node, hardware, loop_options, extra_summary,
                             recording).run()


class _LinkedMaster:
    """One run of the networked master: the hardware's lifecycle around the link, the peer
    wait, the tick driver over :class:`LinkedMasterStages`, the summary."""

    def __init__(self, options: RunOptions, model: TeleopModel, node: MasterNode,
                 hardware: HandleHardware, loop_options: MasterLoopOptions,
                 extra_summary: dict[str, Any], recording: RunRecording | None) -> None:
        self.options = options
        self.model = model
        self.node = node
        self.hardware = hardware
        self.loop_options = loop_options
        self.extra_summary = extra_summary
        self.recording = recording
        link_config = options.link
        ratio = [axis.position_ratio_ah1 for axis in model.axes]
        self.tool_guard = ToolInputGuard(ToolGuardSettings.from_config(options.config),
                                         model.sample_period_s)
        self.supervisor = MasterSupervisor((float(ratio[0]), float(ratio[1])),
                                           loop_options.sync_tolerance_m,
                                           link_config.max_message_age_s,
                                           link_config.resync_messages, self.tool_guard)
        self.tick = MasterTick(node, [self.supervisor])  # supervise and node (master/tick.py)
        self.trace = TraceRecorder(MASTER_TRACE_COLUMNS, loop_options.trace_every)
        self.events: list[dict[str, Any]] = []  # the node's, the hardware's, the switch's
        self.inert = InertMonitor(options.config["supervision"]["inert_after_s"],
                                  events=self.events)
        self.ros2: Any | None = None
        self.harness: ProgramHarness | None = None

    def run(self) -> int:
        """The run; returns the exit status."""
        status_code = 0
        run = None
        hardware = self.hardware
        with StopSignals() as signals:
            if not configure_hardware(hardware):
                return 1
            self.extra_summary.update(emulator_placement(hardware))
            self.extra_summary.update(hardware.summary())  # e.g. the CAN drives' fallbacks
            try:
                with Link(self.options.link) as link:
                    run = self._run_linked(link, signals)
            except HardwareError as error:
                print(f"haptic-master: hardware error: {error}", file=sys.stderr)
                status_code = 1
            finally:
                self._shut_down()
        if isinstance(run, int):  # the slave did not come (or a stop came first)
            return run
        if run is None:
            return status_code or 1
        self._finish(run)
        return 1 if self.supervisor.faulted else status_code

    def _shut_down(self) -> None:
        """The hardware disabled and cleaned up, ROS 2's tokens withdrawn."""
        try:
            self.hardware.deactivate()
        except Exception:  # noqa: BLE001 - best effort; cleanup follows
            pass
        self.hardware.cleanup()
        if self.ros2 is not None:  # the tokens withdrawn, the session closed
            self.ros2.stop()
            self.extra_summary.update(self.ros2.figures)

    def _run_linked(self, link: Link, signals: StopSignals) -> RunStats | int:
        """The peer wait, then the loop; the exit status when the slave did not come."""
        options, hardware = self.options, self.hardware
        period_s = self.model.sample_period_s
        harness = self.harness = ProgramHarness("haptic-master", "slave", options, link,
                                                period_s, self.recording)
        # the ROS 2 bridge process first: it joins its router while the slave comes
        self.ros2 = start_ros2(options.config, "master", period_s, say=harness.say,
                               loop_counts=harness.loop_counts)
        came = harness.wait_for_peer(self.loop_options.peer_wait_s, signals)
        if came is not None:
            return came
        # the node state the loop's ACTIVATE fills in place, made and first launched here
        # (at the handle's position, the drives still disabled): made in the tick, its
        # supervise stage took longer than the period
        self.tick.prepare(hardware.read().position_m)
        harness.start()
        if self.loop_options.display and link.session is not None:
            harness.attach_display(DisplayPublisher(
                link.session, options.link.key_prefix, "master").start())
        stages = LinkedMasterStages(
            hardware, link, self.tick, harness, self.model.ch1_gain_k,
            self.loop_options.governor, self.loop_options.allow_unstable, self.trace,
            self.recording, self.inert, self.events, self.ros2)
        self.stages = stages
        self.driver = TickDriver([stages])
        device_cpu_start_s = hardware.device_process_cpu_s()
        run = harness.run(self.driver, stages.status_text, signals, stages.stop_safely,
                          lead=early_sync(hardware),
                          lead_s=options.config["master"]["can"]["sync_lead_s"],
                          before_loop=lambda: stages.start(enable_drives(hardware)))
        self.extra_summary.update(self.inert.summary(run.elapsed_s))
        self.extra_summary.update(device_process_cpu(
            device_cpu_start_s, hardware.device_process_cpu_s(), run.elapsed_s))
        return run

    def _finish(self, run: RunStats) -> None:
        """The summary, the trace, the recording closed (ProgramHarness.finish)."""
        harness, supervisor, governor = self.harness, self.supervisor, self.loop_options.governor
        watchdog = supervisor.watchdog
        state = self.tick.state
        summary = harness.summary(
            run, watchdog, self.stages.max_force_N, self.stages.event_lists(),
            hardware_faults=supervisor.hardware_faults[:50], node_faulted=supervisor.faulted,
            stages=self.driver.stage_times[0].summary(),
            work_area_holds=supervisor.work_area_stops,
            slave_stop_holds=supervisor.peer_stops - supervisor.work_area_stops,
            stepped_time_s=run.steps * self.model.sample_period_s,
            **self.tool_guard.summary(),
            **(governor.summary() if governor is not None else {}),
            **passivity_summary(state.passivity if state is not None else None,
                                self.node.passivity_standby),
            **self.extra_summary)
        if self.loop_options.trace_path:
            self.trace.save(self.loop_options.trace_path)
            summary["trace"] = str(self.loop_options.trace_path)
        harness.finish(summary)
