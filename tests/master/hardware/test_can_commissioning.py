"""Commissioning the CAN rig from the drives' EDS: the configure sequence by SDO, safe
activation, supervision (heartbeats both ways, RPDO deadline, statusword warnings, quick
stop), the bus-load budget and CAN FD, against the emulated CiA 301/402 drives (canopen
LocalNodes from the packaged EDS) on python-can's virtual bus."""

from __future__ import annotations

import dataclasses
import threading
import time
import uuid
from pathlib import Path

import can
import canopen
import numpy as np
import pytest

from haptic.common.config import load_config, override
from haptic.master.hardware import cia402
from haptic.master.hardware.bus_load import bus_load, classic_frame_bits
from haptic.master.hardware.can_driver import CanHandleDriver
from haptic.master.hardware.canopen_setup import PlanError, interpolation_period
from haptic.master.hardware.cia402 import DriveState
from haptic.master.hardware.drive_device import packaged_eds_path
from haptic.master.hardware.interface import HardwareError, LifecycleState, create_hardware
from haptic.master.settings import master_settings
from haptic.master.simulated_rig.can_devices import (
    NMT_OPERATIONAL_STATE,
    NMT_PRE_OPERATIONAL_STATE,
    SimulatedCanRig,
    SimulatedRigHardware,
)

TS_S = 0.00054


def _config(**overrides):
    config = load_config()
    config = override(config, "master.sim.operator", "constant:fx=0,fy=0")
    config = override(config, "master.sim.channel", f"test-{uuid.uuid4().hex}")
    for key, value in overrides.items():
        config = override(config, key.replace("__", "."), value)
    return config


def _hardware(config) -> SimulatedRigHardware:
    hardware = create_hardware("sim-inproc", config)
    assert isinstance(hardware, SimulatedRigHardware)
    return hardware


def _rig_and_driver(config, rig_settings=None) -> SimulatedRigHardware:
    """The in-process rig, its devices optionally built from other settings (another EDS)."""
    settings = master_settings(config)
    channel = settings.sim.channel
    rig = SimulatedCanRig.from_config(config, channel)
    if rig_settings is not None:
        rig = SimulatedCanRig(rig.model, rig_settings, channel, (0.0, 0.0),
                              np.random.default_rng(0))
    driver = CanHandleDriver(settings.can, {"interface": "virtual", "channel": channel},
                             settings.sim.pdo_timeout_s, TS_S)
    return SimulatedRigHardware(rig, driver)


def test_configure_maps_the_pdos_of_drives_at_their_eds_defaults() -> None:
    with _hardware(_config()) as hardware:
        device = hardware.rig.devices[0]
        assert not device.tpdo.enabled and not device.rpdo.enabled  # EDS defaults
        assert [v.index for v in device.tpdo.mapping] == [0x6041]
        assert device.raw(0x60C2, 1) == 10 and device.raw(0x60C2, 2) == -3
        hardware.configure()
        driver = hardware.driver
        for axis, device in enumerate(hardware.rig.devices):
            node = driver.settings.node_ids[axis]
            assert device.tpdo.enabled and device.rpdo.enabled
            assert device.tpdo.cob_id == 0x180 + node and device.rpdo.cob_id == 0x200 + node
            assert device.tpdo.transmission_type == 1 and device.rpdo.transmission_type == 1
            assert [v.index for v in device.tpdo.mapping] == [0x6041, 0x6064]
            assert [v.index for v in device.rpdo.mapping] == [0x6040, 0x607A]
            assert (device.raw(0x60C2, 1), device.raw(0x60C2, 2)) == (54, -5)  # Ts
            assert device.interpolation_period_s == pytest.approx(TS_S)
            assert device.heartbeat_producer_ms == 100
            assert (device.heartbeat_consumer_node, device.heartbeat_consumer_ms) == (127, 300)
            assert device.rpdo.event_timer_ms == 100
            assert device.following_error_window_counts == 20000
            assert driver.identities[axis]["device_type"] == 0x00020192
            assert driver.identities[axis]["product_code"] == 0x4C02
        assert [d.nmt_state for d in hardware.rig.drives] == [NMT_OPERATIONAL_STATE] * 2
        assert driver.bus_load is not None and driver.bus_load.ok
        hardware.activate()
        for _ in range(20):
            hardware.write(np.array([0.001, -0.001]))
            reading = hardware.read()
            assert reading.ok, reading.faults
        assert driver.late_frames == 0


