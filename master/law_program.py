"""The networked master in a lane-law mode (``[control] mode`` = ``wave``, ``four-channel``,
``four-channel-tdpa`` or ``mmt``): the handle hardware, the law's master side
(common/control/law_pairs.py, the Warp kernel the comparison's lanes step) and the law's link
(common/wire/law_link.py) on the real-time runner, through the one tick driver.

One tick at Ts::

    read       hardware.read()              fh (the operator's force), yh, faults
    poll       LawPeer.poll()               the newest tool message, the watchdog
    law        ControlPair.master(...)      the handle command; this side's message
    write      hardware.write(command)      (the hold in the safe state)
    send       LawPeer.send(enabled)
    telemetry  trace, recording, status

The safety layer around the law: the operator's force reaches the law clamped to ``[master.
safety] force_limit_N`` (a non-finite axis counts as 0 N), and above ``force_trip_N`` (or on
a hardware fault) the master latches its safe state for the rest of the run (exit status 1);
the handle command moves at most ``velocity_limit_m_per_s``, stays within
:data:`COMMAND_WINDOW_M` of the measured position (inside the drives' following-error window)
and in the work area both sides hold (common/model/work_area.py). A law that commands a
velocity only (wave variables) drives the handle through the integral of its commands, kept
within the same window (no wind-up against the operator's hand). In the safe state (the
watchdog not ``ok``, a latched fault) the law is not stepped and the handle holds where it was
when forces went off; the drives' quick stop and re-enable are the paper mode's
(``stop_motion``, ``resume_motion``).

What the operator feels in these modes is the handle's own motion under the law's command:
the simulated rig's operator is shown the force the hand applies (the laws render the
environment through the handle's motion, not through a separate tool force).
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from typing import Any

import numpy as np

from haptic.common.control.law_pairs import ControlPair, passivity_port
from haptic.common.control.law_settings import LawSettings
from haptic.common.model.passivity import passivity_summary
from haptic.common.model.work_area import SharedWorkArea
from haptic.common.records.trace import TraceRecorder
from haptic.common.runtime.cli_options import RunOptions
from haptic.common.runtime.law_peer import LawPeer, meet_law_peer
from haptic.common.runtime.program_harness import ProgramHarness
from haptic.common.runtime.runner import RunStats, StopSignals
from haptic.common.runtime.tick_driver import Stage, TickDriver
from haptic.common.wire.law_link import LawLink
from haptic.master.hardware.interface import HandleHardware, HandleReading, HardwareError
from haptic.master.program import (
    MasterLoopOptions,
    configure_hardware,
    emulator_placement,
    enable_drives,
)
from haptic.master.settings import SafetySettings
from haptic.master.standalone import early_sync

#: The stages of one tick in a law mode, in order (the summary's ``stages``).
LAW_TICK_STAGES = ("read", "poll", "law", "write", "send", "telemetry")
LAW_MASTER_TRACE_COLUMNS = (
    "time_s", "handle_force_x_N", "handle_force_y_N", "handle_position_x_m",
    "handle_position_y_m", "command_x_m", "command_y_m", "forces_enabled",
)
#: How far the handle command may run ahead of the measured handle position, m: well inside
#: the drives' following-error window (``[master.can] following_error_window_m``, 10 mm).
COMMAND_WINDOW_M = 0.003


@dataclass
class LawMasterGuard:
    """The safety layer around the master's law (see the module): the force limit and trip
    (N), the work area's handle box (m)."""

    safety: SafetySettings
    area: SharedWorkArea

    def operator_force_N(self, force_N: np.ndarray) -> np.ndarray:
        """The operator's force as the law gets it, (1, 2), N: non-finite axes 0, clamped."""
        limit = self.safety.force_limit_N
        return np.clip(np.where(np.isfinite(force_N), force_N, 0.0), -limit, limit)[None, :]

    def trip_reason(self, reading: HandleReading) -> str | None:
        """Why this reading latches the safe state (a hardware fault, a force above the
        trip), or None."""
        if reading.faults:
            return f"hardware fault: {reading.faults[0]}"
        force = reading.force_N
        if np.isfinite(force).all() and float(np.max(np.abs(force))) > self.safety.force_trip_N:
            return (f"operator force {float(np.max(np.abs(force))):.2f} N above the trip "
                    f"{self.safety.force_trip_N:g} N")
        return None

    def held(self, command_m: np.ndarray) -> np.ndarray:
        """The command (2,), m, within the work area's handle box."""
        return np.clip(command_m, self.area.handle_low_m, self.area.handle_high_m)

    def command(self, wanted_m: np.ndarray, previous_m: np.ndarray, measured_m: np.ndarray,
                period_s: float) -> np.ndarray:
        """The handle command (2,), m, the drives may follow: ``wanted_m`` moved at most
        ``velocity_limit_m_per_s`` from the previous command, within :data:`COMMAND_WINDOW_M`
        of the measured position (well inside a drive's following-error window: a law's
        virtual manipulator may run ahead of a handle its servo has not caught up with), in
        the work area's handle box."""
        step = self.safety.velocity_limit_m_per_s * period_s
        command = np.clip(wanted_m, previous_m - step, previous_m + step)
        command = np.clip(command, measured_m - COMMAND_WINDOW_M, measured_m + COMMAND_WINDOW_M)
        return self.held(command)


