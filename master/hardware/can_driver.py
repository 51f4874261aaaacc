"""The handle over CAN: two CiA 402 drives in cyclic synchronous position mode and the
two-channel force sensor (DBC), behind :class:`~haptic.master.hardware.interface.HandleHardware`.

One control cycle is one SYNC: :meth:`CanHandleDriver.read` sends SYNC and waits (at most
``pdo_timeout_s``) for both drives' TPDO (TPDO1 unless the EDS fixes another: statusword,
position actual value) and the sensor frame sampled at that SYNC (or, where
:meth:`CanHandleDriver.sync` sent the SYNC ahead of the tick, ``[master.can] sync_lead_s``
before it, collects the frames that came meanwhile); :meth:`CanHandleDriver.write` sends each
drive's RPDO (RPDO1 unless the EDS fixes another: controlword, target position), which the
drive applies at the next SYNC. What each drive's EDS lacks is replaced by a named fallback
(:mod:`haptic.master.hardware.canopen_setup`), logged at configure and listed in
:attr:`CanHandleDriver.fallbacks` and :meth:`CanHandleDriver.summary`. A command
written in cycle k therefore acts over [t_{k+1}, t_{k+2}): zero-order hold plus one sample
of delay, the contract the analysis and the simulated rig use.

Units are converted here and nowhere else: counts <-> m with the lead-screw pitch and the
encoder resolution, raw sensor counts -> N with the configured scale and offset.
"""

from __future__ import annotations

import logging
import math
import struct
import sys
import threading
import time
from typing import Any

import can
import numpy as np
from can.broadcastmanager import ThreadBasedCyclicSendTask

from haptic.master.hardware import cia402
from haptic.master.hardware.bus_load import BusLoad, bus_load, cycle_frames
from haptic.master.hardware.canopen_setup import (
    CSP_SUPPORTED,
    RPDO1_OBJECTS,
    TPDO1_OBJECTS,
    DrivePlan,
    PlanSettings,
    describe,
    plan_drive,
    variable,
)
from haptic.master.hardware.cia402 import DriveState
from haptic.master.hardware.drive_device import load_drive_dictionary
from haptic.master.hardware.force_sensor import STATUS_OK, ForceSensorCodec, load_database
from haptic.master.hardware.interface import (
    HandleHardware,
    HandleReading,
    HardwareError,
    LifecycleState,
)
from haptic.master.hardware.unix_can import send_burst
from haptic.master.settings import CanSettings, master_settings

AXES = ("x", "y")
INT32_MAX = 2**31 - 1
logger = logging.getLogger(__name__)