def test_a_drive_that_aborts_a_mapping_is_refused_reported_and_left_pre_operational(
        tmp_path: Path) -> None:
    # The x drive's own EDS does not let 0x607A be mapped; the master's copy says it can.
    eds = packaged_eds_path().read_text().replace(
        "[607A]\nParameterName=Target position\nObjectType=0x7\nDataType=0x0004\n"
        "AccessType=rw\nDefaultValue=0\nPDOMapping=1",
        "[607A]\nParameterName=Target position\nObjectType=0x7\nDataType=0x0004\n"
        "AccessType=rw\nDefaultValue=0\nPDOMapping=0")
    assert "PDOMapping=0" in eds
    drive_eds = tmp_path / "drive.eds"
    drive_eds.write_text(eds)
    config = _config()
    rig_settings = dataclasses.replace(master_settings(config).can, x_eds_file=str(drive_eds))
    hardware = _rig_and_driver(config, rig_settings)
    start = hardware.rig.last_sample
    with pytest.raises(HardwareError) as error:
        hardware.configure()
    message = str(error.value)
    assert "x drive (node 1)" in message and "0x1600:00" in message
    assert "0x06040041" in message
    assert hardware.lifecycle_state is LifecycleState.UNCONFIGURED
    assert [d.nmt_state for d in hardware.rig.drives] == [NMT_PRE_OPERATIONAL_STATE] * 2
    assert hardware.rig.last_sample is start  # no SYNC: nothing moved


def test_an_eds_without_an_object_the_loop_needs_is_refused_before_the_bus(
        tmp_path: Path) -> None:
    eds = packaged_eds_path().read_text().replace("[6064]", "[6069]")
    path = tmp_path / "no6064.eds"
    path.write_text(eds)
    config = _config(master__can__y_eds_file=str(path))
    settings = master_settings(config)
    driver = CanHandleDriver(settings.can, {"interface": "virtual", "channel": "unused"},
                             0.05, TS_S)
    with pytest.raises(PlanError, match=r"y drive's EDS .* has no object 0x6064:00: the "
                       r"cyclic synchronous position loop cannot run without it$"):
        driver.configure()
    assert driver.lifecycle_state is LifecycleState.UNCONFIGURED


def test_interpolation_period_is_exact() -> None:
    assert interpolation_period(0.00054) == (54, -5)
    assert interpolation_period(0.001) == (1, -3)
    assert interpolation_period(0.01) == (1, -2)
    with pytest.raises(PlanError):
        interpolation_period(0.000123456789)


def test_a_half_configured_drive_never_moves_target_equals_actual_before_enable() -> None:
    config = _config(master__sim__initial_position_m=[0.012, -0.034])
    with _hardware(config) as hardware:
        hardware.configure()
        rig, driver = hardware.rig, hardware.driver
        far = int(rig.settings.counts_from_metres(0.05))
        for drive in rig.drives:  # a stale target from an earlier run
            drive.target_counts = far
        hardware.activate()
        assert driver.drive_states == (DriveState.OPERATION_ENABLED,) * 2
        for drive in rig.drives:
            assert abs(drive.target_counts - drive.position_counts) <= 1
        for _ in range(40):
            reading = hardware.read()
            assert reading.ok, reading.faults
        np.testing.assert_allclose(reading.position_m, [0.012, -0.034], atol=2e-6)


def test_activation_stops_on_a_fault_that_comes_back_with_the_emcy_code() -> None:
    with _hardware(_config()) as hardware:
        hardware.configure()
        hardware.rig.inject_drive_fault(0, 0x7305, persistent=True)
        with pytest.raises(HardwareError) as error:
            hardware.activate()
        assert "x 0x7305" in str(error.value)
        assert hardware.lifecycle_state is LifecycleState.INACTIVE
        # one fault reset at most, not a loop: at most two EMCYs from the x drive
        assert 1 <= sum(code == 0x7305 for _, code in hardware.driver.emcy_log) <= 2
        assert hardware.rig.drives[0].state is not DriveState.OPERATION_ENABLED


