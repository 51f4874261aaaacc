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

The driver composes the CAN stack's parts, one job each: what it sends and when
(:mod:`~haptic.master.hardware.frame_sender`), the SDO client
(:mod:`~haptic.master.hardware.sdo_client`), the drives' plans and their configuration by SDO
(:mod:`~haptic.master.hardware.drive_commissioning`), the heartbeats
(:mod:`~haptic.master.hardware.heartbeat`), the cyclic frames and the drives' image
(:mod:`~haptic.master.hardware.pdo_cycle`), the CiA 402 enable sequence
(:mod:`~haptic.master.hardware.enable_sequence`), the drives' EMCYs, warnings and quick stop
(:mod:`~haptic.master.hardware.drive_events`) and the sensor's frames
(:mod:`~haptic.master.hardware.force_reading`). Here: the lifecycle, the cycle's
:meth:`~CanHandleDriver.read` and :meth:`~CanHandleDriver.write`, and the supervision that
turns what the parts find into the reading's faults and the drives' quick stop.

Units are converted here and nowhere else: counts <-> m with the lead-screw pitch and the
encoder resolution, raw sensor counts -> N with the configured scale and offset.
"""

from __future__ import annotations

import logging
import math
import sys
import time
from typing import Any

import can
import numpy as np

from haptic.master.hardware import cia402
from haptic.master.hardware.bus_load import BusLoad, bus_load, cycle_frames
from haptic.master.hardware.canopen_setup import DrivePlan, describe
from haptic.master.hardware.cia402 import HEARTBEAT_BASE, DriveState
from haptic.master.hardware.drive_commissioning import (
    configure_drive,
    plan_drives,
    read_identity,
)
from haptic.master.hardware.drive_events import (
    FOLLOWS_TARGET,
    WARNING_BITS,
    WARNING_IDLE,
    QuickStopWatch,
    emcy_fault,
    warning_events,
)
from haptic.master.hardware.enable_sequence import enable_drives
from haptic.master.hardware.force_reading import ForceSensorReader
from haptic.master.hardware.force_sensor import ForceSensorCodec, load_database
from haptic.master.hardware.frame_sender import Burst, FrameSender, UntilSync
from haptic.master.hardware.heartbeat import Heartbeats
from haptic.master.hardware.interface import (
    AXES,
    HandleHardware,
    HandleReading,
    HardwareError,
    LifecycleState,
)
from haptic.master.hardware.pdo_cycle import EMCY, HEARTBEAT, OTHER, SENSOR, TPDO, PdoCycle
from haptic.master.hardware.sdo_client import SdoClient
from haptic.master.settings import CanSettings, master_settings

__all__ = ["AXES", "HEARTBEAT_BASE", "CanHandleDriver", "can_hardware"]

INT32_MAX = 2**31 - 1
_NO_FORCE = (math.nan, math.nan)
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
        How long :meth:`read` waits for the frames of its SYNC, s; an SDO exchange waits
        ``enable_timeout_cycles`` of these (:attr:`sdo`'s ``deadline_s``, set here).
    sample_period_s:
        Ts, s: the drives' interpolation period (0x60C2) and the bus-load budget.
    """

    def __init__(self, settings: CanSettings, bus_options: dict[str, Any],
                 pdo_timeout_s: float, sample_period_s: float) -> None:
        self.settings = settings
        self.bus_options = dict(bus_options)
        self.pdo_timeout_s = float(pdo_timeout_s)
        self.sample_period_s = float(sample_period_s)
        self._fd = bool(settings.fd)
        nodes = settings.node_ids
        codec = ForceSensorCodec(settings.force_scale_N_per_count, settings.force_offset_count,
                                 load_database(settings.dbc_file or None))
        # What this driver sends (NMT, SYNC, its RPDOs, SDO requests, its heartbeat; extra
        # frames by id; PDOs of the drives that stay on unused): an interface that hands a
        # process its own frames back (udp_multicast) does not make them late frames.
        self.frames = FrameSender({cia402.NMT_COB_ID, cia402.SYNC_COB_ID,
                                   HEARTBEAT_BASE + settings.master_node_id}
                                  | {cia402.RPDO1_BASE + n for n in nodes}
                                  | {cia402.SDO_RX_BASE + n for n in nodes})
        self.pdos = PdoCycle(self.frames, nodes, codec.frame_id, self._fd)
        self.heartbeats = Heartbeats(self.frames, settings.master_node_id,
                                     settings.heartbeat_period_s, settings.heartbeat_timeout_s)
        self.sdo = SdoClient(self.frames, self.pdo_timeout_s * settings.enable_timeout_cycles,
                             self._note_supervision_frame)
        self.sensor = ForceSensorReader(codec)
        #: since the master's stop: SYNCs, and per axis, taken by the drive, reported late
        self.stop_watch = QuickStopWatch()
        self._state = LifecycleState.UNCONFIGURED
        self._cycle = 0
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
        #: Every EMCY received (axis, error code), in order.
        self.emcy_log: list[tuple[str, int]] = []
        #: The bus-load budget computed at configure.
        self.bus_load: BusLoad | None = None
        #: The drives' identities read at configure (0x1000, 0x1018:1-4), per axis.
        self.identities: list[dict[str, int]] = []
        #: Print the bus-load budget (one line, stderr) at configure: the real bus's backend.
        self.announce_bus_load = False
        #: per axis, the statusword warning bits not in their healthy state (events on change)
        self._warnings: list[int]
        self._tripped: bool
        #: Why the master stopped the drives (stop_motion), None when it did not.
        self._master_stop: str | None
        self._clear_trip()
        #: What configure found in each drive's EDS: the fallbacks taken (one line each,
        #: naming the drive), per drive its PDOs, watchdogs and fallbacks (summary()).
        self.fallbacks: list[str] = []
        self.plans: list[DrivePlan] = []
        #: Why the SYNC counter is on or off (set at configure).
        self.sync_counter_note = "SYNC counter not configured yet"

    # --- what the parts hold ------------------------------------------------------------

    @property
    def lifecycle_state(self) -> LifecycleState:
        return self._state

    @property
    def drive_states(self) -> tuple[DriveState, DriveState]:
        """CiA 402 state of the x and y drives, from the last statusword read."""
        states = self.pdos.drive_states
        return (states[0], states[1])

    @property
    def codec(self) -> ForceSensorCodec:
        """The force sensor's frame codec (DBC, scale and offset)."""
        return self.sensor.codec

    @property
    def sync_counter_overflow(self) -> int:
        """The SYNC counter's overflow value (0x1019) in use, 0 off (set at configure)."""
        return self.pdos.sync_counter_overflow

    @property
    def sdo_resends(self) -> int:
        """SDO requests sent again because no reply came in time."""
        return self.sdo.resends

    @property
    def idle_heartbeat_errors(self) -> list[str]:
        """Errors that stopped the idle heartbeat task (bus gone), for diagnosis."""
        return self.heartbeats.idle_errors

    # --- lifecycle -------------------------------------------------------------------

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
        read; :mod:`haptic.master.hardware.drive_commissioning`), start the nodes (NMT) and
        take a first sample. On any failure every node is left pre-operational and the bus is
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
        self.pdos.sync_counter = 0
        try:
            self.frames.bus = can.Bus(**self.bus_options)
        except (can.CanError, OSError, ValueError, ImportError) as error:
            options = ", ".join(f"{k}={v}" for k, v in self.bus_options.items())
            raise HardwareError(f"cannot open the CAN bus ({options}): {error}") from None
        try:
            self._start_drives(plans)
        except BaseException:
            try:
                for node in self.settings.node_ids:
                    self._nmt(cia402.NMT_PRE_OPERATIONAL, node)
            except (can.CanError, OSError):
                pass
            self._close_bus()
            self._state = LifecycleState.UNCONFIGURED
            raise
        self.pdos.hold_targets()

    def _start_drives(self, plans: list[DrivePlan]) -> None:
        """:meth:`configure` on the open bus: the drives configured and started, a first
        sample taken, the idle heartbeat running."""
        # the master's heartbeat from now on: a drive consumes it as soon as its 0x1016 is
        # written, and configuring the other drive by SDO can take longer than its timeout
        self.heartbeats.start_idle()
        for node in self.settings.node_ids:
            self._nmt(cia402.NMT_PRE_OPERATIONAL, node)
        self.identities = []
        for axis, node in enumerate(self.settings.node_ids):
            name = f"{AXES[axis]} drive (node {node})"
            self.identities.append(read_identity(self.sdo, node, plans[axis], name))
            configure_drive(self.sdo, node, plans[axis], name)
        self.heartbeats.expect(time.monotonic())
        for node in self.settings.node_ids:
            self._nmt(cia402.NMT_START, node)
        self._state = LifecycleState.INACTIVE
        reading = self.read()
        if not np.all(np.isfinite(reading.position_m)):
            raise HardwareError("no position from the drives after start: "
                                + "; ".join(reading.faults))
        self.heartbeats.start_idle()

    def _plans(self) -> list[DrivePlan]:
        """Each drive's plan from its EDS (:func:`~haptic.master.hardware.drive_commissioning.
        plan_drives`), the fallbacks taken (:attr:`fallbacks`), the SYNC counter, and the
        cyclic frames' layout and heartbeat supervision the plans ask for."""
        planned = plan_drives(self.settings, self.sample_period_s, self._fd)
        self.sync_counter_note = planned.sync_counter_note
        self.pdos.sync_counter_overflow = planned.sync_counter_overflow
        self.plans = planned.plans
        self.fallbacks = planned.fallbacks
        self.heartbeats.guard_requests = []
        for axis, (node, plan) in enumerate(zip(self.settings.node_ids, planned.plans,
                                                strict=True)):
            self.pdos.use_plan(axis, plan)
            self.heartbeats.watch(axis, node, plan.heartbeat_supervised, plan.guarded)
        return planned.plans

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

    def _clear_trip(self) -> None:
        """No stop in force and no warning bit seen: where an activation starts."""
        self._tripped = False
        self._master_stop = None
        self._warnings = [0, 0]

    def activate(self) -> None:
        """Enable both drives safely: each drive's target (0x607A, by SDO, read back, and in
        the RPDO) is set to its actual position first, then the CiA 402 sequence runs with
        every transition checked (:mod:`~haptic.master.hardware.enable_sequence`); a drive
        in Fault is reset once. An EMCY, a new fault or an unexpected transition stops the
        sequence (both drives shut down) with the EMCY codes in the error."""
        if self._state is not LifecycleState.INACTIVE:
            raise HardwareError(f"activate needs the inactive state (now {self._state.value})")
        self.heartbeats.stop_idle()  # from now on every read() sends it when due
        try:
            self._activate()
        except BaseException:
            if self._state is LifecycleState.INACTIVE:
                self.heartbeats.start_idle()
            raise

    def _activate(self) -> None:
        reading = self.read()
        if not np.all(np.isfinite(reading.position_m)):
            raise HardwareError("cannot activate without positions: " + "; ".join(reading.faults))
        self._clear_trip()
        for axis, node in enumerate(self.settings.node_ids):
            name = f"{AXES[axis]} drive (node {node})"
            counts = int(self.pdos.position_counts[axis])
            self.sdo.write(node, cia402.TARGET_POSITION, counts, name)
            back = self.sdo.read(node, cia402.TARGET_POSITION, name)
            if back != counts:
                raise HardwareError(f"{name}: 0x607A reads back {back} after writing {counts}")
        self.pdos.hold_targets()
        self._enable()
        self._state = LifecycleState.ACTIVE

    def _enable(self) -> None:
        """The enable sequence over this driver's cycle (:meth:`read`)."""
        enable_drives(self.pdos, self.read, self.emcy_log, self.settings.enable_timeout_cycles)

    def deactivate(self) -> None:
        """Disable operation then shut the drives down (the lead screws hold the handle)."""
        if self._state is not LifecycleState.ACTIVE:
            return
        self._state = LifecycleState.INACTIVE
        self._master_stop = None
        # from quick stop, disable operation is no transition: disable voltage instead
        self.pdos.send_both(cia402.CW_DISABLE_VOLTAGE if self._tripped
                            else cia402.CW_DISABLE_OPERATION)
        self.read()
        self.pdos.send_both(cia402.CW_SHUTDOWN)
        self.read()
        self.heartbeats.start_idle()

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
        self.stop_watch.restart()
        self.pdos.hold_targets()
        self.pdos.send_both(cia402.CW_QUICK_STOP)
        self._pending_events.append(f"quick stop on both drives: {reason}")

    def resume_motion(self) -> None:
        """Re-enable the drives after :meth:`stop_motion`: the enable sequence from where each
        drive stopped, every transition checked, the targets at the actual positions (the
        loop's next command starts from there). A failure is a fault in the next reading
        and the drives stay stopped."""
        if self._state is not LifecycleState.ACTIVE or self._master_stop is None:
            return
        self._master_stop = None
        self.pdos.hold_targets()
        try:
            self._enable()
        except HardwareError as error:
            self._pending_faults.append(f"re-enabling after the quick stop failed: {error}")
            return  # still tripped: write() keeps quick stop
        self._tripped = False
        self.pdos.hold_targets()
        self._pending_events.append("drives re-enabled at their actual positions after the "
                                    "quick stop")

    def quick_stop(self, reason: str) -> None:
        """Command quick stop on both drives (they stop where they are) and hold it until the
        next :meth:`activate`; the next reading reports ``reason``."""
        if self._state is not LifecycleState.ACTIVE or self._tripped:
            return
        self._tripped = True
        self.pdos.hold_targets()
        self.pdos.send_both(cia402.CW_QUICK_STOP)
        self._pending_faults.append(f"quick stop on both drives: {reason}")

    def cleanup(self) -> None:
        """Deactivate if needed, stop the nodes' PDOs (NMT pre-operational), close the bus."""
        if self.frames.bus is None:
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

    def _close_bus(self) -> None:
        self.heartbeats.stop_idle()
        self._sync_pending = False
        self.frames.drop_held()
        bus = self.frames.bus
        if bus is not None:
            bus.shutdown()
            self.frames.bus = None

    def _nmt(self, command: int, node: int) -> None:
        self.frames.send(cia402.NMT_COB_ID, bytes([command, node]))

    # --- cyclic I/O ------------------------------------------------------------------

    def sync(self) -> None:
        """Start the next cycle ahead of its :meth:`read`: drop the frames left from an
        earlier SYNC (acting on an EMCY or a heartbeat among them), send the master's
        heartbeat when due and the SYNC. The drives apply the last :meth:`write`'s targets
        and sample at the SYNC and answer while the loop waits for its tick (the runner's
        ``lead``), so :meth:`read` finds the frames there instead of waiting for them; the
        sample-to-command delay stays one SYNC. Nothing when a SYNC is already pending."""
        frames = self.frames
        if frames.bus is None or self._state is LifecycleState.UNCONFIGURED:
            raise HardwareError("sync needs a configured driver")
        if self._sync_pending:
            return
        if self._master_stop is not None:
            self.stop_watch.cycles += 1
        self._discard_late_frames(self._pending_faults, self._sync_drive_fault)
        now = time.monotonic()
        with Burst(frames):  # with the frames held for it (:meth:`until_sync`): one burst
            self.heartbeats.send_if_due(now)
            frames.put(self.pdos.next_sync())
        self._cycle += 1
        self._sync_sent_s = now
        self._sync_pending = True

    def read(self) -> HandleReading:
        """Collect the PDOs of the pending SYNC (:meth:`sync`; sent now when none is
        pending), return the sample (NaN where missing) with the drives' faults and
        statusword events.

        Supervision: EMCYs, a drive in Fault or out of operation enabled, a drive's heartbeat
        older than ``heartbeat_timeout_s`` or reporting another NMT state are faults, and
        while active they command quick stop on both drives; statusword warning bits
        (7 warning, 11 internal limit, 13 following error, 12 cleared: target ignored, 9
        cleared: not remote) are events, once per change."""
        if self.frames.bus is None or self._state is LifecycleState.UNCONFIGURED:
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
        position_m = [math.nan, math.nan]
        have_drive = [False, False]
        force_N = self._collect(now + self.pdo_timeout_s, position_m, have_drive, faults,
                                events, drive_fault)
        states = self.pdos.drive_states
        active = self._state is LifecycleState.ACTIVE
        heartbeats = self.heartbeats
        for axis, node in enumerate(self.settings.node_ids):
            state = states[axis]
            if not have_drive[axis]:
                faults.append(f"missing {self.pdos.tpdo_names[axis]} from the {AXES[axis]} "
                              f"drive (node {node})")
            elif state in (DriveState.FAULT, DriveState.FAULT_REACTION_ACTIVE):
                faults.append(f"{AXES[axis]} drive in {state.value}")
                drive_fault[axis] = True
            elif active and not self._tripped and state is not DriveState.OPERATION_ENABLED:
                faults.append(f"{AXES[axis]} drive left operation enabled ({state.value})")
                drive_fault[axis] = True
            elif self._master_stop is not None and active:
                self.stop_watch.check(axis, state, self.settings.enable_timeout_cycles,
                                      events, faults, drive_fault)
            # inline, the common case (heard in time) costs no call
            if now - heartbeats.seen_s[axis] > heartbeats.timeout_s:
                heartbeats.check_lost(axis, node, now, faults, drive_fault)
        if force_N is None:
            faults.append("missing force sensor frame")
            force_N = _NO_FORCE
        if (drive_fault[0] or drive_fault[1]) and active:
            self.quick_stop("a drive fault")
            faults.extend(self._pending_faults)
            self._pending_faults = []
        reading = HandleReading(np.array(force_N), np.array(position_m), self._cycle,
                                tuple(faults), tuple(events))
        self.last_reading = reading
        return reading

    def _collect(self, deadline: float, position_m: list[float], have_drive: list[bool],
                 faults: list[str], events: list[str], drive_fault: list[bool]
                 ) -> tuple[float, float] | None:
        """Receive the frames of the pending SYNC until both TPDOs and the sensor frame have
        come or ``deadline`` (time.monotonic(), s) has passed: each drive's state and
        position (into ``position_m``, m, and ``have_drive``), its warning events, EMCYs and
        heartbeats; returns the sensor's force (N), None when its frame did not come."""
        bus = self.frames.bus
        assert bus is not None
        pdos = self.pdos
        dispatch = pdos.dispatch
        codecs, swapped = pdos.tpdo_codecs, pdos.tpdo_reversed
        states, positions = pdos.drive_states, pdos.position_counts
        seen_warnings = self._warnings
        heartbeats = self.heartbeats
        metres_per_count = self.settings.metres_per_count
        force_N = None
        while not (have_drive[0] and have_drive[1] and force_N is not None):
            # past the deadline, only what has arrived already (a late read after sync());
            # a long wait (pdo_timeout_s above the heartbeat period: the simulated rig's
            # drives share a busy machine) keeps the heartbeat going, or the drives' consumer
            # would take a master waiting for them for a lost one
            clock = time.monotonic()
            message = bus.recv(timeout=max(min(deadline, heartbeats.due_s) - clock, 0.0))
            if message is None:
                clock = time.monotonic()
                if clock >= deadline:
                    break
                heartbeats.send_if_due(clock)
                continue
            kind, axis = dispatch.get(message.arbitration_id, OTHER)
            if kind == TPDO:
                data = message.data
                codec = codecs[axis]
                if len(data) != codec.size:
                    faults.append(f"{AXES[axis]} drive {pdos.tpdo_names[axis]} malformed: "
                                  f"PDO payload of {len(data)} bytes, expected {codec.size}")
                    continue
                statusword, counts = codec.unpack(data)
                if swapped[axis]:
                    statusword, counts = counts, statusword
                have_drive[axis] = True
                state = states[axis] = cia402.decode_statusword(statusword)
                positions[axis] = counts
                position_m[axis] = counts * metres_per_count
                warnings = (statusword & WARNING_BITS) ^ WARNING_IDLE
                if state is not DriveState.OPERATION_ENABLED:
                    warnings &= ~FOLLOWS_TARGET  # bit 12 speaks only when enabled
                if warnings != seen_warnings[axis]:
                    warning_events(axis, seen_warnings[axis], warnings, events)
                    seen_warnings[axis] = warnings
            elif kind == SENSOR:
                force_N = self.sensor.force(bytes(message.data), faults)
            elif kind in (EMCY, HEARTBEAT) and not message.is_remote_frame:
                self._supervision_frame(kind, axis, bytes(message.data), faults, drive_fault)
        return force_N

    def _supervision_frame(self, kind: int, axis: int, data: bytes, faults: list[str],
                           drive_fault: list[bool]) -> None:
        """An EMCY or a heartbeat of ``axis``'s drive."""
        if kind == EMCY:
            code = emcy_fault(axis, data, faults)
            if code > 0:
                self.emcy_log.append((AXES[axis], code))
                drive_fault[axis] = True
        elif kind == HEARTBEAT:
            self.heartbeats.heard(axis, data, self._state is not LifecycleState.UNCONFIGURED,
                                  faults, drive_fault)

    def _note_supervision_frame(self, message: can.Message) -> None:
        """A frame that came during an SDO exchange: an EMCY is logged and reported by the
        next read, a heartbeat is noted."""
        kind, axis = self.pdos.dispatch.get(message.arbitration_id, OTHER)
        if kind in (EMCY, HEARTBEAT) and not message.is_remote_frame:
            self._supervision_frame(kind, axis, bytes(message.data), self._pending_faults,
                                    [False, False])

    def _discard_late_frames(self, faults: list[str], drive_fault: list[bool]) -> None:
        """Drop frames left from an earlier SYNC (they arrived after its timeout, which that
        cycle reported as missing); an EMCY or a heartbeat among them is still acted on, and
        is not a late frame."""
        frames = self.frames
        bus = frames.bus
        assert bus is not None
        while (message := bus.recv(timeout=0.0)) is not None:
            if message.is_remote_frame or message.arbitration_id in (
                    frames.own_extended_ids if message.is_extended_id else frames.own_ids):
                continue  # our own frame, back from an interface that echoes
            kind, axis = self.pdos.dispatch.get(message.arbitration_id, OTHER)
            if kind in (EMCY, HEARTBEAT):
                self._supervision_frame(kind, axis, bytes(message.data), faults, drive_fault)
                continue
            self.late_frames += 1

    def write(self, position_command_m: np.ndarray) -> None:
        """Send the targets (m) to both drives; a non-finite command is never sent (the
        previous target is repeated and a fault is reported by the next read). After a
        quick stop the drives get quick stop and the held targets until re-activated."""
        if self._state is not LifecycleState.ACTIVE:
            return
        pdos = self.pdos
        if self._tripped:
            pdos.send_both(cia402.CW_QUICK_STOP)
            return
        counts = pdos.target_counts.tolist()  # per axis, as Python ints
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
            counts = pdos.target_counts.tolist()
        else:
            pdos.target_counts = np.array(counts, np.int64)
        pdos.send_rpdos(cia402.CW_ENABLE_OPERATION, counts)

    # --- frames ----------------------------------------------------------------------

    def burst(self) -> Burst:
        """Hold the frames sent inside (RPDOs, :meth:`send_frame`'s) and send them back to
        back at the end, as one burst where the bus can (``unix_datagram``: one datagram, one
        wake-up of the devices' process instead of one per frame; any other bus: one frame
        after the other, as without it). Nested bursts go out with the outermost; frames
        held for the next SYNC (:meth:`until_sync`) go out first."""
        return Burst(self.frames)

    def until_sync(self) -> UntilSync:
        """Hold the frames sent inside until the next SYNC and send them in its burst, just
        before it (the simulated rig's ``unix_datagram`` bus: its devices' process is woken
        once a cycle instead of twice, and the loop's tick no longer pays that wake-up). The
        drives latch synchronous RPDOs and apply them at the SYNC, so they act exactly as if
        the frames had come right away. Anything else sent meanwhile sends them first, in
        order; closing the bus drops them."""
        return UntilSync(self.frames)

    def send_frame(self, frame_id: int, data: bytes, extended: bool = False) -> None:
        """Send one frame as is on the driver's bus (a simulated rig's extra frames, e.g. its
        operator display frame); ``extended``: a 29-bit identifier. :class:`HardwareError`
        when the bus is not open."""
        if self.frames.bus is None:
            raise HardwareError("send_frame needs a configured driver")
        self.frames.send_frame(frame_id, data, extended)


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
