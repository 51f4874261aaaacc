"""The handle over CAN: two CiA 402 drives in cyclic synchronous position mode and the
two-channel force sensor (DBC), behind :class:`~haptic.master.hardware.HandleHardware`.

One control cycle is one SYNC: :meth:`CanHandleDriver.read` sends SYNC and waits (at most
``pdo_timeout_s``) for both drives' TPDO1 (statusword, position actual value) and the
sensor frame sampled at that SYNC; :meth:`CanHandleDriver.write` sends each drive's RPDO1
(controlword, target position), which the drive applies at the next SYNC. A command
written in cycle k therefore acts over [t_{k+1}, t_{k+2}): zero-order hold plus one sample
of delay, the contract the analysis and the simulated rig use.

Units are converted here and nowhere else: counts <-> m with the lead-screw pitch and the
encoder resolution, raw sensor counts -> N with the configured scale and offset.
"""

from __future__ import annotations

import time
from typing import Any

import can
import numpy as np

from haptic.master import cia402
from haptic.master.cia402 import DriveState
from haptic.master.force_sensor import ForceSensorCodec, load_database
from haptic.master.hardware import (
    HandleHardware,
    HandleReading,
    HardwareError,
    LifecycleState,
    register_hardware,
)
from haptic.master.settings import CanSettings, master_settings

AXES = ("x", "y")
INT32_MAX = 2**31 - 1