def test_a_drive_faulted_once_is_reset_once_and_enabled() -> None:
    with _hardware(_config()) as hardware:
        hardware.configure()
        hardware.rig.inject_drive_fault(1, 0x2310)
        hardware.read()
        assert hardware.driver.drive_states[1] is DriveState.FAULT
        hardware.activate()
        assert hardware.driver.drive_states == (DriveState.OPERATION_ENABLED,) * 2


def _active(config) -> SimulatedRigHardware:
    hardware = _hardware(config)
    hardware.configure()
    hardware.activate()
    return hardware


def test_a_stalled_master_stops_the_drives_by_their_heartbeat_consumer() -> None:
    hardware = _active(_config())
    try:
        rig = hardware.rig
        hardware.write(np.array([0.0, 0.0]))
        hardware.read()
        time.sleep(0.6)  # the master stalls: no heartbeat, no SYNC (timeout 0.3 s)
        assert [d.state for d in rig.drives] == [DriveState.FAULT] * 2
        assert [d.error_code for d in rig.drives] == [0x8130] * 2
        reading = hardware.read()
        text = "; ".join(reading.faults)
        assert "EMCY error code 0x8130" in text and "quick stop" in text
        before = reading.position_m.copy()
        for _ in range(30):  # a master that resumes cannot move a stopped drive
            hardware.write(before + 0.005)
            reading = hardware.read()
        np.testing.assert_allclose(reading.position_m, before, atol=2e-6)
    finally:
        hardware.cleanup()


def test_a_master_waiting_for_stalled_drives_keeps_its_heartbeat() -> None:
    """The simulated drives share a busy machine and stall 0.45 s (their thread cannot take
    a frame): the master's read waits for their PDOs (the sim's pdo_timeout_s is 0.5 s,
    longer than their heartbeat consumer time, 0.3 s), and its heartbeat goes on while it
    waits, so the drives, running again, do not take it for a lost master (no EMCY
    0x8130)."""
    hardware = _active(_config())
    try:
        rig = hardware.rig
        hardware.write(np.array([0.0, 0.0]))
        hardware.read()
        stalled = threading.Event()

        def stall() -> None:
            with rig._lock:  # noqa: SLF001 - the drives' thread waits on it: a stall
                stalled.set()
                time.sleep(0.45)

        staller = threading.Thread(target=stall)
        staller.start()
        stalled.wait(5.0)
        reading = hardware.read()  # waits for the PDOs until the drives run again
        staller.join(5.0)
        assert not any("0x8130" in fault for fault in reading.faults)
        for _ in range(400):  # 0.2 s of cycles after the stall
            hardware.write(np.array([0.0, 0.0]))
            reading = hardware.read()
            assert not any("0x8130" in fault for fault in reading.faults)
        assert [d.error_code for d in rig.drives] == [0, 0]
    finally:
        hardware.cleanup()


def test_a_master_waiting_configured_keeps_its_heartbeat_and_activates_cleanly() -> None:
    """Configured and waiting (for the slave, say) longer than the drives' heartbeat
    consumer time: the master's heartbeat goes on from a periodic task, the disabled drives
    do not fault, and the enable sequence sees no EMCY; once active, the loop sends it."""
    hardware = _hardware(_config())
    try:
        hardware.configure()
        time.sleep(0.7)  # > heartbeat_timeout_s = 0.3 s without a read()
        assert [d.error_code for d in hardware.rig.drives] == [0, 0]
        hardware.activate()
        assert hardware.driver.lifecycle_state is LifecycleState.ACTIVE
        assert hardware.driver.heartbeats.idle_task is None
        hardware.deactivate()
        assert hardware.driver.heartbeats.idle_task is not None
    finally:
        hardware.cleanup()
    assert hardware.driver.heartbeats.idle_task is None


def test_a_silent_drive_is_reported_by_the_masters_heartbeat_consumer_and_stopped() -> None:
    hardware = _active(_config())
    try:
        driver, rig = hardware.driver, hardware.rig
        driver.sdo.write(1, rig.devices[0].dictionary[0x1017], 0, "x drive")  # x goes quiet
        deadline = time.monotonic() + 2.0
        faults: list[str] = []
        while time.monotonic() < deadline:
            hardware.write(np.zeros(2))
            faults += hardware.read().faults
            if any("no heartbeat from the x drive" in f for f in faults):
                break
            time.sleep(0.01)
        assert any("no heartbeat from the x drive" in f for f in faults), faults
        assert any("quick stop" in f for f in faults)
        hardware.read()
        assert all(d.state in (DriveState.QUICK_STOP_ACTIVE, DriveState.SWITCH_ON_DISABLED)
                   for d in rig.drives)
        assert not any("no heartbeat from the y drive" in f for f in faults)
    finally:
        hardware.cleanup()


