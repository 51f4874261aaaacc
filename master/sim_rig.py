"""The simulated rig: two CiA 402 drives and the force sensor on python-can's virtual bus.

:class:`SimulatedCanRig` runs the pure :class:`~haptic.master.rig_model.RigModel` and speaks
the real frames (NMT, SDO, RPDO1/TPDO1, SYNC, EMCY, the sensor's DBC frame), so the CAN
driver (:class:`~haptic.master.can_driver.CanHandleDriver`) runs unchanged against it. The
devices are stepped by the driver's SYNC frames, one model step per SYNC, so a run is
deterministic whatever the thread timing: RPDOs are synchronous (transmission type 1), a
controlword or target received in cycle k is applied at SYNC k+1, then the model advances,
then each drive answers with TPDO1 and the sensor with its frame sampled at that SYNC.

Faults can be injected for tests and drills: a drive fault (EMCY, statusword Fault), lost
frames, an invalid or overloaded sensor sample.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Any

import can
import numpy as np

from haptic.common.model import model_from_config
from haptic.master import cia402
from haptic.master.can_driver import CanHandleDriver
from haptic.master.cia402 import DriveState
from haptic.master.force_sensor import (
    STATUS_OK,
    STATUS_OVERLOAD,
    ForceSample,
    ForceSensorCodec,
    load_database,
)
from haptic.master.hardware import HandleHardware, HandleReading, LifecycleState, register_hardware
from haptic.master.rig_model import RigModel, RigSample
from haptic.master.settings import CanSettings, master_settings

NMT_PRE_OPERATIONAL_STATE = "pre-operational"
NMT_OPERATIONAL_STATE = "operational"
NMT_STOPPED_STATE = "stopped"


@dataclass
class _Drive:
    node_id: int
    nmt_state: str = NMT_PRE_OPERATIONAL_STATE
    state: DriveState = DriveState.SWITCH_ON_DISABLED
    mode: int = 0
    controlword: int = 0
    received_controlword: int | None = None
    received_target: int | None = None
    target_counts: int = 0
    pending_fault_code: int = 0
    drop_tpdo: int = 0


class SimulatedCanRig:
    """The rig's devices on a virtual bus channel, answering from a background thread.

    Parameters
    ----------
    model:
        The rig block (axes and operator).
    settings:
        Node ids, unit conversions and sensor calibration (the same the driver uses).
    channel:
        python-can virtual bus channel.
    initial_position_m:
        Handle position at start (x, y), m.
    rng:
        Seeded generator for the sensor noise.
    """

    def __init__(self, model: RigModel, settings: CanSettings, channel: str,
                 initial_position_m: tuple[float, float], rng: np.random.Generator) -> None:
        self.model = model
        self.settings = settings
        self.channel = channel
        self.codec = ForceSensorCodec(settings.force_scale_N_per_count,
                                      settings.force_offset_count,
                                      load_database(settings.dbc_file or None))
        self.state = model.initial_state(np.asarray([initial_position_m], float), rng)
        self.drives = [_Drive(node) for node in settings.node_ids]
        self.tool_force_N = np.zeros((1, 2))
        self.last_sample: RigSample | None = None
        self.sync_count = 0
        self.errors: list[str] = []
        self._sensor_counter = 0
        self._sensor_status_override: int | None = None
        self._sensor_status_cycles = 0
        self._drop_sensor = 0
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._bus: can.BusABC | None = None
        self._thread: threading.Thread | None = None

    # --- lifecycle -------------------------------------------------------------------

    def start(self) -> None:
        """Connect to the virtual bus and start answering frames; send the boot-ups."""
        if self._thread is not None:
            return
        self._bus = can.Bus(interface="virtual", channel=self.channel)
        self._stop.clear()
        self._thread = threading.Thread(target=self._serve, name="sim-rig", daemon=True)
        self._thread.start()
        for drive in self.drives:
            self._send(0x700 + drive.node_id, b"\x00")  # boot-up

    def stop(self) -> None:
        """Stop the thread (joined) and leave the bus."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        if self._bus is not None:
            self._bus.shutdown()
            self._bus = None

    # --- fault injection (thread-safe; acts at the next SYNC) -------------------------

    def inject_drive_fault(self, axis: int, error_code: int = 0x2310) -> None:
        """The drive of ``axis`` (0 x, 1 y) faults: EMCY ``error_code`` and statusword Fault."""
        with self._lock:
            self.drives[axis].pending_fault_code = error_code

    def drop_tpdo(self, axis: int, count: int = 1) -> None:
        """The drive of ``axis`` sends no TPDO1 for the next ``count`` SYNCs."""
        with self._lock:
            self.drives[axis].drop_tpdo = count

    def drop_sensor_frames(self, count: int = 1) -> None:
        """The sensor sends nothing for the next ``count`` SYNCs."""
        with self._lock:
            self._drop_sensor = count

    def set_sensor_status(self, status: int, count: int = 1) -> None:
        """The sensor reports ``status`` (e.g. 2 invalid) for the next ``count`` SYNCs."""
        with self._lock:
            self._sensor_status_override = status
            self._sensor_status_cycles = count

    def set_tool_force(self, tool_force_N: np.ndarray) -> None:
        """The tool force (N, x and y) the operator feels from now on."""
        with self._lock:
            self.tool_force_N = np.asarray(tool_force_N, float).reshape(1, 2).copy()

    # --- frame handling (the thread) --------------------------------------------------

    def _serve(self) -> None:
        while not self._stop.is_set():
            bus = self._bus
            if bus is None:
                return
            message = bus.recv(timeout=0.05)
            if message is None:
                continue
            try:
                with self._lock:
                    self._handle(message.arbitration_id, bytes(message.data))
            except Exception as error:  # keep serving; the test or user sees .errors
                self.errors.append(f"{type(error).__name__}: {error}")

    def _send(self, frame_id: int, data: bytes) -> None:
        if self._bus is not None:
            self._bus.send(can.Message(arbitration_id=frame_id, data=data, is_extended_id=False))

    def _handle(self, frame_id: int, data: bytes) -> None:
        if frame_id == cia402.SYNC_COB_ID:
            self._on_sync()
            return
        if frame_id == cia402.NMT_COB_ID and len(data) >= 2:
            self._on_nmt(data[0], data[1])
            return
        for drive in self.drives:
            if frame_id == cia402.RPDO1_BASE + drive.node_id:
                if drive.nmt_state == NMT_OPERATIONAL_STATE:
                    controlword, target = cia402.decode_pdo(cia402.RPDO1_MAPPING, data)
                    drive.received_controlword, drive.received_target = controlword, target
                return
            if frame_id == cia402.SDO_RX_BASE + drive.node_id:
                if drive.nmt_state != NMT_STOPPED_STATE:
                    self._send(cia402.SDO_TX_BASE + drive.node_id, self._on_sdo(drive, data))
                return

    def _on_nmt(self, command: int, node: int) -> None:
        for drive in self.drives:
            if node not in (0, drive.node_id):
                continue
            if command == cia402.NMT_START:
                drive.nmt_state = NMT_OPERATIONAL_STATE
            elif command == cia402.NMT_STOP:
                drive.nmt_state = NMT_STOPPED_STATE
            elif command == cia402.NMT_PRE_OPERATIONAL:
                drive.nmt_state = NMT_PRE_OPERATIONAL_STATE
            elif command in (cia402.NMT_RESET_NODE, cia402.NMT_RESET_COMMUNICATION):
                drive.nmt_state = NMT_PRE_OPERATIONAL_STATE
                self._send(0x700 + drive.node_id, b"\x00")

    def _on_sdo(self, drive: _Drive, data: bytes) -> bytes:
        request = cia402.decode_sdo(data)
        index, subindex = request.index, request.subindex
        if subindex != 0 or index not in cia402.OBJECT_DICTIONARY:
            return cia402.sdo_abort(index, subindex, cia402.SDO_ABORT_NO_OBJECT)
        variable = cia402.OBJECT_DICTIONARY[index]
        axis = self.drives.index(drive)
        if request.command == 0x40:  # upload
            values = {
                0x6040: drive.controlword, 0x6041: self._statusword(drive),
                0x6060: drive.mode, 0x6061: drive.mode, 0x607A: drive.target_counts,
                0x6064: self._position_counts(axis),
            }
            return cia402.sdo_upload_response(variable, values[index])
        size = cia402.sdo_download_size(request.command)
        if size is None:
            return cia402.sdo_abort(index, subindex, cia402.SDO_ABORT_COMMAND)
        if not variable.writable:
            return cia402.sdo_abort(index, subindex, cia402.SDO_ABORT_READ_ONLY)
        value = int(variable.decode_raw(request.data[:size]))
        if index == 0x6060:
            if value != cia402.MODE_CYCLIC_SYNC_POSITION:
                return cia402.sdo_abort(index, subindex, cia402.SDO_ABORT_VALUE_RANGE)
            drive.mode = value
        elif index == 0x6040:
            drive.received_controlword = value
        elif index == 0x607A:
            drive.received_target = value
        return cia402.sdo_download_response(index, subindex)

    def _statusword(self, drive: _Drive) -> int:
        return cia402.statusword_for(drive.state, following_target=True)

    def _position_counts(self, axis: int) -> int:
        position = self.last_sample.handle_position_m[0, axis] if self.last_sample else (
            self.state.plant[0] @ self.model.position_C[axis])
        return int(self.settings.counts_from_metres(position))

    def _on_sync(self) -> None:
        self.sync_count += 1
        targets = np.full((1, 2), np.nan)
        for axis, drive in enumerate(self.drives):
            if drive.pending_fault_code:
                drive.state = DriveState.FAULT
                self._send(cia402.EMCY_BASE + drive.node_id,
                           cia402.emcy_frame(drive.pending_fault_code))
                drive.pending_fault_code = 0
            if drive.received_controlword is not None:
                previous = drive.controlword
                drive.controlword = drive.received_controlword
                enabled_before = drive.state is DriveState.OPERATION_ENABLED
                if drive.mode == cia402.MODE_CYCLIC_SYNC_POSITION:
                    drive.state = cia402.next_drive_state(drive.state, drive.controlword,
                                                          previous)
                if drive.state is DriveState.OPERATION_ENABLED and not enabled_before:
                    drive.target_counts = self._position_counts(axis)  # no jump on enable
            if drive.received_target is not None and drive.state is DriveState.OPERATION_ENABLED:
                drive.target_counts = drive.received_target
            drive.received_controlword = drive.received_target = None
            if drive.state is DriveState.OPERATION_ENABLED:
                targets[0, axis] = self.settings.metres_from_counts(drive.target_counts)
        # Disabled or faulted drives keep the command they applied (brake, lead screw).
        sample = self.model.step(self.state, targets, self.tool_force_N)
        self.last_sample = sample
        for axis, drive in enumerate(self.drives):
            if drive.nmt_state != NMT_OPERATIONAL_STATE:
                continue
            if drive.drop_tpdo > 0:
                drive.drop_tpdo -= 1
                continue
            self._send(cia402.TPDO1_BASE + drive.node_id, cia402.encode_pdo(
                cia402.TPDO1_MAPPING, (self._statusword(drive), self._position_counts(axis))))
        self._send_sensor(sample.handle_force_measured_N[0])

    def _send_sensor(self, force_N: np.ndarray) -> None:
        counter = self._sensor_counter
        self._sensor_counter = (counter + 1) % 256
        if self._drop_sensor > 0:
            self._drop_sensor -= 1
            return
        raw_x, raw_y, saturated = self.codec.to_counts(force_N)
        status = STATUS_OVERLOAD if saturated else STATUS_OK
        if self._sensor_status_cycles > 0 and self._sensor_status_override is not None:
            status = self._sensor_status_override
            self._sensor_status_cycles -= 1
        self._send(self.codec.frame_id, self.codec.encode(ForceSample(raw_x, raw_y, counter,
                                                                      status)))