class CanHandleDriver(HandleHardware):
    """The handle on a CAN bus opened with ``can.Bus(**bus_options)``.

    Parameters
    ----------
    settings:
        Node ids, unit conversions and the sensor's DBC, scale and offset.
    bus_options:
        Keyword arguments of ``can.Bus`` (interface, channel, bitrate, ...).
    pdo_timeout_s:
        How long :meth:`read` waits for the frames of its SYNC, s.
    """

    def __init__(self, settings: CanSettings, bus_options: dict[str, Any],
                 pdo_timeout_s: float) -> None:
        self.settings = settings
        self.bus_options = dict(bus_options)
        self.pdo_timeout_s = float(pdo_timeout_s)
        self.codec = ForceSensorCodec(settings.force_scale_N_per_count,
                                      settings.force_offset_count,
                                      load_database(settings.dbc_file or None))
        self._bus: can.BusABC | None = None
        self._state = LifecycleState.UNCONFIGURED
        self._cycle = 0
        self._drive_states = [DriveState.NOT_READY_TO_SWITCH_ON] * 2
        self._last_controlword = [cia402.CW_DISABLE_VOLTAGE] * 2
        self._target_counts = np.zeros(2, np.int64)
        self._position_counts = np.zeros(2, np.int64)
        self._sensor_counter: int | None = None
        self._pending_faults: list[str] = []
        self.last_reading: HandleReading | None = None
        #: Frames that arrived after their cycle's timeout and were discarded.
        self.late_frames = 0
        # What this driver sends (NMT, SYNC, its RPDO1s and SDO requests; extra frames by
        # id): an interface that hands a process its own frames back (udp_multicast) does
        # not make them late frames.
        self._own_ids = ({cia402.NMT_COB_ID, cia402.SYNC_COB_ID}
                         | {cia402.RPDO1_BASE + n for n in settings.node_ids}
                         | {cia402.SDO_RX_BASE + n for n in settings.node_ids})
        self._own_extended_ids: set[int] = set()

    # --- lifecycle -------------------------------------------------------------------

    @property
    def lifecycle_state(self) -> LifecycleState:
        return self._state

    @property
    def drive_states(self) -> tuple[DriveState, DriveState]:
        """CiA 402 state of the x and y drives, from the last statusword read."""
        return (self._drive_states[0], self._drive_states[1])

    def configure(self) -> None:
        """Open the bus, put the drives in cyclic synchronous position mode over SDO, start
        them (NMT) and take a first sample."""
        if self._state is not LifecycleState.UNCONFIGURED:
            return
        try:
            self._bus = can.Bus(**self.bus_options)
        except (can.CanError, OSError, ValueError, ImportError) as error:
            options = ", ".join(f"{k}={v}" for k, v in self.bus_options.items())
            raise HardwareError(f"cannot open the CAN bus ({options}): {error}") from None
        try:
            for node in self.settings.node_ids:
                self._nmt(cia402.NMT_PRE_OPERATIONAL, node)
            for axis, node in enumerate(self.settings.node_ids):
                self._sdo_write(node, cia402.MODES_OF_OPERATION,
                                cia402.MODE_CYCLIC_SYNC_POSITION, AXES[axis])
                mode = self._sdo_read(node, cia402.MODES_OF_OPERATION_DISPLAY, AXES[axis])
                if mode != cia402.MODE_CYCLIC_SYNC_POSITION:
                    raise HardwareError(f"{AXES[axis]} drive (node {node}) reports mode "
                                        f"{mode}, not cyclic synchronous position (8)")
            for node in self.settings.node_ids:
                self._nmt(cia402.NMT_START, node)
            self._state = LifecycleState.INACTIVE
            reading = self.read()
            if not np.all(np.isfinite(reading.position_m)):
                raise HardwareError("no position from the drives after start: "
                                    + "; ".join(reading.faults))
        except BaseException:
            self._close_bus()
            self._state = LifecycleState.UNCONFIGURED
            raise
        self._target_counts = self._position_counts.copy()

    def activate(self) -> None:
        """Run the CiA 402 enable sequence (fault reset, shutdown, switch on, enable
        operation) on both drives, targets holding the current position."""
        if self._state is not LifecycleState.INACTIVE:
            raise HardwareError(f"activate needs the inactive state (now {self._state.value})")
        reading = self.read()
        if not np.all(np.isfinite(reading.position_m)):
            raise HardwareError("cannot activate without positions: " + "; ".join(reading.faults))
        self._target_counts = self._position_counts.copy()
        for _ in range(self.settings.enable_timeout_cycles):
            commands = [self._enable_step(axis) for axis in range(2)]
            if all(command is None for command in commands):
                break
            for axis, command in enumerate(commands):
                self._send_rpdo(axis, self._last_controlword[axis] if command is None
                                else command)
            self.read()
            self._target_counts = self._position_counts.copy()
        else:
            self._send_both(cia402.CW_SHUTDOWN)
            states = ", ".join(f"{a}: {s.value}" for a, s in zip(AXES, self._drive_states,
                                                                 strict=True))
            raise HardwareError(f"drives did not reach operation enabled ({states})")
        self._state = LifecycleState.ACTIVE

    def _enable_step(self, axis: int) -> int | None:
        command = cia402.enable_command_for(self._drive_states[axis])
        if command == cia402.CW_FAULT_RESET and self._last_controlword[axis] & 0x80:
            return cia402.CW_DISABLE_VOLTAGE  # fault reset acts on a rising edge of bit 7
        return command

    def deactivate(self) -> None:
        """Disable operation then shut the drives down (the lead screws hold the handle)."""
        if self._state is not LifecycleState.ACTIVE:
            return
        self._state = LifecycleState.INACTIVE
        self._send_both(cia402.CW_DISABLE_OPERATION)
        self.read()
        self._send_both(cia402.CW_SHUTDOWN)
        self.read()

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

    def _close_bus(self) -> None:
        if self._bus is not None:
            self._bus.shutdown()
            self._bus = None

    # --- cyclic I/O ------------------------------------------------------------------

    def read(self) -> HandleReading:
        """Send SYNC, collect that SYNC's PDOs, return the sample (NaN where missing)."""
        if self._bus is None or self._state is LifecycleState.UNCONFIGURED:
            raise HardwareError("read needs a configured driver")
        faults = self._pending_faults
        self._pending_faults = []
        self._discard_late_frames(faults)
        self._bus.send(can.Message(arbitration_id=cia402.SYNC_COB_ID, data=b"",
                                   is_extended_id=False))
        self._cycle += 1
        nodes = self.settings.node_ids
        tpdo_ids = {cia402.TPDO1_BASE + node: axis for axis, node in enumerate(nodes)}
        emcy_ids = {cia402.EMCY_BASE + node: axis for axis, node in enumerate(nodes)}
        position_m = np.full(2, np.nan)
        force_N = np.full(2, np.nan)
        have_drive = [False, False]
        have_sensor = False
        deadline = time.monotonic() + self.pdo_timeout_s
        while not (all(have_drive) and have_sensor):
            remaining = deadline - time.monotonic()
            if remaining <= 0.0:
                break
            message = self._bus.recv(timeout=remaining)
            if message is None:
                break
            frame_id, data = message.arbitration_id, bytes(message.data)
            if frame_id in tpdo_ids:
                axis = tpdo_ids[frame_id]
                try:
                    statusword, counts = cia402.decode_pdo(cia402.TPDO1_MAPPING, data)
                except ValueError as error:
                    faults.append(f"{AXES[axis]} drive TPDO1 malformed: {error}")
                    continue
                have_drive[axis] = True
                self._drive_states[axis] = cia402.decode_statusword(statusword)
                self._position_counts[axis] = counts
                position_m[axis] = self.settings.metres_from_counts(counts)
            elif frame_id == self.codec.frame_id:
                have_sensor = True
                force_N = self._sensor_force(data, faults)
            elif frame_id in emcy_ids:
                axis = emcy_ids[frame_id]
                code, register = cia402.decode_emcy(data)
                if code != 0:
                    faults.append(f"{AXES[axis]} drive EMCY error code 0x{code:04X} "
                                  f"(register 0x{register:02X})")
        for axis, node in enumerate(nodes):
            if not have_drive[axis]:
                faults.append(f"missing TPDO1 from the {AXES[axis]} drive (node {node})")
            elif self._drive_states[axis] in (DriveState.FAULT, DriveState.FAULT_REACTION_ACTIVE):
                faults.append(f"{AXES[axis]} drive in {self._drive_states[axis].value}")
            elif self._state is LifecycleState.ACTIVE and (
                self._drive_states[axis] is not DriveState.OPERATION_ENABLED
            ):
                faults.append(f"{AXES[axis]} drive left operation enabled "
                              f"({self._drive_states[axis].value})")
        if not have_sensor:
            faults.append("missing force sensor frame")
        reading = HandleReading(force_N, position_m, self._cycle, tuple(faults))
        self.last_reading = reading
        return reading

    def _discard_late_frames(self, faults: list[str]) -> None:
        """Drop frames left from an earlier SYNC (they arrived after its timeout, which that
        cycle reported as missing); an EMCY among them is still reported."""
        assert self._bus is not None
        emcy_ids = {cia402.EMCY_BASE + node: axis
                    for axis, node in enumerate(self.settings.node_ids)}
        while (message := self._bus.recv(timeout=0.0)) is not None:
            if message.arbitration_id in (self._own_extended_ids if message.is_extended_id
                                          else self._own_ids):
                continue  # our own frame, back from an interface that echoes
            self.late_frames += 1
            if message.arbitration_id in emcy_ids:
                code, register = cia402.decode_emcy(bytes(message.data))
                faults.append(f"{AXES[emcy_ids[message.arbitration_id]]} drive EMCY error "
                              f"code 0x{code:04X} (register 0x{register:02X})")

    def _sensor_force(self, data: bytes, faults: list[str]) -> np.ndarray:
        try:
            sample = self.codec.decode(data)
        except Exception as error:  # cantools raises several types for a bad frame
            faults.append(f"force sensor frame malformed: {error}")
            return np.full(2, np.nan)
        if self._sensor_counter is not None and sample.counter != (self._sensor_counter + 1) % 256:
            faults.append(f"force sensor counter jumped from {self._sensor_counter} to "
                          f"{sample.counter} (a stale or lost sample)")
        self._sensor_counter = sample.counter
        force = self.codec.to_newtons(sample)
        if not np.all(np.isfinite(force)):
            faults.append(f"force sensor status {sample.status} (not ok)")
        return force

    def write(self, position_command_m: np.ndarray) -> None:
        """Send the targets (m) to both drives; a non-finite command is never sent (the
        previous target is repeated and a fault is reported by the next read)."""
        if self._state is not LifecycleState.ACTIVE:
            return
        command = np.asarray(position_command_m, float)
        counts = self._target_counts.copy()
        finite = np.isfinite(command)
        if not np.all(finite):
            self._pending_faults.append("non-finite position command refused")
        counts[finite] = self.settings.counts_from_metres(command[finite])
        if np.any(np.abs(counts) > INT32_MAX):
            self._pending_faults.append("position command beyond the drives' int32 range")
            counts = self._target_counts.copy()
        self._target_counts = counts
        self._send_both(cia402.CW_ENABLE_OPERATION)

    # --- frames ----------------------------------------------------------------------

    def send_frame(self, frame_id: int, data: bytes, extended: bool = False) -> None:
        """Send one frame as is on the driver's bus (a simulated rig's extra frames, e.g. its
        operator display frame); ``extended``: a 29-bit identifier. :class:`HardwareError`
        when the bus is not open."""
        if self._bus is None:
            raise HardwareError("send_frame needs a configured driver")
        (self._own_extended_ids if extended else self._own_ids).add(frame_id)
        self._bus.send(can.Message(arbitration_id=frame_id, data=data, is_extended_id=extended))

    def _send(self, frame_id: int, data: bytes) -> None:
        assert self._bus is not None
        self._bus.send(can.Message(arbitration_id=frame_id, data=data, is_extended_id=False))

    def _send_rpdo(self, axis: int, controlword: int) -> None:
        node = self.settings.node_ids[axis]
        payload = cia402.encode_pdo(cia402.RPDO1_MAPPING,
                                    (controlword, int(self._target_counts[axis])))
        self._send(cia402.RPDO1_BASE + node, payload)
        self._last_controlword[axis] = controlword

    def _send_both(self, controlword: int) -> None:
        for axis in range(2):
            self._send_rpdo(axis, controlword)

    def _nmt(self, command: int, node: int) -> None:
        self._send(cia402.NMT_COB_ID, bytes([command, node]))

    def _sdo_exchange(self, node: int, request: bytes, label: str) -> cia402.SdoFrame:
        assert self._bus is not None
        self._send(cia402.SDO_RX_BASE + node, request)
        deadline = time.monotonic() + self.pdo_timeout_s * self.settings.enable_timeout_cycles
        while (remaining := deadline - time.monotonic()) > 0.0:
            message = self._bus.recv(timeout=remaining)
            if message is None:
                break
            if message.arbitration_id == cia402.SDO_TX_BASE + node:
                reply = cia402.decode_sdo(bytes(message.data))
                if reply.command == 0x80:
                    code = int.from_bytes(reply.data, "little")
                    raise HardwareError(f"{label}: SDO abort 0x{code:08X} on "
                                        f"0x{reply.index:04X}")
                return reply
        raise HardwareError(f"{label}: no SDO reply from node {node}")

    def _sdo_write(self, node: int, variable: Any, value: int, axis: str) -> None:
        reply = self._sdo_exchange(node, cia402.sdo_download_request(variable, value),
                                   f"{axis} drive write {variable.name}")
        if reply.command != 0x60:
            raise HardwareError(f"{axis} drive: unexpected SDO reply 0x{reply.command:02X}")

    def _sdo_read(self, node: int, variable: Any, axis: str) -> int:
        reply = self._sdo_exchange(node, cia402.sdo_upload_request(variable),
                                   f"{axis} drive read {variable.name}")
        size = variable.STRUCT_TYPES[variable.data_type].size
        return int(variable.decode_raw(reply.data[:size]))


@register_hardware("can")
def _can_hardware(config: dict[str, Any]) -> HandleHardware:
    settings = master_settings(config)
    can_settings = settings.can
    return CanHandleDriver(
        can_settings,
        {"interface": can_settings.interface, "channel": can_settings.channel,
         "bitrate": can_settings.bitrate},
        can_settings.pdo_timeout_s,
    )