def test_the_rpdo_deadline_stops_a_drive_that_gets_syncs_but_no_targets() -> None:
    with _active(_config()) as hardware:
        faults: list[str] = []
        for _ in range(260):  # 0.1 s of SYNC time is 185 SYNCs at Ts = 540 us
            faults += hardware.read().faults
        assert any("0x8250" in f for f in faults), faults
        assert hardware.rig.drives[0].error_code == 0x8250


def test_statusword_warning_bits_become_events_and_a_following_error_trips() -> None:
    with _active(_config()) as hardware:
        rig = hardware.rig
        events: list[str] = []
        faults: list[str] = []
        start = hardware.read().position_m
        for _ in range(60):  # a step beyond the 10 mm following error window
            hardware.write(start + np.array([0.3, 0.0]))
            reading = hardware.read()
            events += reading.events
            faults += reading.faults
        assert "x drive statusword: warning (bit 7) on" in events
        assert "x drive statusword: following error (bit 13) on" in events
        assert not any(e.startswith("y drive") and "bit 13" in e for e in events)
        assert any("0x8611" in f for f in faults)
        assert rig.drives[0].error_code == 0x8611
        assert events.count("x drive statusword: warning (bit 7) on") == 1  # once per change


def test_sdo_replies_are_matched_to_their_object_and_emcys_meanwhile_are_kept() -> None:
    with _hardware(_config()) as hardware:
        hardware.configure()
        driver = hardware.driver
        channel = driver.bus_options["channel"]
        with can.Bus(interface="virtual", channel=channel) as other:
            # a stale reply for another object, then an EMCY, before the real reply
            other.send(can.Message(arbitration_id=0x581, is_extended_id=False,
                                   data=cia402.sdo_upload_response(cia402.STATUSWORD, 0xFFFF)))
            other.send(can.Message(arbitration_id=0x081, is_extended_id=False,
                                   data=cia402.emcy_frame(0x5530)))
            dictionary = hardware.rig.devices[0].dictionary
            assert driver.sdo.read(1, dictionary[0x1018][2], "x drive") == 0x4C02
        reading = hardware.read()
        assert any("0x5530" in f for f in reading.faults)
        assert ("x", 0x5530) in driver.emcy_log
        assert driver.late_frames == 0


def test_heartbeats_are_not_late_frames() -> None:
    with _active(_config()) as hardware:
        end = time.monotonic() + 0.35  # at least three heartbeats of each drive
        while time.monotonic() < end:
            hardware.write(np.zeros(2))
            assert hardware.read().ok
            time.sleep(0.002)
        assert hardware.driver.late_frames == 0


def test_the_bus_load_budget_refuses_classical_can_at_the_papers_rate() -> None:
    assert [classic_frame_bits(n) for n in (0, 6, 8)] == [55, 115, 135]
    classic = bus_load(TS_S, 1_000_000, False, 5_000_000, 0.7)
    assert classic.cycle_s == pytest.approx(650e-6)  # SYNC, 4 x 6 bytes, 8 bytes
    assert not classic.ok
    config = _config(master__can__fd=False)
    settings = master_settings(config)
    driver = CanHandleDriver(settings.can, {"interface": "virtual", "channel": "unused"},
                             0.05, TS_S)
    with pytest.raises(HardwareError) as error:
        driver.configure()
    message = str(error.value)
    # the SYNC counter's byte (0x1019) is in the budget: 650 + 10 bit-times
    for option in ("bus load 122% of Ts", "SYNC 65.0 us", "longer Ts", "sensor on its own bus",
                   "CAN FD"):
        assert option in message
    assert driver.frames.bus is None
    slow = CanHandleDriver(settings.can, {"interface": "virtual", "channel": "unused"},
                           0.05, 0.001)
    assert slow.check_bus_load().ok  # 661 us of 1 ms: 66 %
    assert bus_load(TS_S, 1_000_000, True, 5_000_000, 0.7).ok