class CanHandleDriver(HandleHardware):
    """The handle on a CAN bus opened with ``can.Bus(**bus_options)``.

    Parameters
    ----------
    settings:
        Node ids, the drives' EDS files, unit conversions, heartbeats, the bus-load limit,
        CAN FD and the sensor's DBC, scale and offset.
    bus_options:
        Keyword arguments of ``can.Bus`` (interface, channel, bitrate, ...).
    pdo_timeout_s:
        How long :meth:`read` waits for the frames of its SYNC, s.
    sample_period_s:
        Ts, s: the drives' interpolation period (0x60C2) and the bus-load budget.
    """

    def __init__(self, settings: CanSettings, bus_options: dict[str, Any],
                 pdo_timeout_s: float, sample_period_s: float) -> None:
        self.settings = settings
        self.bus_options = dict(bus_options)
        self.pdo_timeout_s = float(pdo_timeout_s)
        self.sample_period_s = float(sample_period_s)
        self.codec = ForceSensorCodec(settings.force_scale_N_per_count,
                                      settings.force_offset_count,
                                      load_database(settings.dbc_file or None))
        self._bus: can.BusABC | None = None
        #: Frames held by :meth:`burst` (None: frames go out as they are sent).
        self._held: list[can.Message] | None = None
        #: Frames :meth:`until_sync` holds for the next SYNC's burst (sent before anything
        #: else that goes out first, so the frames keep their order).
        self._for_sync: list[can.Message] = []
        self._holding_for_sync = False
        self._state = LifecycleState.UNCONFIGURED
        self._cycle = 0
        self._drive_states = [DriveState.NOT_READY_TO_SWITCH_ON] * len(AXES)
        self._last_controlword = [cia402.CW_DISABLE_VOLTAGE] * len(AXES)
        self._target_counts = np.zeros(len(AXES), np.int64)
        self._position_counts = np.zeros(len(AXES), np.int64)
        self._sensor_counter: int | None = None
        self._pending_faults: list[str] = []
        self._pending_events: list[str] = []
        #: a SYNC is out whose PDOs read() has not collected yet (sync()), sent at this
        #: time (time.monotonic(), s), and the drive faults found before it (late EMCYs)
        self._sync_pending = False
        self._sync_sent_s = 0.0
        self._sync_drive_fault = [False, False]
        self.last_reading: HandleReading | None = None
        #: Frames that arrived after their cycle's timeout and were discarded.
        self.late_frames = 0
        #: SDO requests sent again because no reply came within SDO_RESEND_S
        self.sdo_resends = 0
        #: Every EMCY received (axis, error code), in order.
        self.emcy_log: list[tuple[str, int]] = []
        #: The bus-load budget computed at configure.
        self.bus_load: BusLoad | None = None
        #: The drives' identities read at configure (0x1000, 0x1018:1-4), per axis.
        self.identities: list[dict[str, int]] = []
        self._fd = bool(settings.fd)
        #: Print the bus-load budget (one line, stderr) at configure: the real bus's backend.
        self.announce_bus_load = False
        #: per axis, the statusword warning bits not in their healthy state (events on change)
        self._warnings: list[int]
        self._tripped: bool
        #: Why the master stopped the drives (stop_motion), None when it did not.
        self._master_stop: str | None
        self._clear_trip()
        #: since the master's stop: SYNCs, and per axis, taken by the drive, reported late
        self._stop_cycles: int
        self._stop_taken: list[bool]
        self._stop_reported: list[bool]
        self._watch_stop()
        self._heartbeat_period_s = settings.heartbeat_period_s
        self._heartbeat_timeout_s = settings.heartbeat_timeout_s
        #: the master's next heartbeat, the drives' last ones and their losses reported
        self._heartbeat_due_s: float
        self._heartbeat_seen_s: list[float]
        self._heartbeat_lost: list[bool]
        self._expect_heartbeats(0.0)
        self._master_heartbeat = bytes([0x05])  # operational
        #: the master's heartbeat while inactive (a python-can periodic task): configured and
        #: waiting (e.g. for the slave), the loop does not run, but the node is alive and the
        #: disabled drives must not fault; while active, read() sends it, so a stalled loop
        #: stops the drives by their heartbeat consumer
        self._idle_heartbeat: Any = None
        self._idle_guards: list[Any] = []
        #: errors that stopped the idle heartbeat task (bus gone), for diagnosis
        self.idle_heartbeat_errors: list[str] = []
        nodes = settings.node_ids
        #: What configure found in each drive's EDS: the fallbacks taken (one line each,
        #: naming the drive), per drive its PDOs, watchdogs and fallbacks (summary()).
        self.fallbacks: list[str] = []
        self.plans: list[DrivePlan] = []
        self._standard_layout()
        #: frame id -> (kind, axis) of every frame read() acts on.
        self._dispatch: dict[int, tuple[int, int]] = {}
        for axis, node in enumerate(nodes):
            self._dispatch[cia402.TPDO1_BASE + node] = (_TPDO, axis)
            self._dispatch[cia402.EMCY_BASE + node] = (_EMCY, axis)
            self._dispatch[HEARTBEAT_BASE + node] = (_HEARTBEAT, axis)
        self._dispatch[self.codec.frame_id] = (_SENSOR, 0)
        self._sync = can.Message(arbitration_id=cia402.SYNC_COB_ID, data=b"",
                                 is_extended_id=False, is_fd=self._fd,
                                 bitrate_switch=self._fd)
        #: The SYNC counter's overflow value (0x1019) in use, 0 off (set at configure), why.
        self.sync_counter_overflow = 0
        self.sync_counter_note = "SYNC counter not configured yet"
        self._sync_counter = 0  # the last SYNC's counter, 1..overflow
        self._counted_syncs = [
            can.Message(arbitration_id=cia402.SYNC_COB_ID, data=bytes([count]),
                        is_extended_id=False, is_fd=self._fd, bitrate_switch=self._fd)
            for count in range(1, 241)]
        # What this driver sends (NMT, SYNC, its RPDOs, SDO requests, its heartbeat; extra
        # frames by id; PDOs of the drives that stay on unused): an interface that hands a
        # process its own frames back (udp_multicast) does not make them late frames.
        self._own_ids = ({cia402.NMT_COB_ID, cia402.SYNC_COB_ID,
                          HEARTBEAT_BASE + settings.master_node_id}
                         | {cia402.RPDO1_BASE + n for n in nodes}
                         | {cia402.SDO_RX_BASE + n for n in nodes})
        self._own_extended_ids: set[int] = set()

    def _standard_layout(self) -> None:
        """Per axis, until a plan says otherwise (:meth:`_use_plans`): RPDO1 and TPDO1 as
        the driver maps them, the drive's heartbeat watched, no node guarding."""
        #: per axis: whether the master watches the drive's heartbeat (or its answers to
        #: node guarding), whether it is guarded; the guarding requests the master sends
        #: with its heartbeat
        self._heartbeat_supervised = [True, True]
        self._guarded = [False, False]
        self._guard_requests: list[can.Message] = []
        #: per axis: the PDOs' names, COB-IDs and payload codecs (TPDO: the statusword and
        #: the position, in the reverse order where the flag says so; RPDO: packs them)
        self._tpdo_names = ["TPDO1", "TPDO1"]
        self._tpdo_codecs = [_TPDO1, _TPDO1]
        self._tpdo_reversed = [False, False]
        self._rpdo_ids = [cia402.RPDO1_BASE + node for node in self.settings.node_ids]
        self._rpdo_codecs = [_RPDO1, _RPDO1]
        self._rpdo_reversed = [False, False]

    # --- lifecycle -------------------------------------------------------------------

    @property
    def lifecycle_state(self) -> LifecycleState:
        return self._state

    @property
    def drive_states(self) -> tuple[DriveState, DriveState]:
        """CiA 402 state of the x and y drives, from the last statusword read."""
        return (self._drive_states[0], self._drive_states[1])

    def check_bus_load(self) -> BusLoad:
        """The cycle's bus-load budget (:mod:`haptic.master.hardware.bus_load`);
        :class:`HardwareError` naming the options when it is above
        ``[master.can] bus_load_limit``."""
        settings = self.settings
        tpdo = tuple(plan.tpdo.size for plan in self.plans) or (6, 6)
        rpdo = tuple(plan.rpdo.size for plan in self.plans) or (6, 6)
        budget = bus_load(self.sample_period_s, settings.bitrate, self._fd,
                          settings.data_bitrate, settings.bus_load_limit,
                          settings.heartbeat_period_s,
                          cycle_frames(sync_bytes=1 if settings.sync_counter_overflow else 0,
                                       tpdo_bytes=tpdo, rpdo_bytes=rpdo))
        self.bus_load = budget
        if not budget.ok:
            raise HardwareError(budget.refusal())
        return budget

    def configure(self) -> None:
        """Plan each drive's configuration from its EDS and check the bus-load budget (a bad
        EDS or budget never touches a drive), log each fallback taken (one line), open the
        bus, configure each drive by SDO (every write read back, every object the EDS fixes
        read; :mod:`haptic.master.hardware.canopen_setup`), start the nodes (NMT) and take a
        first sample. On any failure every node is left pre-operational and the bus is
        closed."""
        if self._state is not LifecycleState.UNCONFIGURED:
            return
        plans = self._plans()
        budget = self.check_bus_load()
        for line in self.fallbacks:
            logger.warning("haptic-master: %s", line)
        if self.announce_bus_load:
            print(f"haptic-master: {budget.summary()}; {self.sync_counter_note}",
                  file=sys.stderr, flush=True)
        self._sync_counter = 0
        try:
            self._bus = can.Bus(**self.bus_options)
        except (can.CanError, OSError, ValueError, ImportError) as error:
            options = ", ".join(f"{k}={v}" for k, v in self.bus_options.items())
            raise HardwareError(f"cannot open the CAN bus ({options}): {error}") from None
        try:
            # the master's heartbeat from now on: a drive consumes it as soon as its 0x1016 is
            # written, and configuring the other drive by SDO can take longer than its timeout
            self._start_idle_heartbeat()
            for node in self.settings.node_ids:
                self._nmt(cia402.NMT_PRE_OPERATIONAL, node)
            self.identities = []
            for axis, node in enumerate(self.settings.node_ids):
                self._configure_drive(axis, node, plans[axis])
            self._expect_heartbeats(time.monotonic())
            for node in self.settings.node_ids:
                self._nmt(cia402.NMT_START, node)
            self._state = LifecycleState.INACTIVE
            reading = self.read()
            if not np.all(np.isfinite(reading.position_m)):
                raise HardwareError("no position from the drives after start: "
                                    + "; ".join(reading.faults))
            self._start_idle_heartbeat()
        except BaseException:
            try:
                for node in self.settings.node_ids:
                    self._nmt(cia402.NMT_PRE_OPERATIONAL, node)
            except (can.CanError, OSError):
                pass
            self._close_bus()
            self._state = LifecycleState.UNCONFIGURED
            raise
        self._target_counts = self._position_counts.copy()

    def _plans(self) -> list[DrivePlan]:
        """Each drive's plan from its EDS (:mod:`~haptic.master.hardware.canopen_setup`), the
        fallbacks taken (:attr:`fallbacks`) and the cyclic frames' layout. The SYNC
        counter (0x1019) is on when configured and every drive's EDS has the object writable
        (one SYNC serves all: a drive without it expects SYNCs without data)."""
        settings = self.settings
        window_counts = int(round(settings.following_error_window_m
                                  / settings.metres_per_count))
        dictionaries = []
        for axis, (node, eds) in enumerate(zip(settings.node_ids, settings.eds_files,
                                               strict=True)):
            what = f"{AXES[axis]} drive's EDS ({eds or 'packaged'})"
            try:
                dictionaries.append((load_drive_dictionary(eds, node), what))
            except (OSError, ValueError, KeyError) as error:
                raise HardwareError(f"cannot read the {what}: {error}") from None
        overflow = self._counter_for_bus(settings.sync_counter_overflow, dictionaries)
        plan_settings = PlanSettings(
            self.sample_period_s, settings.master_node_id, settings.heartbeat_period_s,
            settings.heartbeat_timeout_s, settings.rpdo_timeout_s,
            min(window_counts, 0xFFFFFFFF), overflow, settings.allow_no_drive_watchdog,
            self._fd)
        plans = []
        for node, (dictionary, what) in zip(settings.node_ids, dictionaries, strict=True):
            plans.append(plan_drive(dictionary, node, plan_settings, what))
        self.plans = plans
        self.fallbacks = [f"{AXES[axis]} drive (node {settings.node_ids[axis]}): {line}"
                          for axis, plan in enumerate(plans) for line in plan.fallbacks]
        if self.sync_counter_note.startswith("SYNC counter off: the"):
            self.fallbacks.append(self.sync_counter_note)
        self._use_plans(plans)
        return plans

    def _counter_for_bus(self, overflow: int, dictionaries: list[tuple[Any, str]]) -> int:
        """The SYNC counter's overflow value in use (0 off) and its note."""
        lacking = [what for dictionary, what in dictionaries
                   if 0x1019 not in dictionary or not dictionary[0x1019].writable]
        if overflow and lacking:
            self.sync_counter_note = (f"SYNC counter off: the {' and the '.join(lacking)} "
                                      f"{'have' if len(lacking) > 1 else 'has'} no 0x1019")
            overflow = 0
        else:
            self.sync_counter_note = (f"SYNC counter 1..{overflow}" if overflow
                                      else "SYNC counter off ([master.can] "
                                      "sync_counter_overflow = 0)")
        self.sync_counter_overflow = overflow
        return overflow

    def _use_plans(self, plans: list[DrivePlan]) -> None:
        """The cyclic frames' ids and layouts, the supervision and the node guarding the
        plans ask for."""
        nodes = self.settings.node_ids
        self._guard_requests = []
        for axis, (node, plan) in enumerate(zip(nodes, plans, strict=True)):
            old_tpdo = next(i for i, v in self._dispatch.items() if v == (_TPDO, axis))
            del self._dispatch[old_tpdo]
            self._dispatch[plan.tpdo.cob_id] = (_TPDO, axis)
            self._own_ids.discard(self._rpdo_ids[axis])
            self._rpdo_ids[axis] = plan.rpdo.cob_id
            self._own_ids.add(plan.rpdo.cob_id)
            self._own_ids.update(plan.ignored_cob_ids)
            self._tpdo_names[axis] = plan.tpdo.name
            self._tpdo_codecs[axis], self._tpdo_reversed[axis] = plan.tpdo.codec(
                plan.dictionary, TPDO1_OBJECTS)
            self._rpdo_codecs[axis], self._rpdo_reversed[axis] = plan.rpdo.codec(
                plan.dictionary, RPDO1_OBJECTS)
            self._heartbeat_supervised[axis] = plan.heartbeat_supervised
            self._guarded[axis] = plan.guarded
            if plan.guarded:
                self._guard_requests.append(can.Message(
                    arbitration_id=HEARTBEAT_BASE + node, is_remote_frame=True, dlc=1,
                    is_extended_id=False))

    def summary(self) -> dict[str, Any]:
        """What the run's summary gets from the driver: ``fallbacks`` (one line each, naming
        the drive), ``can_drives`` (per drive its PDOs, watchdogs and fallbacks) and
        ``can_sync_counter`` (:attr:`sync_counter_note`); empty before configure."""
        if not self.plans:
            return {}
        return {"fallbacks": list(self.fallbacks),
                "can_drives": {AXES[axis]: describe(plan)
                               for axis, plan in enumerate(self.plans)},
                "can_sync_counter": self.sync_counter_note}

    def _next_sync(self) -> can.Message:
        """This cycle's SYNC: without data, or with the counter 1..overflow (CiA 301)."""
        overflow = self.sync_counter_overflow
        if not overflow:
            return self._sync
        self._sync_counter = self._sync_counter % overflow + 1
        return self._counted_syncs[self._sync_counter - 1]

    def _expect_heartbeats(self, now: float) -> None:
        """Supervise the heartbeats from ``now`` (time.monotonic(), s): each drive's counts as
        heard then, none lost, and the master's own is due."""
        self._heartbeat_seen_s = [now, now]
        self._heartbeat_lost = [False, False]
        self._heartbeat_due_s = now

    def _clear_trip(self) -> None:
        """No stop in force and no warning bit seen: where an activation starts."""
        self._tripped = False
        self._master_stop = None
        self._warnings = [0, 0]

    def _watch_stop(self) -> None:
        """Watch each drive take the master's stop afresh (:meth:`_check_quick_stop`)."""
        self._stop_cycles = 0
        self._stop_taken = [False, False]
        self._stop_reported = [False, False]

    def _configure_drive(self, axis: int, node: int, plan: DrivePlan) -> None:
        name = f"{AXES[axis]} drive (node {node})"
        dictionary = plan.dictionary
        device_type = self._sdo_read(node, variable(dictionary, 0x1000, 0, name), name)
        if device_type & 0xFFFF != 402:
            raise HardwareError(f"{name} is not a CiA 402 drive (0x1000 device type "
                                f"0x{device_type:08X})")
        if plan.check_modes:
            modes = self._sdo_read(node, variable(dictionary, 0x6502, 0, name), name)
            if not modes & CSP_SUPPORTED:
                raise HardwareError(f"{name} has no cyclic synchronous position: 0x6502 "
                                    f"reads 0x{modes:08X} (bit 7, mode 8, clear)")
        identity = {"device_type": device_type}
        for subindex, key in ((1, "vendor_id"), (2, "product_code"), (3, "revision"),
                              (4, "serial_number")):
            if subindex in plan.identity:
                identity[key] = self._sdo_read(
                    node, variable(dictionary, 0x1018, subindex, name), name)
        info = dictionary.device_information
        for key, expected in (("vendor_id", info.vendor_number),
                              ("product_code", info.product_number)):
            if expected and key in identity and identity[key] != expected:
                raise HardwareError(f"{name} reports {key} 0x{identity[key]:08X}, its EDS "
                                    f"describes 0x{expected:08X}: another device or EDS")
        self.identities.append(identity)
        for step in plan.steps:
            if step.write:
                self._sdo_write(node, step.variable, step.value, name)
            back = self._sdo_read(node, step.variable, name)
            if back != step.value:
                raise HardwareError(f"{name}: {step.label} reads back {back} after writing "
                                    f"{step.value}" if step.write else
                                    f"{name}: {step.label} reads {back}, not the EDS's fixed "
                                    f"{step.value}")
        mode = self._sdo_read(node, variable(dictionary, 0x6061, 0, name), name)
        if mode != cia402.MODE_CYCLIC_SYNC_POSITION:
            raise HardwareError(f"{name} reports mode {mode}, not cyclic synchronous "
                                "position (8)")

    def activate(self) -> None:
        """Enable both drives safely: each drive's target (0x607A, by SDO, read back, and in
        the RPDO) is set to its actual position first, then the CiA 402 sequence runs with
        every transition checked; a drive in Fault is reset once. An EMCY, a new fault or
        an unexpected transition stops the sequence (both drives shut down) with the EMCY
        codes in the error."""
        if self._state is not LifecycleState.INACTIVE:
            raise HardwareError(f"activate needs the inactive state (now {self._state.value})")
        self._stop_idle_heartbeat()  # from now on every read() sends it when due
        try:
            self._activate()
        except BaseException:
            if self._state is LifecycleState.INACTIVE:
                self._start_idle_heartbeat()
            raise

    def _activate(self) -> None:
        reading = self.read()
        if not np.all(np.isfinite(reading.position_m)):
            raise HardwareError("cannot activate without positions: " + "; ".join(reading.faults))
        self._clear_trip()
        for axis, node in enumerate(self.settings.node_ids):
            name = f"{AXES[axis]} drive (node {node})"
            counts = int(self._position_counts[axis])
            self._sdo_write(node, cia402.TARGET_POSITION, counts, name)
            back = self._sdo_read(node, cia402.TARGET_POSITION, name)
            if back != counts:
                raise HardwareError(f"{name}: 0x607A reads back {back} after writing {counts}")
        self._target_counts = self._position_counts.copy()
        self._enable_sequence()
        self._state = LifecycleState.ACTIVE

    def _enable_sequence(self) -> None:
        """The CiA 402 enable sequence, one step per SYNC, the targets kept at the actual
        positions until both drives are enabled; every transition checked (see
        :meth:`activate`); :class:`HardwareError` when it stops."""
        emcy_start = len(self.emcy_log)
        resets = [0, 0]
        for _ in range(self.settings.enable_timeout_cycles):
            before = list(self._drive_states)
            commands = [self._enable_step(axis, resets) for axis in range(2)]
            if all(command is None for command in commands):
                break
            for axis, command in enumerate(commands):
                self._send_rpdo(axis, self._last_controlword[axis] if command is None
                                else command)
            self.read()
            new_emcy = self.emcy_log[emcy_start:]
            for axis in range(2):
                after = self._drive_states[axis]
                command = commands[axis]
                if command is None or after is before[axis]:
                    continue
                expected = _EXPECTED_AFTER.get((before[axis], command))
                if after is not expected and not (
                        command == cia402.CW_DISABLE_VOLTAGE and before[axis] is
                        DriveState.FAULT):
                    self._abort_activation(
                        f"{AXES[axis]} drive went from {before[axis].value} to {after.value} "
                        f"on controlword 0x{command:04X}", new_emcy)
            if new_emcy:
                self._abort_activation("EMCY during the enable sequence", new_emcy)
            if any(state is DriveState.FAULT and resets[axis] > 1
                   for axis, state in enumerate(self._drive_states)):
                self._abort_activation("a drive faulted again after its fault reset", new_emcy)
            if any(state is not DriveState.OPERATION_ENABLED for state in self._drive_states):
                self._target_counts = self._position_counts.copy()
        else:
            self._abort_activation("drives did not reach operation enabled",
                                   self.emcy_log[emcy_start:])

    def _abort_activation(self, reason: str, emcys: list[tuple[str, int]]) -> None:
        self._send_both(cia402.CW_DISABLE_VOLTAGE)
        states = ", ".join(f"{a}: {s.value}" for a, s in zip(AXES, self._drive_states,
                                                             strict=True))
        codes = ", ".join(f"{axis} 0x{code:04X}" for axis, code in emcys) or "none"
        raise HardwareError(f"activation stopped: {reason} ({states}; EMCY {codes})")

    def _enable_step(self, axis: int, resets: list[int]) -> int | None:
        state = self._drive_states[axis]
        command = cia402.enable_command_for(state)
        if command == cia402.CW_FAULT_RESET:
            if self._last_controlword[axis] & 0x80:
                return cia402.CW_DISABLE_VOLTAGE  # fault reset acts on a rising edge of bit 7
            resets[axis] += 1
        return command

    def deactivate(self) -> None:
        """Disable operation then shut the drives down (the lead screws hold the handle)."""
        if self._state is not LifecycleState.ACTIVE:
            return
        self._state = LifecycleState.INACTIVE
        self._master_stop = None
        # from quick stop, disable operation is no transition: disable voltage instead
        self._send_both(cia402.CW_DISABLE_VOLTAGE if self._tripped
                        else cia402.CW_DISABLE_OPERATION)
        self.read()
        self._send_both(cia402.CW_SHUTDOWN)
        self.read()
        self._start_idle_heartbeat()

    def stop_motion(self, reason: str) -> None:
        """The master's own trip: quick stop on both drives (CiA 402, controlword 0x0002; each
        stops by its quick stop option code 0x605A, in Quick stop active or Switch on
        disabled), the targets held at the actual positions. The next readings report each
        drive's transition as an event, or a fault when a drive is not stopped within
        ``enable_timeout_cycles`` SYNCs. Not a fault itself; :meth:`resume_motion` undoes it."""
        if self._state is not LifecycleState.ACTIVE or self._tripped:
            return
        self._tripped = True
        self._master_stop = reason
        self._watch_stop()
        self._target_counts = self._position_counts.copy()
        self._send_both(cia402.CW_QUICK_STOP)
        self._pending_events.append(f"quick stop on both drives: {reason}")

    def resume_motion(self) -> None:
        """Re-enable the drives after :meth:`stop_motion`: the enable sequence from where each
        drive stopped, every transition checked, the targets at the actual positions (the
        loop's next command starts from there). A failure is a fault in the next reading
        and the drives stay stopped."""
        if self._state is not LifecycleState.ACTIVE or self._master_stop is None:
            return
        self._master_stop = None
        self._target_counts = self._position_counts.copy()
        try:
            self._enable_sequence()
        except HardwareError as error:
            self._pending_faults.append(f"re-enabling after the quick stop failed: {error}")
            return  # still tripped: write() keeps quick stop
        self._tripped = False
        self._target_counts = self._position_counts.copy()
        self._pending_events.append("drives re-enabled at their actual positions after the "
                                    "quick stop")

    def _check_quick_stop(self, axis: int, events: list[str], faults: list[str],
                          drive_fault: list[bool]) -> None:
        """After the master's quick stop: the drive in Quick stop active or Switch on
        disabled (an event, once), or a fault once it is late."""
        state = self._drive_states[axis]
        if state in (DriveState.QUICK_STOP_ACTIVE, DriveState.SWITCH_ON_DISABLED):
            if not self._stop_taken[axis]:
                self._stop_taken[axis] = True
                events.append(f"{AXES[axis]} drive took the quick stop ({state.value})")
        elif (self._stop_cycles > self.settings.enable_timeout_cycles
              and not self._stop_taken[axis] and not self._stop_reported[axis]):
            self._stop_reported[axis] = True
            drive_fault[axis] = True
            faults.append(f"{AXES[axis]} drive did not take the quick stop ({state.value} "
                          f"after {self._stop_cycles} SYNCs)")

    def quick_stop(self, reason: str) -> None:
        """Command quick stop on both drives (they stop where they are) and hold it until the
        next :meth:`activate`; the next reading reports ``reason``."""
        if self._state is not LifecycleState.ACTIVE or self._tripped:
            return
        self._tripped = True
        self._target_counts = self._position_counts.copy()
        self._send_both(cia402.CW_QUICK_STOP)
        self._pending_faults.append(f"quick stop on both drives: {reason}")

    def cleanup(self) -> None:
        """Deactivate if needed, stop the nodes' PDOs (NMT pre-operational), close the bus."""
        if self._bus is None:
            self._state = LifecycleState.UNCONFIGURED
            return
        try:
            if self._state is LifecycleState.ACTIVE:
                self.deactivate()
            for node in self.settings.node_ids:
                self._nmt(cia402.NMT_PRE_OPERATIONAL, node)
        except (can.CanError, HardwareError):
            pass
        finally:
            self._close_bus()
            self._state = LifecycleState.UNCONFIGURED

    def _start_idle_heartbeat(self) -> None:
        if self._bus is None or self._idle_heartbeat is not None:
            return
        message = can.Message(arbitration_id=HEARTBEAT_BASE + self.settings.master_node_id,
                              data=self._master_heartbeat, is_extended_id=False)

        def stop_on_error(error: Exception) -> bool:
            # the bus went away (its peer ended, or it is closing): stop, and let the next
            # read() report the bus; never an exception in a background thread
            self.idle_heartbeat_errors.append(f"{type(error).__name__}: {error}")
            return False

        self._idle_heartbeat = ThreadBasedCyclicSendTask(
            self._bus, threading.Lock(), message, self._heartbeat_period_s,
            on_error=stop_on_error)
        # the guarded drives' requests, each a task of its own (a task with several
        # messages sends one of them per period)
        self._idle_guards = [ThreadBasedCyclicSendTask(
            self._bus, threading.Lock(), request, self._heartbeat_period_s,
            on_error=stop_on_error) for request in self._guard_requests]

    def _stop_idle_heartbeat(self) -> None:
        tasks = [self._idle_heartbeat, *self._idle_guards]
        self._idle_heartbeat, self._idle_guards = None, []
        for task in tasks:
            if task is None:
                continue
            task.stop()
            # stop() only flags the thread: wait for a send in progress to finish, so the
            # bus is never shut down under it (python-can would log a traceback)
            thread = getattr(task, "thread", None)
            if thread is not None and thread is not threading.current_thread():
                thread.join(timeout=self._heartbeat_period_s + 0.5)

    def _close_bus(self) -> None:
        self._stop_idle_heartbeat()
        self._sync_pending = False
        self._for_sync = []
        if self._bus is not None:
            self._bus.shutdown()
            self._bus = None

    # --- cyclic I/O ------------------------------------------------------------------

    def sync(self) -> None:
        """Start the next cycle ahead of its :meth:`read`: drop the frames left from an
        earlier SYNC (acting on an EMCY or a heartbeat among them), send the master's
        heartbeat when due and the SYNC. The drives apply the last :meth:`write`'s targets
        and sample at the SYNC and answer while the loop waits for its tick (the runner's
        ``lead``), so :meth:`read` finds the frames there instead of waiting for them; the
        sample-to-command delay stays one SYNC. Nothing when a SYNC is already pending."""
        bus = self._bus
        if bus is None or self._state is LifecycleState.UNCONFIGURED:
            raise HardwareError("sync needs a configured driver")
        if self._sync_pending:
            return
        if self._master_stop is not None:
            self._stop_cycles += 1
        self._discard_late_frames(self._pending_faults, self._sync_drive_fault)
        now = time.monotonic()
        with self.burst():  # with the frames held for it (:meth:`until_sync`): one burst
            self._heartbeat_if_due(now)
            self._put(self._next_sync())
        self._cycle += 1
        self._sync_sent_s = now
        self._sync_pending = True

    def _heartbeat_if_due(self, now: float) -> None:
        """Send the master's heartbeat, and the node guarding requests of the drives guarded
        instead of consuming it, when it is due (``now``: time.monotonic(), s)."""
        if now >= self._heartbeat_due_s:
            self._send(HEARTBEAT_BASE + self.settings.master_node_id, self._master_heartbeat)
            if self._guard_requests:
                self._put_all(self._guard_requests)
            self._heartbeat_due_s = max(self._heartbeat_due_s + self._heartbeat_period_s, now)

    def read(self) -> HandleReading:
        """Collect the PDOs of the pending SYNC (:meth:`sync`; sent now when none is
        pending), return the sample (NaN where missing) with the drives' faults and
        statusword events.

        Supervision: EMCYs, a drive in Fault or out of operation enabled, a drive's heartbeat
        older than ``heartbeat_timeout_s`` or reporting another NMT state are faults, and
        while active they command quick stop on both drives; statusword warning bits
        (7 warning, 11 internal limit, 13 following error, 12 cleared: target ignored, 9
        cleared: not remote) are events, once per change."""
        bus = self._bus
        if bus is None or self._state is LifecycleState.UNCONFIGURED:
            raise HardwareError("read needs a configured driver")
        if not self._sync_pending:
            self.sync()
        self._sync_pending = False
        now = self._sync_sent_s
        faults = self._pending_faults
        self._pending_faults = []
        events = self._pending_events
        self._pending_events = []
        drive_fault = self._sync_drive_fault
        self._sync_drive_fault = [False, False]
        dispatch = self._dispatch
        metres_per_count = self.settings.metres_per_count
        position_m = [math.nan, math.nan]
        force_N = (math.nan, math.nan)
        have_drive = [False, False]
        have_sensor = False
        deadline = now + self.pdo_timeout_s
        while not (have_drive[0] and have_drive[1] and have_sensor):
            # past the deadline, only what has arrived already (a late read after sync());
            # a long wait (pdo_timeout_s above the heartbeat period: the simulated rig's
            # drives share a busy machine) keeps the heartbeat going, or the drives' consumer
            # would take a master waiting for them for a lost one
            clock = time.monotonic()
            message = bus.recv(timeout=max(min(deadline, self._heartbeat_due_s) - clock, 0.0))
            if message is None:
                clock = time.monotonic()
                if clock >= deadline:
                    break
                self._heartbeat_if_due(clock)
                continue
            kind, axis = dispatch.get(message.arbitration_id, _OTHER)
            if kind == _TPDO:
                data = message.data
                codec = self._tpdo_codecs[axis]
                if len(data) != codec.size:
                    faults.append(f"{AXES[axis]} drive {self._tpdo_names[axis]} malformed: "
                                  f"PDO payload of {len(data)} bytes, expected {codec.size}")
                    continue
                statusword, counts = codec.unpack(data)
                if self._tpdo_reversed[axis]:
                    statusword, counts = counts, statusword
                have_drive[axis] = True
                self._drive_states[axis] = cia402.decode_statusword(statusword)
                self._position_counts[axis] = counts
                position_m[axis] = counts * metres_per_count
                warnings = (statusword & _WARNING_BITS) ^ _WARNING_IDLE
                if self._drive_states[axis] is not DriveState.OPERATION_ENABLED:
                    warnings &= ~_FOLLOWS_TARGET  # bit 12 speaks only when enabled
                if warnings != self._warnings[axis]:
                    self._warning_events(axis, warnings, events)
            elif kind == _SENSOR:
                have_sensor = True
                force_N = self._sensor_force(bytes(message.data), faults)
            elif kind in (_EMCY, _HEARTBEAT) and not message.is_remote_frame:
                self._supervision_frame(kind, axis, bytes(message.data), faults, drive_fault)
        for axis, node in enumerate(self.settings.node_ids):
            if not have_drive[axis]:
                faults.append(f"missing {self._tpdo_names[axis]} from the {AXES[axis]} drive "
                              f"(node {node})")
            elif self._drive_states[axis] in (DriveState.FAULT, DriveState.FAULT_REACTION_ACTIVE):
                faults.append(f"{AXES[axis]} drive in {self._drive_states[axis].value}")
                drive_fault[axis] = True
            elif self._state is LifecycleState.ACTIVE and not self._tripped and (
                self._drive_states[axis] is not DriveState.OPERATION_ENABLED
            ):
                faults.append(f"{AXES[axis]} drive left operation enabled "
                              f"({self._drive_states[axis].value})")
                drive_fault[axis] = True
            elif self._master_stop is not None and self._state is LifecycleState.ACTIVE:
                self._check_quick_stop(axis, events, faults, drive_fault)
            if not self._heartbeat_supervised[axis]:
                continue  # it produces none: its TPDO at each SYNC is what shows it alive
            if now - self._heartbeat_seen_s[axis] > self._heartbeat_timeout_s and (
                    not self._heartbeat_lost[axis]):
                self._heartbeat_lost[axis] = True
                drive_fault[axis] = True
                faults.append(f"no heartbeat from the {AXES[axis]} drive (node {node}) for "
                              f"{now - self._heartbeat_seen_s[axis]:.3f} s (timeout "
                              f"{self._heartbeat_timeout_s:g} s)")
        if not have_sensor:
            faults.append("missing force sensor frame")
        if (drive_fault[0] or drive_fault[1]) and self._state is LifecycleState.ACTIVE:
            self.quick_stop("a drive fault")
            faults.extend(self._pending_faults)
            self._pending_faults = []
        reading = HandleReading(np.array(force_N), np.array(position_m), self._cycle,
                                tuple(faults), tuple(events))
        self.last_reading = reading
        return reading

    def _warning_events(self, axis: int, warnings: int, events: list[str]) -> None:
        """Events for the statusword warning bits that changed (``warnings``: the bits that
        are not in their healthy state)."""
        changed = warnings ^ self._warnings[axis]
        self._warnings[axis] = warnings
        for bit, text in _WARNING_TEXT.items():
            if changed & bit:
                state = "on" if warnings & bit else "off"
                events.append(f"{AXES[axis]} drive statusword: {text} {state}")

    def _supervision_frame(self, kind: int, axis: int, data: bytes, faults: list[str],
                           drive_fault: list[bool]) -> None:
        """An EMCY or a heartbeat of ``axis``'s drive."""
        if kind == _EMCY:
            try:
                code, register = cia402.decode_emcy(data)
            except ValueError as error:
                faults.append(f"{AXES[axis]} drive EMCY malformed: {error}")
                return
            if code != 0:
                self.emcy_log.append((AXES[axis], code))
                meaning = _EMCY_TEXT.get(code)
                faults.append(f"{AXES[axis]} drive EMCY error code 0x{code:04X} "
                              f"(register 0x{register:02X}"
                              + (f"; {meaning})" if meaning else ")"))
                drive_fault[axis] = True
        elif kind == _HEARTBEAT:
            self._heartbeat_seen_s[axis] = time.monotonic()
            self._heartbeat_lost[axis] = False
            state = data[0] if data else -1
            if self._guarded[axis] and state > 0:
                state &= 0x7F  # bit 7 of a node guarding answer: its toggle bit
            if self._state is not LifecycleState.UNCONFIGURED and state != 0x05:
                faults.append(f"{AXES[axis]} drive heartbeat reports NMT state "
                              f"{_NMT_STATE_NAMES.get(state, hex(state))}, not operational")
                drive_fault[axis] = True

    def _discard_late_frames(self, faults: list[str], drive_fault: list[bool]) -> None:
        """Drop frames left from an earlier SYNC (they arrived after its timeout, which that
        cycle reported as missing); an EMCY or a heartbeat among them is still acted on, and
        is not a late frame."""
        assert self._bus is not None
        while (message := self._bus.recv(timeout=0.0)) is not None:
            if message.is_remote_frame or message.arbitration_id in (
                    self._own_extended_ids if message.is_extended_id else self._own_ids):
                continue  # our own frame, back from an interface that echoes
            kind, axis = self._dispatch.get(message.arbitration_id, _OTHER)
            if kind in (_EMCY, _HEARTBEAT):
                self._supervision_frame(kind, axis, bytes(message.data), faults, drive_fault)
                continue
            self.late_frames += 1

    def _sensor_force(self, data: bytes, faults: list[str]) -> tuple[float, float]:
        """The sensor frame's force (N, x and y; both NaN where it is not a valid sample, with
        the fault: a status other than ok, or counts that scale beyond a float)."""
        try:
            sample = self.codec.decode(data)
        except Exception as error:  # cantools raises several types for a bad frame
            faults.append(f"force sensor frame malformed: {error}")
            return math.nan, math.nan
        if self._sensor_counter is not None and sample.counter != (self._sensor_counter + 1) % 256:
            faults.append(f"force sensor counter jumped from {self._sensor_counter} to "
                          f"{sample.counter} (a stale or lost sample)")
        self._sensor_counter = sample.counter
        force = self.codec.newtons(sample)
        if math.isfinite(force[0]) and math.isfinite(force[1]):
            return force
        faults.append(f"force sensor status {sample.status} (not ok)" if sample.status
                      != STATUS_OK else f"force sensor counts ({sample.raw_x_count}, "
                      f"{sample.raw_y_count}) are not finite in N: see [master.can] "
                      "force_scale_N_per_count and force_offset_count")
        return math.nan, math.nan

    def write(self, position_command_m: np.ndarray) -> None:
        """Send the targets (m) to both drives; a non-finite command is never sent (the
        previous target is repeated and a fault is reported by the next read). After a
        quick stop the drives get quick stop and the held targets until re-activated."""
        if self._state is not LifecycleState.ACTIVE:
            return
        if self._tripped:
            self._send_both(cia402.CW_QUICK_STOP)
            return
        counts = self._target_counts.tolist()  # per axis, as Python ints
        refused = False
        for axis in range(2):
            value = float(position_command_m[axis])
            if math.isfinite(value):
                counts[axis] = self.settings.count_from_metres(value)
            else:
                refused = True
        if refused:
            self._pending_faults.append("non-finite position command refused")
        if abs(counts[0]) > INT32_MAX or abs(counts[1]) > INT32_MAX:
            self._pending_faults.append("position command beyond the drives' int32 range")
            counts = self._target_counts.tolist()
        else:
            self._target_counts = np.array(counts, np.int64)
        self._send_rpdos(cia402.CW_ENABLE_OPERATION, counts)

    # --- frames ----------------------------------------------------------------------

    def burst(self) -> _Burst:
        """Hold the frames sent inside (RPDOs, :meth:`send_frame`'s) and send them back to
        back at the end, as one burst where the bus can (``unix_datagram``: one datagram, one
        wake-up of the devices' process instead of one per frame; any other bus: one frame
        after the other, as without it). Nested bursts go out with the outermost; frames
        held for the next SYNC (:meth:`until_sync`) go out first. (A context manager of its
        own class: a generator's costs about 1 us more, and the loop enters these each
        tick.)"""
        return _Burst(self)

    def until_sync(self) -> _UntilSync:
        """Hold the frames sent inside until the next SYNC and send them in its burst, just
        before it (the simulated rig's ``unix_datagram`` bus: its devices' process is woken
        once a cycle instead of twice, and the loop's tick no longer pays that wake-up). The
        drives latch synchronous RPDOs and apply them at the SYNC, so they act exactly as if
        the frames had come right away. Anything else sent meanwhile sends them first, in
        order; closing the bus drops them."""
        return _UntilSync(self)

    def _end_burst(self) -> None:
        """The end of the outermost :meth:`burst`: its frames go out, or wait for the SYNC."""
        held, self._held = self._held, None
        if self._holding_for_sync:
            self._for_sync.extend(held)
        elif self._bus is not None:
            self._send_now(held)

    def send_frame(self, frame_id: int, data: bytes, extended: bool = False) -> None:
        """Send one frame as is on the driver's bus (a simulated rig's extra frames, e.g. its
        operator display frame); ``extended``: a 29-bit identifier. :class:`HardwareError`
        when the bus is not open."""
        if self._bus is None:
            raise HardwareError("send_frame needs a configured driver")
        (self._own_extended_ids if extended else self._own_ids).add(frame_id)
        self._put(can.Message(arbitration_id=frame_id, data=data, is_extended_id=extended))

    def _send(self, frame_id: int, data: bytes, fd: bool = False) -> None:
        self._put(can.Message(arbitration_id=frame_id, data=data, is_extended_id=False,
                              is_fd=fd, bitrate_switch=fd))

    def _put(self, message: can.Message) -> None:
        """Send ``message`` now (after the frames held for the SYNC), or hold it for the
        burst being sent."""
        self._put_all([message])

    def _put_all(self, frames: list[can.Message]) -> None:
        """:meth:`_put` of ``frames``, in order, as one burst when sent now."""
        if self._held is not None:
            self._held.extend(frames)
            return
        self._send_now(frames)

    def _send_now(self, frames: list[can.Message]) -> None:
        """Send ``frames`` as one burst, after the frames held for the SYNC (their place)."""
        assert self._bus is not None
        frames, self._for_sync = self._for_sync + frames, []
        if frames:
            send_burst(self._bus, frames)

    def _rpdo_frame(self, axis: int, controlword: int, count: int) -> can.Message:
        """``axis``'s drive RPDO: ``controlword`` and the target position ``count``."""
        fd = self._fd
        data = (self._rpdo_codecs[axis].pack(count, controlword) if self._rpdo_reversed[axis]
                else self._rpdo_codecs[axis].pack(controlword, count))
        return can.Message(arbitration_id=self._rpdo_ids[axis], data=data,
                           is_extended_id=False, is_fd=fd, bitrate_switch=fd)

    def _send_rpdos(self, controlword: int, counts: list[int]) -> None:
        """Both drives' RPDO (``controlword`` and the target ``counts``, per axis) as one
        burst, as :meth:`burst` would send them."""
        self._put_all([self._rpdo_frame(0, controlword, counts[0]),
                       self._rpdo_frame(1, controlword, counts[1])])
        self._last_controlword[0] = self._last_controlword[1] = controlword

    def _send_rpdo(self, axis: int, controlword: int) -> None:
        """One drive's RPDO (the enable sequence's per-axis steps)."""
        self._put(self._rpdo_frame(axis, controlword, int(self._target_counts[axis])))
        self._last_controlword[axis] = controlword

    def _send_both(self, controlword: int) -> None:
        self._send_rpdos(controlword, self._target_counts.tolist())

    def _nmt(self, command: int, node: int) -> None:
        self._send(cia402.NMT_COB_ID, bytes([command, node]))

    def _sdo_exchange(self, node: int, request: bytes, variable: Any,
                      label: str) -> cia402.SdoFrame:
        """Send an SDO request and wait for the reply of the same object (a reply for
        another index/subindex is stale and skipped); EMCYs meanwhile are logged and
        reported by the next read, heartbeats are noted. An abort raises with the object
        and its code."""
        assert self._bus is not None
        self._send(cia402.SDO_RX_BASE + node, request)
        now = time.monotonic()
        deadline = now + self.pdo_timeout_s * self.settings.enable_timeout_cycles
        # a request or its reply lost on the way is asked again (an SDO read or an expedited
        # write is idempotent), every SDO_RESEND_S until the deadline
        resend_at = now + SDO_RESEND_S
        obj = f"0x{variable.index:04X}:{variable.subindex:02X} ({variable.name})"
        while (remaining := deadline - time.monotonic()) > 0.0:
            message = self._bus.recv(timeout=min(remaining, max(resend_at - time.monotonic(),
                                                                0.0)))
            if message is None:
                now = time.monotonic()
                if now >= deadline:
                    break
                if now >= resend_at:
                    self.sdo_resends += 1
                    self._send(cia402.SDO_RX_BASE + node, request)
                    resend_at = now + SDO_RESEND_S
                continue
            if message.arbitration_id == cia402.SDO_TX_BASE + node:
                try:
                    reply = cia402.decode_sdo(bytes(message.data))
                except ValueError:
                    continue
                if (reply.index, reply.subindex) != (variable.index, variable.subindex):
                    continue  # a stale reply to an earlier request
                if reply.command == 0x80:
                    code = int.from_bytes(reply.data, "little")
                    raise HardwareError(f"{label}: SDO abort 0x{code:08X} "
                                        f"({_abort_text(code)}) on {obj}")
                return reply
            kind, axis = self._dispatch.get(message.arbitration_id, _OTHER)
            if kind in (_EMCY, _HEARTBEAT) and not message.is_remote_frame:
                self._supervision_frame(kind, axis, bytes(message.data),
                                        self._pending_faults, [False, False])
        raise HardwareError(f"{label}: no SDO reply from node {node} for {obj}")

    def _sdo_write(self, node: int, variable: Any, value: int, label: str) -> None:
        reply = self._sdo_exchange(node, cia402.sdo_download_request(variable, value),
                                   variable, f"{label} write")
        if reply.command != 0x60:
            raise HardwareError(f"{label}: unexpected SDO reply 0x{reply.command:02X} to the "
                                f"write of 0x{variable.index:04X}:{variable.subindex:02X}")

    def _sdo_read(self, node: int, variable: Any, label: str) -> int:
        reply = self._sdo_exchange(node, cia402.sdo_upload_request(variable), variable,
                                   f"{label} read")
        if reply.command & 0xE0 != 0x40 or not reply.command & 0x02:
            raise HardwareError(f"{label}: 0x{variable.index:04X}:{variable.subindex:02X} "
                                f"answered with SDO command 0x{reply.command:02X}, not an "
                                "expedited upload")
        size = len(variable) // 8
        return int(variable.decode_raw(reply.data[:size]))