class SimulatedRigHardware(HandleHardware):
    """The simulated rig behind the hardware interface: the CAN driver talking to a
    :class:`SimulatedCanRig` on a virtual bus (the control code cannot tell it from the
    real rig)."""

    def __init__(self, rig: SimulatedCanRig, driver: CanHandleDriver) -> None:
        self.rig = rig
        self.driver = driver

    @property
    def lifecycle_state(self) -> LifecycleState:
        return self.driver.lifecycle_state

    def configure(self) -> None:
        self.rig.start()
        try:
            self.driver.configure()
        except BaseException:
            self.rig.stop()
            raise

    def activate(self) -> None:
        self.driver.activate()

    def deactivate(self) -> None:
        self.driver.deactivate()

    def cleanup(self) -> None:
        try:
            self.driver.cleanup()
        finally:
            self.rig.stop()

    def read(self) -> HandleReading:
        return self.driver.read()

    def write(self, position_command_m: np.ndarray) -> None:
        self.driver.write(position_command_m)

    def present_tool_force(self, tool_force_N: np.ndarray) -> None:
        self.rig.set_tool_force(tool_force_N)


def simulated_rig_hardware(config: dict[str, Any]) -> SimulatedRigHardware:
    """The simulated rig for a validated configuration (``[model]``, ``[master.can]`` for
    node ids and conversions, ``[master.sim]``)."""
    settings = master_settings(config)
    model = model_from_config(config)
    sim = settings.sim
    rig_model = RigModel.from_model(model, sim.operator, sim.force_noise_std_N)
    rig = SimulatedCanRig(rig_model, settings.can, sim.channel, sim.initial_position_m,
                          np.random.default_rng(sim.seed))
    driver = CanHandleDriver(settings.can, {"interface": "virtual", "channel": sim.channel},
                             sim.pdo_timeout_s)
    return SimulatedRigHardware(rig, driver)


register_hardware("sim")(simulated_rig_hardware)
