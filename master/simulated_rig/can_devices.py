"""The simulated rig: two CiA 402 drives and the force sensor as CAN frame logic.

:class:`SimulatedCanRig` runs the pure :class:`~haptic.master.simulated_rig.rig_block.RigModel`
and speaks the real frames (NMT, SDO, RPDO1/TPDO1, SYNC, EMCY, heartbeat, the sensor's DBC
frame), so the CAN driver (:class:`~haptic.master.hardware.can_driver.CanHandleDriver`) runs
unchanged against it. Each drive is a conformant CiA 301/402 device
(:mod:`haptic.master.hardware.drive_device`: canopen's ``LocalNode`` with the object
dictionary of its EDS, PDOs as configured by SDO, heartbeat producer and consumer, RPDO
deadline, following error window, quick stop); the driver configures it from scratch as it
would a real drive. The devices are stepped by the driver's SYNC frames, one model step per
SYNC, so a run is deterministic whatever the thread or process timing: RPDOs are synchronous
(transmission type 1), a controlword or target received in cycle k is applied at SYNC k+1,
then the model advances, then each drive answers with TPDO1 and the sensor with its frame
sampled at that SYNC.

The rig composes its parts, one job each: the drives as network nodes (NMT, heartbeats, node
and life guarding; :mod:`~haptic.master.simulated_rig.device_network`), the devices' answer
to one SYNC (:mod:`~haptic.master.simulated_rig.sync_answer`) and the emulator-only operator
frames (:mod:`~haptic.master.simulated_rig.operator_frames`). Here: who feeds the frames, which
frame goes where, the SYNC answer prepared ahead or taken back, and fault injection.

The frame logic does not care who feeds it frames. :meth:`SimulatedCanRig.start` serves
python-can's ``virtual`` bus from a background thread of this process (backend
``sim-inproc``: the tests that inject faults use it);
:mod:`haptic.master.simulated_rig.rig_emulator`
serves a bus that crosses processes from its own process, ``haptic-rig-sim`` (backend
``sim``, as a real rig's drives are separate devices). Both call :meth:`SimulatedCanRig.serve`.

The operator display frame (simulated rigs only, :data:`OPERATOR_DISPLAY_ID`) carries the
tool force the master reflects to the simulated operator, who feels it. It is also the last
frame the ``sim`` backend sends in a cycle, so from it on the serving loop, whenever no frame
waits, prepares the devices' answer to the next SYNC (model step and frames), and the SYNC
itself only sends the prepared frames; any later frame that changes an input (RPDO, NMT,
SDO, fault injection) discards the prepared answer, which is prepared anew when idle again or
computed at the SYNC. Frames that come in the SYNC's own datagram (the ``sim`` backend's
cycle) are answered at the SYNC. The answer is the same either way.

Faults can be injected for tests and drills: a drive fault (EMCY, statusword Fault), lost
frames, an invalid or overloaded sensor sample.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import can
import numpy as np

from haptic.common.model.teleop import model_from_config
from haptic.master.hardware import cia402
from haptic.master.hardware.can_driver import CanHandleDriver
from haptic.master.hardware.cia402 import DriveState
from haptic.master.hardware.drive_device import DriveObjects, DriveRuntime
from haptic.master.hardware.force_sensor import (
    STATUS_OK,
    STATUS_OVERLOAD,
    ForceSensorCodec,
    load_database,
)
from haptic.master.hardware.interface import (
    HandleHardware,
    HandleReading,
    LifecycleState,
)
from haptic.master.hardware.unix_can import (
    EXTENDED_FLAG,
    FD_FLAG,
    RawFrame,
    send_raw_burst,
    wire_flags,
)
from haptic.master.settings import CanSettings, master_settings
from haptic.master.simulated_rig.device_network import (
    NMT_OPERATIONAL_STATE,
    NMT_PRE_OPERATIONAL_STATE,
    NMT_STOPPED_STATE,
    DeviceNetwork,
)
from haptic.master.simulated_rig.operator_frames import (
    OPERATOR_DISPLAY_ID,
    OPERATOR_READY_ID,
    decode_operator_display,
    encode_operator_display,
)
from haptic.master.simulated_rig.rig_block import RigModel, RigSample
from haptic.master.simulated_rig.sync_answer import (
    SyncAnswer,
    apply_latched,
    check_following_error,
    check_sync,
    raw_frames,
    state_arrays,
    tpdo_frames,
)

__all__ = [
    "NMT_OPERATIONAL_STATE", "NMT_PRE_OPERATIONAL_STATE", "NMT_STOPPED_STATE",
    "OPERATOR_DISPLAY_ID", "OPERATOR_READY_ID", "SimulatedCanRig", "SimulatedRigHardware",
    "decode_operator_display", "encode_operator_display", "simulated_rig_hardware",
]


def _receive(bus: can.BusABC, timeout_s: float) -> list[RawFrame]:
    """The frames ``bus`` has within ``timeout_s``: a whole datagram's, raw, where the bus
    gives them so (``unix_datagram``'s ``recv_frames``), else the one frame ``recv`` gives."""
    receive_frames = getattr(bus, "recv_frames", None)
    if receive_frames is not None:
        return receive_frames(timeout_s)
    message = bus.recv(timeout=timeout_s)
    if message is None:
        return []
    return [(message.arbitration_id, wire_flags(message), bytes(message.data))]


class SimulatedCanRig:
    """The rig's devices: CAN frame logic over :class:`RigModel`, fed frames either by its own
    thread on a virtual bus (:meth:`start`) or by a caller's loop (:meth:`attach`, then
    :meth:`serve`).

    Parameters
    ----------
    model:
        The rig block (axes and operator).
    settings:
        Node ids, unit conversions and sensor calibration (the same the driver uses).
    channel:
        python-can virtual bus channel :meth:`start` opens (informative for :meth:`attach`).
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
        self._state_arrays = state_arrays(self.state)
        self.tool_force_N = np.zeros((1, 2))
        #: whether the operator has grasped the handle (the ready lamp has been on)
        self.operator_grasped = False
        self.last_sample: RigSample | None = None
        self.drives = [DriveRuntime(node) for node in settings.node_ids]
        #: Each drive's object dictionary (its EDS) and communication objects.
        self.devices = [
            DriveObjects(node, eds, self._send, drive,
                         lambda axis=axis: self._position_counts(axis), fd=settings.fd,
                         sync_period_s=model.period_s)
            for axis, (node, eds, drive) in enumerate(zip(settings.node_ids, settings.eds_files,
                                                          self.drives, strict=True))]
        for axis, drive in enumerate(self.drives):
            drive.position_counts = self._position_counts(axis)
        #: SYNCs received as CAN FD frames: the cyclic answers go out as FD frames too.
        self._sync_fd = False
        self.sync_count = 0
        #: Each drive's last SYNC counter (0: none yet) and the counter jumps it saw.
        self.sync_counter_seen = [0, 0]
        self.sync_counter_jumps = [0, 0]
        #: The drives as network nodes: NMT, heartbeats, node and life guarding.
        self.network = DeviceNetwork(self.drives, self.devices, self._send,
                                     self._connection_lost, self.sync_counter_seen)
        #: SYNCs answered with an answer prepared ahead (:meth:`prepare_ahead`).
        self.prepared_syncs = 0
        self.errors: list[str] = []
        self._sensor_counter = 0
        self._sensor_status_override: int | None = None
        self._sensor_status_cycles = 0
        self._drop_sensor = 0
        self._prepared: SyncAnswer | None = None
        #: The display frame came since the last SYNC: its answer may be prepared ahead.
        self._answer_wanted = False
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._bus: can.BusABC | None = None
        self._thread: threading.Thread | None = None

    @classmethod
    def from_config(cls, config: dict[str, Any], channel: str,
                    operator_waits_for_lamp: bool = False) -> SimulatedCanRig:
        """The devices of a validated configuration: ``[model]`` (Ts, Gh, Th), ``[master.can]``
        (node ids, conversions, DBC) and ``[master.sim]`` (operator, noise, seed, start).
        ``operator_waits_for_lamp``: the operator's script starts at the first ready-lamp
        frame (:data:`OPERATOR_READY_ID`, sent by the simulated backends); otherwise at the
        first SYNC (a rig driven by the ``can`` backend, which sends no emulator frames)."""
        settings = master_settings(config)
        sim = settings.sim
        rig_model = RigModel.from_model(model_from_config(config), sim.operator,
                                        sim.force_noise_std_N)
        rig = cls(rig_model, settings.can, channel, sim.initial_position_m,
                  np.random.default_rng(sim.seed))
        rig.operator_grasped = not operator_waits_for_lamp
        return rig

    # --- lifecycle -------------------------------------------------------------------

    def start(self) -> None:
        """Connect to the virtual bus ``channel`` and answer frames from a background thread
        of this process; send the boot-ups."""
        if self._thread is not None:
            return
        self._stop.clear()
        self.attach(can.Bus(interface="virtual", channel=self.channel))
        self._thread = threading.Thread(target=self.serve, args=(self._stop.is_set,),
                                        name="sim-rig", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop the thread (joined) and leave the bus."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        if self._bus is not None:
            self._bus.shutdown()
            self._bus = None

    def attach(self, bus: can.BusABC) -> None:
        """Speak on ``bus`` (opened by the caller, who also shuts it down) from now on, and
        send the drives' boot-ups."""
        self._bus = bus
        self.network.boot_up()

    def serve(self, should_stop: Callable[[], bool], poll_s: float = 0.05,
              on_error: Callable[[str], None] | None = None) -> None:
        """Block on the bus and answer each frame until ``should_stop()`` is true (checked
        after the frames of each receive and at least every ``poll_s`` s). Between frames
        the drives' heartbeats go out and their heartbeat consumers are checked
        (:meth:`poll_timers`), after the frames already queued are handled: a drive's
        consumer runs on frames as they arrive, so a heartbeat that came while this process
        was not scheduled counts (a busy machine must not look like a lost master). Once the
        operator display frame has come, the answer to the next SYNC is prepared whenever no
        frame is waiting (:meth:`prepare_ahead`), so the SYNC only sends it. On this
        package's ``unix_datagram`` bus the frames come as raw tuples, a whole datagram at a
        time (no python-can message objects: about a sixth of the emulator's CPU a cycle).
        A frame that raises is recorded in :attr:`errors` (and passed to ``on_error``) and
        serving goes on."""
        network = self.network
        while not should_stop():
            bus = self._bus
            if bus is None:
                return
            now_s = time.monotonic()
            if now_s >= network.timers_due_s:  # only when a heartbeat or a check is due
                self._handle_queued(bus, on_error)
                now_s = time.monotonic()
                network.timers_due_s = now_s + max(0.0, self.poll_timers(now_s))
            frames = _receive(bus, 0.0)  # the frames already here come first
            if not frames:
                if self._answer_wanted:  # idle: prepare the next SYNC's answer meanwhile
                    self.prepare_ahead()
                    now_s = time.monotonic()
                frames = _receive(bus, min(poll_s, max(0.0, network.timers_due_s - now_s)))
            self._handle_frames(frames, on_error)

    def _handle_queued(self, bus: can.BusABC, on_error: Callable[[str], None] | None,
                       limit: int = 256) -> None:
        """Handle the frames already received (at most ``limit`` receives), without
        waiting."""
        for _ in range(limit):
            frames = _receive(bus, 0.0)
            if not frames:
                return
            self._handle_frames(frames, on_error)

    def _handle_frames(self, frames: list[RawFrame],
                       on_error: Callable[[str], None] | None) -> None:
        for frame_id, flags, data in frames:
            error = self.handle_frame(frame_id, data, bool(flags & EXTENDED_FLAG),
                                      bool(flags & FD_FLAG))
            if error is not None and on_error is not None:
                on_error(error)

    def handle_message(self, message: can.Message) -> str | None:
        """Act on one received frame (thread-safe); returns the error text when it raised
        (also kept in :attr:`errors`), else ``None``."""
        return self.handle_frame(message.arbitration_id, bytes(message.data),
                                 message.is_extended_id, message.is_fd)

    def handle_frame(self, frame_id: int, data: bytes, extended: bool = False,
                     fd: bool = False) -> str | None:
        """:meth:`handle_message` of a frame given by its id, data and format."""
        try:
            with self._lock:
                self._handle(frame_id, data, extended, fd)
        except Exception as error:  # keep serving; the test or user sees .errors
            text = f"{type(error).__name__}: {error}"
            self.errors.append(text)
            return text
        return None

    def prepare_ahead(self) -> bool:
        """Prepare the answer to the next SYNC now, if the operator display frame has come
        since the last SYNC and none is prepared (thread-safe; the serving loop calls it when
        no frame is waiting): the SYNC then only sends it. Any input that changes after it
        takes it back. Returns whether an answer is prepared.

        Preparing costs the copies that taking the model's step back needs, so it is done
        only when idle: frames that come together with their SYNC (the ``sim`` backend holds
        the cycle's RPDOs and display frame for the SYNC's datagram) are answered at the
        SYNC without them."""
        try:
            with self._lock:
                if self._answer_wanted and self._prepared is None:
                    self._prepared = self._prepare_sync(undoable=True)
                return self._prepared is not None
        except Exception as error:  # as a frame that raises: kept, and serving goes on
            self._answer_wanted = False  # tried once: the SYNC computes it (and reports)
            self.errors.append(f"{type(error).__name__}: {error}")
            return False

    def poll_timers(self, now_s: float) -> float:
        """Send the drives' heartbeats that are due and trip a drive whose heartbeat consumer
        or life guarding timed out (EMCY 0x8130, then its 0x6007 reaction); returns the time
        to the next heartbeat, s (thread-safe)."""
        with self._lock:
            return self.network.poll(now_s)

    def _connection_lost(self, axis: int, emcy_code: int) -> None:
        """The drive lost its master (heartbeat or RPDO deadline): EMCY, then the abort
        connection reaction of 0x6007 (1 fault, 2 disable voltage, 3 quick stop) when it is
        enabled (under the lock)."""
        self._discard_prepared()
        drive, device = self.drives[axis], self.devices[axis]
        self._send(cia402.EMCY_BASE + drive.node_id, cia402.emcy_frame(emcy_code))
        if drive.state is not DriveState.OPERATION_ENABLED:
            return
        option = device.abort_connection_option
        if option == 1:
            drive.state, drive.error_code = DriveState.FAULT, emcy_code
        elif option == 2:
            drive.state = DriveState.SWITCH_ON_DISABLED
        elif option == 3:
            drive.state = DriveState.QUICK_STOP_ACTIVE
        drive.target_counts = drive.position_counts  # stop where it is

    # --- fault injection (thread-safe; acts at the next SYNC) -------------------------

    def inject_drive_fault(self, axis: int, error_code: int = 0x2310,
                           persistent: bool = False) -> None:
        """The drive of ``axis`` (0 x, 1 y) faults: EMCY ``error_code`` and statusword Fault;
        ``persistent``: the cause stays, so it faults again after every fault reset."""
        with self._lock:
            self.drives[axis].pending_fault_code = error_code
            if persistent:
                self.drives[axis].persistent_fault_code = error_code
            self._discard_prepared()

    def drop_tpdo(self, axis: int, count: int = 1) -> None:
        """The drive of ``axis`` sends no TPDO1 for the next ``count`` SYNCs."""
        with self._lock:
            self.drives[axis].drop_tpdo = count
            self._discard_prepared()

    def drop_sensor_frames(self, count: int = 1) -> None:
        """The sensor sends nothing for the next ``count`` SYNCs."""
        with self._lock:
            self._drop_sensor = count
            self._discard_prepared()

    def set_sensor_status(self, status: int, count: int = 1) -> None:
        """The sensor reports ``status`` (e.g. 2 invalid) for the next ``count`` SYNCs."""
        with self._lock:
            self._sensor_status_override = status
            self._sensor_status_cycles = count
            self._discard_prepared()

    def set_tool_force(self, tool_force_N: np.ndarray) -> None:
        """The tool force (N, x and y) the operator feels from now on."""
        with self._lock:
            self.tool_force_N = np.asarray(tool_force_N, float).reshape(1, 2).copy()
            self._discard_prepared()

    def set_operator_ready(self, enabled: bool) -> None:
        """The master's ready lamp: the operator grasps the handle the first time it is on."""
        with self._lock:
            if enabled and not self.operator_grasped:
                self.operator_grasped = True
                self._discard_prepared()

    # --- frame handling (under the lock) ----------------------------------------------

    def _send(self, frame_id: int, data: bytes) -> None:
        if self._bus is not None:
            self._bus.send(can.Message(arbitration_id=frame_id, data=data, is_extended_id=False))

    def _handle(self, frame_id: int, data: bytes, extended: bool = False,
                fd: bool = False) -> None:
        if extended:  # CANopen is 11-bit: the only 29-bit frame here is the display frame
            if frame_id == OPERATOR_DISPLAY_ID:
                tool_force_N = decode_operator_display(data).reshape(1, 2)
                self._discard_prepared()
                self.tool_force_N = tool_force_N
                self._answer_wanted = True  # prepared when idle (prepare_ahead), or at the SYNC
            elif frame_id == OPERATOR_READY_ID and data[:1] == b"\x01":
                if not self.operator_grasped:
                    self.operator_grasped = True
                    self._discard_prepared()
            return
        if frame_id == cia402.SYNC_COB_ID:
            if fd != self._sync_fd:
                self._discard_prepared()
                self._sync_fd = fd
            refused = check_sync(self.devices, data, self.sync_counter_seen,
                                 self.sync_counter_jumps, self._send)
            if refused:
                self._discard_prepared()
            answer, self._prepared = self._prepared, None
            self._answer_wanted = False
            if answer is None:
                answer = self._prepare_sync(undoable=False, refused=refused)
            else:
                self.prepared_syncs += 1
            self._commit_sync(answer)
            return
        if frame_id == cia402.NMT_COB_ID and len(data) >= 2:
            self._discard_prepared()
            self.network.on_nmt(data[0], data[1])
            return
        for axis, (drive, device) in enumerate(zip(self.drives, self.devices, strict=True)):
            if 0x700 <= frame_id <= 0x77F and frame_id == 0x700 + device.heartbeat_consumer_node:
                self.network.heard(axis)  # changes no input
                continue
            if frame_id == 0x700 + drive.node_id and not data:
                self.network.answer_guarding(axis)  # a node guarding request (a remote frame)
                return
            rpdo = device.rpdos_by_id.get(frame_id)
            if rpdo is not None:
                if drive.nmt_state == NMT_OPERATIONAL_STATE:
                    self._discard_prepared()
                    values = device.decode_rpdo(data, rpdo)
                    if isinstance(values, int):  # a length error: not processed
                        self._send(cia402.EMCY_BASE + drive.node_id,
                                   cia402.emcy_frame(values))
                        continue
                    drive.received_controlword = values.get(0x6040, drive.received_controlword)
                    drive.received_target = values.get(0x607A, drive.received_target)
                    drive.syncs_without_rpdo = 0
                continue
            if frame_id == cia402.SDO_RX_BASE + drive.node_id:
                if drive.nmt_state != NMT_STOPPED_STATE:
                    self._discard_prepared()
                    device.on_sdo_request(data)
                    if device.refresh_if_changed():
                        self.network.timers_due_s = 0.0  # a heartbeat time may have changed
                return
        # Anything else (another node's frames, this bus's own frames coming back) is not ours.

    def _position_counts(self, axis: int, sample: RigSample | None = None) -> int:
        """Encoder counts of ``axis`` in ``sample`` (default: the last SYNC's)."""
        sample = self.last_sample if sample is None else sample
        position = sample.handle_position_m[0, axis] if sample is not None else (
            self.state.plant[0] @ self.model.position_C[axis])
        return self.settings.count_from_metres(position)

    def _prepare_sync(self, undoable: bool, refused: frozenset[int] = frozenset()
                      ) -> SyncAnswer:
        """The devices' answer to the next SYNC: each drive applies the controlword and
        target it latched (:func:`~haptic.master.simulated_rig.sync_answer.apply_latched`),
        the model advances one period with the enabled drives' targets, the drives check
        their following error window, then each operational drive sends its TPDOs as mapped
        and the sensor its frame sampled at this SYNC. Only the model's state changes here
        (``undoable``: keep what :meth:`_discard_prepared` needs to restore it); the rest at
        the commit."""
        drives = [drive.copy() for drive in self.drives]
        frames: list[tuple[int, bytes]] = []
        targets = apply_latched(drives, self.devices, refused, self.settings, frames)
        undo: list[tuple[Any, str, np.ndarray]] = []
        rng_undo = None
        if undoable:
            undo = [(holder, name, getattr(holder, name).copy())
                    for holder, name in self._state_arrays]
            if self.model.force_noise_std_N > 0.0:
                rng_undo = self.state.rng.bit_generator.state
        try:
            return self._step_and_answer(drives, frames, targets, refused, undo, rng_undo)
        except BaseException:
            if undoable:  # the SYNC computes its answer again: from the state before the step
                self._restore(undo, rng_undo)
            raise

    def _step_and_answer(self, drives: list[DriveRuntime], frames: list[tuple[int, bytes]],
                         targets: np.ndarray, refused: frozenset[int],
                         undo: list[tuple[Any, str, np.ndarray]], rng_undo: Any
                         ) -> SyncAnswer:
        """:meth:`_prepare_sync` from the model's step on: the step, the drives' checks and
        their frames, the sensor's."""
        if not self.operator_grasped:
            # the operator waits for the ready lamp: the script's clock has not started
            # (one period before its start: no intent yet, even with onset 0)
            self.state.operator.time_s[0] = -self.model.period_s
            self.state.operator.integral_N_s[0] = 0.0
        # Disabled or faulted drives keep the command they applied (brake, lead screw).
        sample = self.model.step(self.state, targets, self.tool_force_N)
        for axis, (drive, device) in enumerate(zip(drives, self.devices, strict=True)):
            drive.position_counts = self._position_counts(axis, sample)
            if axis in refused:
                continue
            drive.sync_count += 1
            check_following_error(drive, device, frames)
            if drive.nmt_state != NMT_OPERATIONAL_STATE or not device.tpdos or (
                    device.sync_cob_id != cia402.SYNC_COB_ID):
                continue
            if drive.drop_tpdo > 0:
                drive.drop_tpdo -= 1
                continue
            tpdo_frames(drive, device, frames)
        counter = self._sensor_counter
        drop_sensor, status_cycles = self._drop_sensor, self._sensor_status_cycles
        if drop_sensor > 0:
            drop_sensor -= 1
        else:
            raw_x, raw_y, saturated = self.codec.to_counts(sample.handle_force_measured_N[0])
            status = STATUS_OVERLOAD if saturated else STATUS_OK
            if status_cycles > 0 and self._sensor_status_override is not None:
                status = self._sensor_status_override
                status_cycles -= 1
            frames.append((self.codec.frame_id,
                           self.codec.encode_counts(raw_x, raw_y, counter, status)))
        return SyncAnswer(drives, sample, raw_frames(frames, drives, self._sync_fd),
                          (counter + 1) % 256, drop_sensor, status_cycles, undo, rng_undo)

    def _discard_prepared(self) -> None:
        """Take back a prepared answer (an input changed after it): the model's state as it
        was before its step."""
        answer, self._prepared = self._prepared, None
        if answer is not None:
            self._restore(answer.undo, answer.rng_undo)

    def _restore(self, undo: list[tuple[Any, str, np.ndarray]], rng_undo: Any) -> None:
        """The model's state arrays (and its noise generator) as ``undo`` saved them."""
        for holder, name, saved in undo:
            getattr(holder, name)[...] = saved  # in place: the arrays may be bound buffers
        if rng_undo is not None:
            self.state.rng.bit_generator.state = rng_undo

    def _commit_sync(self, answer: SyncAnswer) -> None:
        """Make ``answer`` the devices' state, then send its frames (in that order, so whoever
        has received them sees the devices' new state)."""
        for drive, after in zip(self.drives, answer.drives, strict=True):
            vars(drive).update(vars(after))
        self.last_sample = answer.sample
        self._sensor_counter = answer.sensor_counter
        self._drop_sensor = answer.drop_sensor
        self._sensor_status_cycles = answer.sensor_status_cycles
        self.sync_count += 1
        bus = self._bus
        if bus is not None:  # the answers go out back to back, as one burst where it can
            send_raw_burst(bus, answer.frames)


class SimulatedRigHardware(HandleHardware):
    """The simulated rig in this process (backend ``sim-inproc``): the CAN driver talking to a
    :class:`SimulatedCanRig` that answers from a thread on a virtual bus (the control code
    cannot tell it from the real rig). The devices are reachable as :attr:`rig` for fault
    injection; the tool force goes to the operator directly (no display frame)."""

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

    def summary(self) -> dict[str, Any]:
        return self.driver.summary()

    def cleanup(self) -> None:
        try:
            self.driver.cleanup()
        finally:
            self.rig.stop()

    def sync(self) -> None:
        self.driver.sync()

    def read(self) -> HandleReading:
        return self.driver.read()

    def write(self, position_command_m: np.ndarray) -> None:
        self.driver.write(position_command_m)

    def stop_motion(self, reason: str) -> None:
        self.driver.stop_motion(reason)

    def resume_motion(self) -> None:
        self.driver.resume_motion()

    def present_tool_force(self, tool_force_N: np.ndarray) -> None:
        self.rig.set_tool_force(tool_force_N)

    def present_forces_enabled(self, enabled: bool) -> None:
        self.rig.set_operator_ready(enabled)


def simulated_rig_hardware(config: dict[str, Any]) -> SimulatedRigHardware:
    """The in-process simulated rig for a validated configuration (``[model]``,
    ``[master.can]`` for node ids and conversions, ``[master.sim]``; the virtual bus
    ``[master.sim] channel``)."""
    sim = master_settings(config).sim
    rig = SimulatedCanRig.from_config(config, sim.channel, operator_waits_for_lamp=True)
    driver = CanHandleDriver(rig.settings, {"interface": "virtual", "channel": sim.channel},
                             sim.pdo_timeout_s, config["model"]["sample_period_s"])
    return SimulatedRigHardware(rig, driver)