@pytest.mark.parametrize("fd", [True, False])
def test_the_loop_runs_on_can_fd_and_on_classical_can(fd: bool) -> None:
    overrides = {} if fd else {"model__sample_period_s": 0.001}
    config = _config(master__can__fd=fd, **overrides)
    with _hardware(config) as hardware:
        settings = master_settings(config)
        hardware.driver.sample_period_s = config["model"]["sample_period_s"]
        seen: list[can.Message] = []
        with can.Bus(interface="virtual", channel=settings.sim.channel) as listener:
            hardware.configure()
            hardware.activate()
            for _ in range(10):
                hardware.write(np.array([0.0005, 0.0]))
                assert hardware.read().ok
            while (message := listener.recv(timeout=0.0)) is not None:
                seen.append(message)
        cyclic = {0x080, 0x181, 0x182, 0x201, 0x202, 0x190}
        frames = [m for m in seen if m.arbitration_id in cyclic and not m.is_extended_id]
        assert {m.arbitration_id for m in frames} == cyclic
        assert all(m.is_fd is fd and m.bitrate_switch is fd for m in frames)
        sdo = [m for m in seen if 0x580 < m.arbitration_id < 0x680]
        assert sdo and not any(m.is_fd for m in sdo)  # SDO stays classical


def test_canopens_own_remote_node_reads_the_emulated_drives_identity_and_mappings() -> None:
    config = _config()
    rig = SimulatedCanRig.from_config(config, master_settings(config).sim.channel)
    rig.start()
    network = canopen.Network()
    try:
        network.connect(interface="virtual", channel=rig.channel)
        node = canopen.BaseNode402(1, str(packaged_eds_path()))
        network.add_node(node)
        assert node.sdo[0x1000].raw == 0x00020192
        assert node.sdo[0x1001].raw == 0
        assert node.sdo[0x1018][2].raw == 0x4C02
        assert node.sdo[0x1008].raw == "haptic-teleop CiA 402 drive"  # segmented upload
        node.tpdo.read()
        node.rpdo.read()
        assert [v.index for v in node.tpdo[1].map] == [0x6041]
        assert not node.tpdo[1].enabled
        # Map TPDO1 the way canopen does it, then read it back with a fresh node.
        node.tpdo[1].clear()
        node.tpdo[1].add_variable(0x6041)
        node.tpdo[1].add_variable(0x6064)
        node.tpdo[1].trans_type = 1
        node.tpdo[1].enabled = True
        node.tpdo[1].save()
        with pytest.raises(canopen.SdoAbortedError) as error:  # read-only
            node.sdo[0x1018][1].raw = 5
        assert error.value.code == 0x06010002
        fresh = canopen.RemoteNode(1, str(packaged_eds_path()))
        network.add_node(fresh)
        fresh.tpdo.read()
        assert [v.index for v in fresh.tpdo[1].map] == [0x6041, 0x6064]
        assert fresh.tpdo[1].enabled and fresh.tpdo[1].trans_type == 1
    finally:
        network.disconnect()
        rig.stop()


def test_a_node_reset_restores_the_eds_defaults() -> None:
    with _hardware(_config()) as hardware:
        hardware.configure()
        rig = hardware.rig
        assert rig.devices[0].tpdo.enabled
        rig.handle_message(can.Message(arbitration_id=0, is_extended_id=False,
                                       data=bytes([cia402.NMT_RESET_COMMUNICATION, 1])))
        assert not rig.devices[0].tpdo.enabled and rig.devices[1].tpdo.enabled
        assert rig.drives[0].nmt_state == NMT_PRE_OPERATIONAL_STATE


class _Replies:
    """Collects what a drive sends (its SDO replies)."""

    def __init__(self) -> None:
        self.frames: list[tuple[int, bytes]] = []

    def __call__(self, frame_id: int, data: bytes) -> None:
        self.frames.append((frame_id, data))


def _write(device, replies: _Replies, index: int, subindex: int, value: int) -> int | None:
    """SDO download to ``device``; the abort code, or None when accepted."""
    variable = device._variable(index, subindex)
    device.on_sdo_request(cia402.sdo_download_request(variable, value))
    reply = cia402.decode_sdo(replies.frames[-1][1])
    assert (reply.index, reply.subindex) == (index, subindex)
    device.refresh_if_changed()
    return int.from_bytes(reply.data, "little") if reply.command == 0x80 else None