class LawMasterStages:
    """The master's side of the tick driver in a law mode (see the module)."""

    stage_names = LAW_TICK_STAGES
    schedule_shift_ns = 0

    def __init__(self, control: str, hardware: HandleHardware, peer: LawPeer,
                 pair: ControlPair, guard: LawMasterGuard, harness: ProgramHarness,
                 trace: TraceRecorder) -> None:
        self.control = control
        self.hardware, self.peer, self.pair = hardware, peer, pair
        self.guard, self.harness, self.trace = guard, harness, trace
        self.events: list[dict[str, Any]] = []
        self.reading: HandleReading | None = None
        self.fh = np.zeros((1, 2))
        self.command_m = np.zeros(2)
        self.integrated_m = np.zeros(2)
        self.enabled = False
        #: the drives were given a quick stop (stop_motion) that no resume_motion undid yet
        self.stopped = False
        self.fault: str | None = None
        self.now_s = 0.0
        self.max_force_N = 0.0
        self.non_finite_readings = 0

    def stages(self) -> tuple[Stage, ...]:
        return (self.read, self.poll, self.law, self.write, self.send, self.telemetry)

    def start(self, reading: HandleReading) -> None:
        """Before the first tick: the drives' reading after their enable; the hold there."""
        self.reading = reading
        self.command_m = np.nan_to_num(reading.position_m)
        self.integrated_m = self.command_m.copy()

    def read(self, tick: int, now_ns: int) -> None:
        if tick > 0:
            self.reading = self.hardware.read()
        self.now_s = self.harness.time_s(now_ns)
        reason = self.guard.trip_reason(self.reading) if self.fault is None else None
        if reason is not None:
            self.fault = reason
            self.events.append({"time_s": self.now_s, "kind": "fault", "reason": reason})

    def poll(self, tick: int, now_ns: int) -> None:
        enabled = self.peer.poll(self.now_s) and self.fault is None
        if enabled != self.enabled:
            self._switch(enabled)

    def _switch(self, enabled: bool) -> None:
        """Forces on (the drives re-enabled, the integral from where the handle is) or off
        (the hold where it is, the drives' quick stop)."""
        self.enabled = enabled
        hardware = self.hardware
        hardware.present_forces_enabled(enabled)
        position = np.nan_to_num(self.reading.position_m)
        if enabled:
            self.integrated_m = position.copy()
            if self.stopped:  # re-enabled holding where they are (not at the first start)
                hardware.resume_motion()
                self.stopped = False
        else:
            self.command_m = self.guard.held(position)
            hardware.stop_motion(self.fault or self.peer.watchdog.state_text())
            self.stopped = True

    def law(self, tick: int, now_ns: int) -> None:
        if not self.enabled:
            return
        reading = self.reading
        if not np.isfinite(reading.position_m).all():
            self.non_finite_readings += 1  # a missed PDO: hold this tick
            return
        self.fh = fh = self.guard.operator_force_N(reading.force_N)
        peer = self.peer
        position, velocity = self.pair.master(fh, peer.message, peer.fresh, peer.outgoing)
        period_s = self.harness.period_s
        if position is None:
            window = COMMAND_WINDOW_M
            self.integrated_m = np.clip(self.integrated_m + velocity[0] * period_s,
                                        reading.position_m - window, reading.position_m + window)
            wanted = self.integrated_m
        else:
            wanted = position[0]
        self.command_m = self.guard.command(wanted, self.command_m, reading.position_m,
                                            period_s)

    def write(self, tick: int, now_ns: int) -> None:
        self.hardware.present_tool_force(self.fh[0] if self.enabled else np.zeros(2))
        self.hardware.write(self.command_m)

    def send(self, tick: int, now_ns: int) -> None:
        self.peer.send(self.enabled)

    def telemetry(self, tick: int, now_ns: int) -> None:
        reading = self.reading
        fhx, fhy = reading.force_N.tolist()
        if self.enabled:
            self.max_force_N = max(self.max_force_N, math.hypot(fhx, fhy))
        if self.trace.due():
            yhx, yhy = reading.position_m.tolist()
            self.trace.record((self.now_s, fhx, fhy, yhx, yhy, float(self.command_m[0]),
                               float(self.command_m[1]), float(self.enabled)))
        else:
            self.trace.skip()
        self.harness.status(tick, now_ns, self.peer.watchdog, (self.peer.watchdog.events,
                                                               self.events),
                            forces_enabled=self.enabled)

    def stop_safely(self) -> None:
        """Hold where the handle is, then tell the slave (SAFE_STATE | STOPPING)."""
        try:
            hold = np.nan_to_num(self.hardware.read().position_m)
            self.hardware.present_tool_force(np.zeros(2))
            self.hardware.write(hold)
            self.peer.send_stop()
        except Exception as error:  # noqa: BLE001 - shutting down regardless
            self.harness.say(f"while stopping: {error}")

    def status_text(self) -> str:
        return self.harness.status_line(self.peer.watchdog,
                                        f"fh {self.fh[0, 0]:+.2f} N  {self.control}")