#: What read() does with a frame, by id: kinds 1-4 (0 for any other frame) and the axis.
_TPDO, _SENSOR, _EMCY, _HEARTBEAT = range(1, 5)
_OTHER = (0, 0)
HEARTBEAT_BASE = 0x700
_TPDO1 = struct.Struct("<Hi")  # statusword, position actual value (counts)
_RPDO1 = struct.Struct("<Hi")  # controlword, target position (counts)

#: An SDO request without a reply is sent again after this long, s (until the deadline).
SDO_RESEND_S = 0.25

_FOLLOWS_TARGET = cia402.STATUS_FOLLOWING_TARGET
#: Statusword bits watched as events, with their texts, and those of them that are set when
#: healthy (9 remote and 12 "follows the target": flipped before comparing).
_WARNING_TEXT = {0x0080: "warning (bit 7)", cia402.STATUS_REMOTE: "not remote (bit 9 clear)",
                 0x0800: "internal limit active (bit 11)",
                 _FOLLOWS_TARGET: "target ignored (bit 12 clear)",
                 0x2000: "following error (bit 13)"}
_WARNING_BITS = sum(_WARNING_TEXT)  # one bit each
_WARNING_IDLE = cia402.STATUS_REMOTE | _FOLLOWS_TARGET
#: The NMT states a drive's heartbeat may report other than operational (0x05).
_NMT_STATE_NAMES = {0x00: "boot-up", 0x04: "stopped", 0x7F: "pre-operational"}
#: The state each enable-sequence controlword leads to from each state.
_EXPECTED_AFTER = {
    (DriveState.SWITCH_ON_DISABLED, cia402.CW_SHUTDOWN): DriveState.READY_TO_SWITCH_ON,
    (DriveState.NOT_READY_TO_SWITCH_ON, cia402.CW_SHUTDOWN): DriveState.READY_TO_SWITCH_ON,
    (DriveState.READY_TO_SWITCH_ON, cia402.CW_SWITCH_ON): DriveState.SWITCHED_ON,
    (DriveState.SWITCHED_ON, cia402.CW_ENABLE_OPERATION): DriveState.OPERATION_ENABLED,
    (DriveState.FAULT, cia402.CW_FAULT_RESET): DriveState.SWITCH_ON_DISABLED,
    (DriveState.QUICK_STOP_ACTIVE, cia402.CW_DISABLE_VOLTAGE): DriveState.SWITCH_ON_DISABLED,
    (DriveState.FAULT_REACTION_ACTIVE, cia402.CW_SHUTDOWN): DriveState.FAULT,
}
#: What the EMCY codes of CiA 301/402 the loop meets mean.
_EMCY_TEXT = {
    0x8130: "heartbeat or life guard lost", 0x8210: "PDO shorter than mapped",
    0x8220: "PDO longer than mapped",
    0x8240: "unexpected SYNC data length: the drive's 0x1019 does not match the SYNC counter",
    0x8250: "RPDO deadline missed", 0x8611: "following error",
}
_ABORT_TEXT = {
    0x05040001: "command specifier not valid", 0x06010000: "unsupported access",
    0x06010001: "write-only object", 0x06010002: "read-only object",
    0x06020000: "object does not exist", 0x06040041: "object cannot be mapped to the PDO",
    0x06040042: "mapping exceeds the PDO length", 0x06040043: "parameter incompatibility",
    0x06070010: "data type length mismatch", 0x06090011: "sub-index does not exist",
    0x06090030: "value out of range", 0x08000000: "general error",
    0x08000020: "cannot be stored or used now", 0x08000022: "not in the present device state",
}