def test_the_emulated_drive_enforces_the_cia301_pdo_rules() -> None:
    from haptic.master.hardware.drive_device import DriveObjects, DriveRuntime

    replies = _Replies()
    device = DriveObjects(3, None, replies, DriveRuntime(3), lambda: 0)
    assert device.rpdo.cob_id == 0x203 and not device.rpdo.enabled  # $NODEID resolved
    assert _write(device, replies, 0x1400, 1, 0x203) is None  # enable with the default map
    assert _write(device, replies, 0x1600, 0, 0) == 0x06010000  # mapping a valid PDO
    assert _write(device, replies, 0x1400, 1, 0x80000203) is None
    assert _write(device, replies, 0x1600, 1, 0x607A0020) == 0x06010000  # count not 0
    assert _write(device, replies, 0x1600, 0, 0) is None
    assert _write(device, replies, 0x1600, 1, 0x60410010) is None  # statusword: read-only
    assert _write(device, replies, 0x1600, 0, 1) == 0x06040041
    assert _write(device, replies, 0x1600, 1, 0x12340020) is None  # no such object
    assert _write(device, replies, 0x1600, 0, 1) == 0x06040041
    assert _write(device, replies, 0x1600, 1, 0x607A0010) is None  # wrong length
    assert _write(device, replies, 0x1600, 0, 1) == 0x06040041
    assert _write(device, replies, 0x1600, 1, 0x607A0020) is None
    assert _write(device, replies, 0x1600, 0, 1) is None
    assert _write(device, replies, 0x1400, 2, 250) == 0x06090030  # reserved type
    assert _write(device, replies, 0x1400, 1, 0xA0000203) == 0x06090030  # 29-bit id
    assert _write(device, replies, 0x6060, 0, 3) == 0x06090030  # profile velocity: no
    assert _write(device, replies, 0x1018, 1, 5) == 0x06010002  # read-only
    assert _write(device, replies, 0x1400, 1, 0x203) is None
    assert device.rpdo.enabled and [v.index for v in device.rpdo.mapping] == [0x607A]
    assert device.decode_rpdo(bytes(4)) == {0x607A: 0}
    assert device.decode_rpdo(bytes(6)) == 0x8220  # too long: EMCY, not applied
    assert device.decode_rpdo(bytes(2)) == 0x8210


def test_commissioning_keys_are_checked_at_start() -> None:
    from haptic.common.config import ConfigError

    with pytest.raises(ConfigError, match="master.can.master_node_id"):
        master_settings(_config(master__can__master_node_id=1))
    with pytest.raises(ConfigError, match="master.can.heartbeat_timeout_s"):
        master_settings(_config(master__can__heartbeat_timeout_s=0.05))
    with pytest.raises(ConfigError, match="master.can.bus_load_limit"):
        _config(master__can__bus_load_limit=1.5)


def test_the_sync_counter_is_configured_from_the_eds_and_followed_by_the_drives() -> None:
    with _active(_config()) as hardware:
        rig, driver = hardware.rig, hardware.driver
        assert driver.sync_counter_overflow == 240
        assert [device.raw(0x1019) for device in rig.devices] == [240, 240]
        start = hardware.read().position_m
        for _ in range(300):  # across the wrap from 240 to 1
            hardware.write(start)
            reading = hardware.read()
            assert not reading.faults, reading.faults
        assert rig.sync_counter_seen == [driver.pdos.sync_counter] * 2
        assert rig.sync_counter_jumps == [0, 0]
        driver.pdos.sync_counter += 1  # one SYNC lost on the bus: the drives see the jump
        hardware.read()
        assert rig.sync_counter_jumps == [1, 1]


def test_a_drive_without_0x1019_turns_the_sync_counter_off_for_the_bus(tmp_path: Path) -> None:
    eds = packaged_eds_path().read_text()
    path = tmp_path / "no1019.eds"  # canopen reads the object sections, not the lists
    path.write_text(eds.replace(eds[eds.index("[1019]"):eds.index("[1400]")], ""))
    config = _config(master__can__y_eds_file=str(path))
    settings = master_settings(config)
    hardware = _rig_and_driver(config, settings.can)
    try:
        hardware.configure()
        driver = hardware.driver
        assert driver.sync_counter_overflow == 0
        assert "SYNC counter off" in driver.sync_counter_note and "y drive" in \
            driver.sync_counter_note
        assert [device.sync_counter_overflow for device in hardware.rig.devices] == [0, 0]
        hardware.activate()
        for _ in range(20):
            reading = hardware.read()
            assert not reading.faults, reading.faults  # SYNCs without data: no EMCY 0x8240
    finally:
        hardware.cleanup()