def run_law_master(options: RunOptions, control: str, settings: LawSettings,
                   hardware: HandleHardware, guard: LawMasterGuard,
                   loop_options: MasterLoopOptions, extra_summary: dict[str, Any]) -> int:
    """Run the master's side of ``control`` against the slave until the duration ends or
    SIGINT/SIGTERM; returns the exit status (0; 1 for a hardware error, no slave within
    ``peer_wait_s`` or a latched fault). Raises LinkOpenError for a slave that runs another
    control mode (the pairing refuses it)."""
    with StopSignals() as signals:
        if not configure_hardware(hardware):
            return 1
        extra_summary = {**extra_summary, **emulator_placement(hardware), **hardware.summary(),
                         "control": control}
        try:
            with LawLink(options.link, control) as link:
                return _run_linked(options, control, settings, hardware, guard, loop_options,
                                   extra_summary, link, signals)
        except HardwareError as error:
            print(f"haptic-master: hardware error: {error}", file=sys.stderr)
            return 1
        finally:
            try:
                hardware.deactivate()
            except Exception:  # noqa: BLE001 - best effort; cleanup follows
                pass
            hardware.cleanup()


def _run_linked(options: RunOptions, control: str, settings: LawSettings,
                hardware: HandleHardware, guard: LawMasterGuard,
                loop_options: MasterLoopOptions, extra_summary: dict[str, Any], link: LawLink,
                signals: StopSignals) -> int:
    """The peer wait, the loop and the summary; returns the exit status."""
    harness = ProgramHarness("haptic-master", "slave", options, link, settings.period_s)
    met = meet_law_peer(harness, link, control, settings, loop_options.peer_wait_s, signals)
    if isinstance(met, int):
        return met
    pair, peer = met
    trace = TraceRecorder(LAW_MASTER_TRACE_COLUMNS, loop_options.trace_every)
    stages = LawMasterStages(control, hardware, peer, pair, guard, harness, trace)
    driver = TickDriver([stages])
    harness.start()
    run: RunStats = harness.run(driver, stages.status_text, signals, stages.stop_safely,
                                lead=early_sync(hardware),
                                lead_s=options.config["master"]["can"]["sync_lead_s"],
                                before_loop=lambda: stages.start(enable_drives(hardware)))
    summary = harness.summary(run, peer.watchdog, stages.max_force_N,
                              (peer.watchdog.events, stages.events),
                              stages=driver.stage_times[0].summary(),
                              node_faulted=stages.fault is not None,
                              non_finite_readings=stages.non_finite_readings,
                              final_handle_position_m=np.nan_to_num(
                                  stages.reading.position_m).tolist(),
                              **passivity_summary(passivity_port(pair, "master"), False),
                              **extra_summary)
    if loop_options.trace_path:
        trace.save(loop_options.trace_path)
        summary["trace"] = str(loop_options.trace_path)
    harness.finish(summary)
    return 1 if stages.fault is not None else 0


__all__ = ["COMMAND_WINDOW_M", "LAW_MASTER_TRACE_COLUMNS", "LAW_TICK_STAGES", "LawMasterGuard",
           "LawMasterStages", "run_law_master"]