def _abort_text(code: int) -> str:
    return _ABORT_TEXT.get(code, "see CiA 301")


def can_hardware(config: dict[str, Any]) -> HandleHardware:
    """Backend ``can`` for a validated configuration: the handle's drives and force sensor
    on the configured CAN bus."""
    settings = master_settings(config)
    can_settings = settings.can
    options: dict[str, Any] = {"interface": can_settings.interface,
                               "channel": can_settings.channel, "bitrate": can_settings.bitrate}
    if can_settings.fd:
        options.update(fd=True, data_bitrate=can_settings.data_bitrate)
    driver = CanHandleDriver(can_settings, options, can_settings.pdo_timeout_s,
                             config["model"]["sample_period_s"])
    driver.announce_bus_load = True
    return driver


class _Burst:
    """:meth:`CanHandleDriver.burst`'s context manager."""

    __slots__ = ("_driver", "_outer")

    def __init__(self, driver: CanHandleDriver) -> None:
        self._driver = driver
        self._outer = False

    def __enter__(self) -> None:
        driver = self._driver
        self._outer = driver._held is None
        if self._outer:
            driver._held = []

    def __exit__(self, *_exc: object) -> None:
        if self._outer:
            self._driver._end_burst()


class _UntilSync:
    """:meth:`CanHandleDriver.until_sync`'s context manager."""

    __slots__ = ("_driver", "_burst")

    def __init__(self, driver: CanHandleDriver) -> None:
        self._driver = driver
        self._burst: _Burst | None = None

    def __enter__(self) -> None:
        driver = self._driver
        if driver._holding_for_sync:
            return
        driver._holding_for_sync = True
        self._burst = _Burst(driver)
        self._burst.__enter__()

    def __exit__(self, *exc: object) -> None:
        if self._burst is None:
            return
        try:
            self._burst.__exit__(*exc)
        finally:
            self._driver._holding_for_sync = False