def test_a_sync_of_the_wrong_length_is_refused_by_the_drive_and_reported() -> None:
    with _active(_config()) as hardware:
        rig = hardware.rig
        hardware.read()
        device = rig.devices[1]  # its 0x1019 changed behind the master's back
        device.node.set_data(0x1019, 0, bytes([0]), check_writable=False)
        device.refresh()
        before = rig.drives[1].sync_count
        reading = hardware.read()
        text = "; ".join(reading.faults)
        assert "y drive EMCY error code 0x8240" in text and "0x1019" in text, text
        assert "missing TPDO1 from the y drive" in text
        assert rig.drives[1].sync_count == before  # the drive did not act on that SYNC


@pytest.mark.parametrize("option", [2, 6])
def test_the_masters_own_trip_quick_stops_the_drives_and_resume_reenables_at_actual(
        option: int) -> None:
    """stop_motion (the master's watchdog or safety trip): controlword quick stop, each drive
    through Quick stop active (option 2: then Switch on disabled; 6: it stays there), events
    and no fault; commands meanwhile move nothing. resume_motion: the enable sequence from
    there, the targets at the actual positions (no jump), then the drives follow again."""
    with _hardware(_config()) as hardware:
        rig = hardware.rig
        for device in rig.devices:  # the drives' quick stop option code (0x605A)
            device.node.set_data(0x605A, 0, option.to_bytes(2, "little", signed=True),
                                 check_writable=False)
            device.refresh()
        hardware.configure()
        hardware.activate()
        start = hardware.read().position_m
        for _ in range(20):  # move a little first
            hardware.write(start + np.array([0.002, -0.001]))
            hardware.read()
        hardware.stop_motion("watchdog tripped")
        events: list[str] = []
        states = set()
        positions = []
        for _ in range(40):
            hardware.write(start + np.array([0.01, 0.01]))  # ignored: the drives are stopped
            reading = hardware.read()
            assert not reading.faults, reading.faults
            events += reading.events
            states.add(tuple(hardware.driver.drive_states))
            positions.append(reading.position_m.copy())
        held = positions[-1]
        assert "quick stop on both drives: watchdog tripped" in events
        assert (DriveState.QUICK_STOP_ACTIVE,) * 2 in states
        final = DriveState.SWITCH_ON_DISABLED if option == 2 else DriveState.QUICK_STOP_ACTIVE
        assert hardware.driver.drive_states == (final, final)
        assert "x drive took the quick stop (quick stop active)" in events
        # stopped (on the drives' own ramp), nowhere near the ignored 10 mm command
        assert np.ptp(np.array(positions[-10:]), axis=0).max() < 2e-5
        assert np.abs(held - start).max() < 0.003
        hardware.resume_motion()
        assert hardware.driver.drive_states == (DriveState.OPERATION_ENABLED,) * 2
        resumed = hardware.read()
        assert "drives re-enabled at their actual positions after the quick stop" in \
            resumed.events
        assert not resumed.faults, resumed.faults
        per_count = hardware.driver.settings.metres_per_count  # target = actual (+ringing)
        for drive in rig.drives:
            assert abs(drive.target_counts - drive.position_counts) * per_count < 2e-5
        np.testing.assert_allclose(resumed.position_m, held, atol=2e-5)  # no jump
        for _ in range(40):  # and the drives follow commands again
            hardware.write(held + np.array([0.001, 0.0]))
            reading = hardware.read()
        assert not reading.faults, reading.faults
        assert 0.0002 < reading.position_m[0] - held[0] < 0.0011  # towards the 1 mm command


def test_a_drive_that_does_not_take_the_quick_stop_is_a_fault() -> None:
    with _active(_config()) as hardware:
        rig = hardware.rig
        hardware.read()
        with rig._lock:
            rig.drives[0].mode = 1  # profile position: the CSP state machine ignores it
        hardware.stop_motion("node trip")
        faults: list[str] = []
        for _ in range(hardware.driver.settings.enable_timeout_cycles + 3):
            faults += hardware.read().faults
        assert any("x drive did not take the quick stop" in f for f in faults), faults
        assert not any(f.startswith("y drive") for f in faults)
