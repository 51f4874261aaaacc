"""What the CAN driver's unit tests share: the in-process emulated rig configured or
active, the frames a listener heard, a second bus member's frames and the emulated drives'
objects set by hand."""

from __future__ import annotations

import uuid

import can
import numpy as np

from haptic.common.config import load_config, override
from haptic.master.hardware import cia402
from haptic.master.hardware.can_driver import CanHandleDriver
from haptic.master.hardware.cia402 import DriveState
from haptic.master.hardware.interface import create_hardware
from haptic.master.settings import master_settings
from haptic.master.simulated_rig.can_devices import SimulatedRigHardware

HEARTBEAT_BASE = 0x700  # CiA 301's NMT error control COB-ID base, not the driver's constant


def active_rig(**overrides) -> SimulatedRigHardware:
    """:func:`inactive_rig`'s rig, its operator's hand still, configured and active."""
    hardware = inactive_rig(**{"master.sim.operator": "constant:fx=0,fy=0", **overrides})
    hardware.configure()
    hardware.activate()
    return hardware


def faults_after(hardware: SimulatedRigHardware, frames: list[tuple[int, bytes]]
                  ) -> tuple[str, ...]:
    """The next reading's faults after another bus member sent ``frames`` (id, data)."""
    channel = hardware.driver.bus_options["channel"]
    with can.Bus(interface="virtual", channel=channel) as other:
        for frame_id, data in frames:
            other.send(can.Message(arbitration_id=frame_id, data=data, is_extended_id=False))
    return hardware.read().faults


def inactive_rig(**overrides) -> SimulatedRigHardware:
    """The in-process emulated rig on a channel of its own, ``overrides`` (dotted key ->
    value) applied, not configured yet."""
    config = override(load_config(), "master.sim.channel", f"test-{uuid.uuid4().hex}")
    config = override(config, "master.can.heartbeat_timeout_s", 5.0)  # unpaced steps
    for key, value in overrides.items():
        config = override(config, key, value)
    hardware = create_hardware("sim-inproc", config)
    assert isinstance(hardware, SimulatedRigHardware)
    return hardware


def frames_heard(listener: can.BusABC) -> list[can.Message]:
    """Every frame ``listener`` has heard so far."""
    heard = []
    while (message := listener.recv(timeout=0.0)) is not None:
        heard.append(message)
    return heard


def bare_driver() -> tuple[CanHandleDriver, str]:
    """A driver with its bus open on a virtual channel of its own, no devices on it."""
    settings = master_settings(load_config())
    channel = f"test-{uuid.uuid4().hex}"
    driver = CanHandleDriver(settings.can, {"interface": "virtual", "channel": channel},
                             0.01, 0.00054)
    driver.frames.bus = can.Bus(interface="virtual", channel=channel)
    return driver, channel


def set_object(device, index: int, subindex: int, value: int) -> None:
    """Store ``value`` in an emulated drive's object as if it were its own (a read-only one
    too)."""
    device.node.set_data(index, subindex, device._variable(index, subindex).encode_raw(value))


def answering(device, index: int, value: int) -> None:
    """The emulated drive answers reads of ``index`` with ``value`` from now on."""
    read_index = index

    def answer(index: int, subindex: int, od) -> int | None:  # canopen's keywords
        return value if index == read_index else None

    device.node._read_callbacks.insert(0, answer)


def sdo_downloads(heard: list[can.Message], index: int) -> list[tuple[int, int]]:
    """(node, value) of each expedited SDO download of ``index`` among ``heard``."""
    found = []
    for message in heard:
        node = message.arbitration_id - cia402.SDO_RX_BASE
        if 1 <= node <= 127 and len(message.data) == 8 and message.data[0] & 0xE0 == 0x20 and (
                int.from_bytes(message.data[1:3], "little") == index):
            found.append((node, int.from_bytes(message.data[4:8], "little", signed=True)))
    return found


def rpdo_controlwords(heard: list[can.Message], node: int) -> list[int]:
    return [int.from_bytes(m.data[0:2], "little") for m in heard
            if m.arbitration_id == cia402.RPDO1_BASE + node]


def read_with_tpdo(hardware: SimulatedRigHardware, axis: int, payload: bytes):
    """A reading whose ``axis`` TPDO1 is ``payload`` from another bus member (the drive's
    own dropped for that SYNC)."""
    return read_with_tpdo_id(hardware, axis, cia402.TPDO1_BASE + axis + 1, payload)


def read_with_tpdo_id(hardware: SimulatedRigHardware, axis: int, frame_id: int,
                       payload: bytes):
    """A reading for which the ``axis`` drive's TPDO1 is dropped and another bus member sends
    ``payload`` on ``frame_id`` after the SYNC."""
    hardware.rig.drop_tpdo(axis, 1)
    hardware.driver.sync()
    channel = hardware.driver.bus_options["channel"]
    with can.Bus(interface="virtual", channel=channel) as other:
        other.send(can.Message(arbitration_id=frame_id, data=payload, is_extended_id=False))
    return hardware.read()


def set_drive_state(hardware: SimulatedRigHardware, axis: int, state: DriveState) -> None:
    """The emulated drive goes to ``state`` by itself (no EMCY)."""
    with hardware.rig._lock:
        hardware.rig.drives[axis].state = state
        hardware.rig._discard_prepared()


def plans_of(**overrides) -> CanHandleDriver:
    """A driver whose plans were made (the EDS read, no bus) under ``overrides``."""
    config = load_config()
    for key, value in overrides.items():
        config = override(config, key, value)
    driver = CanHandleDriver(master_settings(config).can,
                             {"interface": "virtual", "channel": "unused"}, 0.01, 0.00054)
    driver._plans()
    return driver


def moves_towards_an_offset(hardware, cycles: int) -> None:
    """Activate, ``cycles`` cycles commanding a small offset with every reading ok and the
    drives moving the handle towards it, deactivate; no rig error, no late frame."""
    hardware.activate()
    start = hardware.read().position_m
    for _ in range(cycles):
        hardware.write(np.array([0.0005, -0.0005]))
        reading = hardware.read()
        assert reading.ok, reading.faults
    moved = reading.position_m - start
    assert moved[0] > 2e-5 and moved[1] < -2e-5, moved
    hardware.deactivate()
    assert hardware.rig.errors == [] and hardware.driver.late_frames == 0
