"""The CAN driver's supervision messages and frame checks at unit level, fast: the exact
fault text for each EMCY, heartbeat and sensor frame a drive or a stranger on the bus may
send, the SDO abort texts, and the SYNC counter's wrap, against the in-process emulated rig
(python-can's virtual bus) with the frames of a second bus member where the rig cannot
produce them."""

from __future__ import annotations

import dataclasses
import importlib.resources
import math
import re
import struct
import time
import uuid

import can
import numpy as np
import pytest

from haptic.common.config import load_config, override
from haptic.master.hardware import can_driver, cia402
from haptic.master.hardware.bus_load import bus_load, cycle_frames
from haptic.master.hardware.can_driver import CanHandleDriver, _abort_text
from haptic.master.hardware.cia402 import DriveState
from haptic.master.hardware.drive_device import packaged_eds_path
from haptic.master.hardware.force_sensor import ForceSensorCodec, load_database
from haptic.master.hardware.interface import HardwareError, LifecycleState, create_hardware
from haptic.master.settings import master_settings
from haptic.master.sim.sim_rig import NMT_PRE_OPERATIONAL_STATE, SimulatedRigHardware

HEARTBEAT_BASE = 0x700  # CiA 301's NMT error control COB-ID base, not the driver's constant


def _active(**overrides) -> SimulatedRigHardware:
    """:func:`_inactive`'s rig, its operator's hand still, configured and active."""
    hardware = _inactive(**{"master.sim.operator": "constant:fx=0,fy=0", **overrides})
    hardware.configure()
    hardware.activate()
    return hardware


def _faults_after(hardware: SimulatedRigHardware, frames: list[tuple[int, bytes]]
                  ) -> tuple[str, ...]:
    """The next reading's faults after another bus member sent ``frames`` (id, data)."""
    channel = hardware.driver.bus_options["channel"]
    with can.Bus(interface="virtual", channel=channel) as other:
        for frame_id, data in frames:
            other.send(can.Message(arbitration_id=frame_id, data=data, is_extended_id=False))
    return hardware.read().faults


def test_an_emcy_names_its_axis_code_register_and_known_meaning() -> None:
    """``<axis> drive EMCY error code 0xCODE (register 0xRR; meaning)``, the meaning only for
    the codes the loop knows; the drives are quick-stopped and the EMCY logged."""
    with _active() as hardware:
        hardware.read()
        faults = _faults_after(hardware, [(cia402.EMCY_BASE + 2, cia402.emcy_frame(0x8611, 0x81)),
                                          (cia402.EMCY_BASE + 1, cia402.emcy_frame(0x5530))])
        assert "y drive EMCY error code 0x8611 (register 0x81; following error)" in faults
        assert "x drive EMCY error code 0x5530 (register 0x01)" in faults
        assert "quick stop on both drives: a drive fault" in faults
        assert hardware.driver.emcy_log[-2:] == [("y", 0x8611), ("x", 0x5530)]


def test_an_emcy_error_reset_is_no_fault_and_a_short_one_is_malformed() -> None:
    """Code 0 (error reset) is neither a fault nor logged; an EMCY under 3 bytes is a
    malformed-frame fault of its axis."""
    with _active() as hardware:
        hardware.read()
        faults = _faults_after(hardware, [(cia402.EMCY_BASE + 1, cia402.emcy_frame(0))])
        assert faults == () and hardware.driver.emcy_log == []
        faults = _faults_after(hardware, [(cia402.EMCY_BASE + 2, b"\x11\x22")])
        assert any(f.startswith("y drive EMCY malformed: ") for f in faults), faults
        assert hardware.driver.emcy_log == []


@pytest.mark.parametrize(("payload", "named"), [
    (b"\x7f", "pre-operational"), (b"\x04", "stopped"), (b"\x00", "boot-up"),
    (b"\x42", "0x42"), (b"", "-0x1")])
def test_a_heartbeat_in_another_nmt_state_is_a_fault_naming_it(payload, named) -> None:
    """A drive's heartbeat reporting anything but operational (0x05) is a fault naming the
    state (an unknown state in hex, an empty payload as -0x1)."""
    with _active() as hardware:
        hardware.read()
        faults = _faults_after(hardware, [(HEARTBEAT_BASE + 1, payload)])
        assert f"x drive heartbeat reports NMT state {named}, not operational" in faults


def test_an_operational_heartbeat_from_a_stranger_is_no_fault() -> None:
    """An operational heartbeat is the healthy case, whoever sends it."""
    with _active() as hardware:
        hardware.read()
        assert _faults_after(hardware, [(HEARTBEAT_BASE + 2, b"\x05")]) == ()


def test_a_lost_sensor_frame_then_its_counter_jump_are_reported() -> None:
    """A missing sensor frame is a fault of its cycle; the next frame's counter, two ahead,
    is a jump ``from N to N+2``."""
    with _active() as hardware:
        hardware.read()
        hardware.rig.drop_sensor_frames(1)
        missed = hardware.read()
        assert "missing force sensor frame" in missed.faults
        assert np.isnan(missed.force_N).all()
        jumped = hardware.read()
        found = [re.fullmatch(r"force sensor counter jumped from (\d+) to (\d+) \(a stale or "
                              r"lost sample\)", f) for f in jumped.faults]
        numbers = [tuple(int(g) for g in m.groups()) for m in found if m]
        assert len(numbers) == 1 and (numbers[0][0] + 2) % 256 == numbers[0][1], jumped.faults


#: CiA 301's SDO abort codes the driver names, with their meanings (CiA 301, table 22).
ABORT_MEANINGS = {
    0x05040001: "command specifier not valid", 0x06010000: "unsupported access",
    0x06010001: "write-only object", 0x06010002: "read-only object",
    0x06020000: "object does not exist", 0x06040041: "object cannot be mapped to the PDO",
    0x06040042: "mapping exceeds the PDO length", 0x06040043: "parameter incompatibility",
    0x06070010: "data type length mismatch", 0x06090011: "sub-index does not exist",
    0x06090030: "value out of range", 0x08000000: "general error",
    0x08000020: "cannot be stored or used now", 0x08000022: "not in the present device state",
}


@pytest.mark.parametrize(("code", "meaning"), [*ABORT_MEANINGS.items(),
                                               (0x12345678, "see CiA 301"),
                                               (0x06090031, "see CiA 301")])
def test_the_sdo_abort_texts(code: int, meaning: str) -> None:
    """Known CiA 301 abort codes get their meaning, any other the pointer to the standard."""
    assert _abort_text(code) == meaning


@pytest.mark.parametrize(("code", "meaning"), [
    (0x8130, "heartbeat or life guard lost"), (0x8210, "PDO shorter than mapped"),
    (0x8220, "PDO longer than mapped"),
    (0x8240, "unexpected SYNC data length: the drive's 0x1019 does not match the SYNC counter"),
    (0x8250, "RPDO deadline missed"), (0x8611, "following error")])
def test_each_known_emcy_code_is_named_with_its_meaning(code: int, meaning: str) -> None:
    """The CiA 301/402 EMCY codes the loop meets (CiA 301 table 21, CiA 402) are named."""
    with _inactive() as hardware:
        hardware.configure()
        hardware.read()
        faults = _faults_after(hardware, [(cia402.EMCY_BASE + 1, cia402.emcy_frame(code))])
        assert faults == (f"x drive EMCY error code 0x{code:04X} (register 0x01; {meaning})",)


def test_the_sync_counter_runs_1_to_overflow_and_wraps() -> None:
    """With the counter on (0x1019 = 240), each SYNC carries 1..240 and then 1 again."""
    config = override(load_config(), "master.sim.channel", f"test-{uuid.uuid4().hex}")
    driver = create_hardware("sim-inproc", config).driver
    driver._plans()  # reads the EDS only: the counter is on when every drive has 0x1019
    assert (driver.sync_counter_overflow, driver.sync_counter_note) == (240, "SYNC counter 1..240")
    counts = [driver._next_sync().data[0] for _ in range(481)]
    assert counts == [*range(1, 241), *range(1, 241), 1]


# --- what a new driver starts from, and what it sends at configure --------------------


def _inactive(**overrides) -> SimulatedRigHardware:
    """The in-process emulated rig on a channel of its own, ``overrides`` (dotted key ->
    value) applied, not configured yet."""
    config = override(load_config(), "master.sim.channel", f"test-{uuid.uuid4().hex}")
    config = override(config, "master.can.heartbeat_timeout_s", 5.0)  # unpaced steps
    for key, value in overrides.items():
        config = override(config, key, value)
    hardware = create_hardware("sim-inproc", config)
    assert isinstance(hardware, SimulatedRigHardware)
    return hardware


def _frames(listener: can.BusABC) -> list[can.Message]:
    """Every frame ``listener`` has heard so far."""
    heard = []
    while (message := listener.recv(timeout=0.0)) is not None:
        heard.append(message)
    return heard


def test_a_new_driver_has_counted_nothing_and_its_first_cycle_is_1() -> None:
    """Before configure nothing is counted; configure's first reading is cycle 1, and its
    SYNC carries counter 1, again after a cleanup and a second configure."""
    hardware = _inactive()
    driver = hardware.driver
    assert (driver.late_frames, driver.sdo_resends, driver.emcy_log) == (0, 0, [])
    assert (driver.last_reading, driver.identities, driver.idle_heartbeat_errors) == (
        None, [], [])
    assert driver.sync_counter_note == "SYNC counter not configured yet"
    with can.Bus(interface="virtual", channel=driver.bus_options["channel"]) as listener:
        for configuration in (1, 2):
            hardware.configure()
            assert driver.last_reading is not None
            if configuration == 1:
                assert driver.last_reading.cycle == 1
            syncs = [m.data for m in _frames(listener) if m.arbitration_id == cia402.SYNC_COB_ID]
            assert syncs[0] == b"\x01", syncs
            hardware.cleanup()


def test_the_masters_heartbeat_reports_operational() -> None:
    """The master's heartbeat (0x700 + its node id) carries NMT state 0x05, configured and
    active."""
    with _inactive() as hardware:
        channel = hardware.driver.bus_options["channel"]
        master_heartbeat = HEARTBEAT_BASE + hardware.driver.settings.master_node_id
        with can.Bus(interface="virtual", channel=channel) as listener:
            hardware.configure()
            hardware.activate()
            for _ in range(3):
                hardware.read()
            beats = [bytes(m.data) for m in _frames(listener)
                     if m.arbitration_id == master_heartbeat]
        assert beats and set(beats) == {b"\x05"}, beats


def test_the_drive_states_are_per_axis() -> None:
    """``drive_states`` is (x, y): a fault of the y drive shows in the second place only."""
    with _inactive() as hardware:
        hardware.configure()
        hardware.rig.inject_drive_fault(1, 0x2310)
        hardware.read()
        x_state, y_state = hardware.driver.drive_states
        assert y_state is DriveState.FAULT and x_state is not DriveState.FAULT


# --- frames that are not the cycle's -----------------------------------------------------


def _bare_driver() -> tuple[CanHandleDriver, str]:
    """A driver with its bus open on a virtual channel of its own, no devices on it."""
    settings = master_settings(load_config())
    channel = f"test-{uuid.uuid4().hex}"
    driver = CanHandleDriver(settings.can, {"interface": "virtual", "channel": channel},
                             0.01, 0.00054)
    driver._bus = can.Bus(interface="virtual", channel=channel)
    return driver, channel


def test_the_drivers_own_frames_echoed_back_are_not_late_frames() -> None:
    """An interface that hands a process its own frames back (udp_multicast) must not make
    the NMT, SYNC, heartbeat, RPDO1 and SDO requests this driver sent late frames; any other
    frame left from an earlier cycle is one, and so is a standard frame with the number of
    an extended id this driver sent."""
    driver, channel = _bare_driver()
    try:
        master = driver.settings.master_node_id
        own = [cia402.NMT_COB_ID, cia402.SYNC_COB_ID, HEARTBEAT_BASE + master,
               *(base + node for base in (cia402.RPDO1_BASE, cia402.SDO_RX_BASE)
                 for node in driver.settings.node_ids)]
        driver.send_frame(0x1ABCDE, b"\x01", extended=True)
        with can.Bus(interface="virtual", channel=channel) as other:
            for frame_id in own:
                other.send(can.Message(arbitration_id=frame_id, data=b"\x00",
                                       is_extended_id=False))
            other.send(can.Message(arbitration_id=0x1ABCDE, data=b"", is_extended_id=True))
            faults: list[str] = []
            driver._discard_late_frames(faults, [False, False])
            assert (driver.late_frames, faults) == (0, [])
            for frame_id, extended in ((0x123, False), (0x1ABCDE & 0x7FF, False),
                                       (cia402.SYNC_COB_ID, True)):
                other.send(can.Message(arbitration_id=frame_id, data=b"",
                                       is_extended_id=extended))
            driver._discard_late_frames(faults, [False, False])
            assert (driver.late_frames, faults) == (3, [])
    finally:
        driver._close_bus()


# --- the bus -----------------------------------------------------------------------------


@pytest.mark.parametrize("overflow", [0, 240])
def test_the_bus_load_budget_counts_the_sync_counters_byte(overflow: int) -> None:
    """The budget's SYNC frame has one data byte with the counter on, none without."""
    config = override(load_config(), "master.can.sync_counter_overflow", overflow)
    config = override(config, "master.can.fd", True)
    settings = master_settings(config).can
    driver = CanHandleDriver(settings, {"interface": "virtual", "channel": "unused"},
                             0.01, 0.00054)
    expected = bus_load(0.00054, settings.bitrate, True, settings.data_bitrate,
                        settings.bus_load_limit, settings.heartbeat_period_s,
                        cycle_frames(sync_bytes=1 if overflow else 0))
    assert driver.check_bus_load() == expected
    other = bus_load(0.00054, settings.bitrate, True, settings.data_bitrate,
                     settings.bus_load_limit, settings.heartbeat_period_s,
                     cycle_frames(sync_bytes=0 if overflow else 1))
    assert other != expected


def test_only_the_real_buss_backend_prints_its_budget(capsys: pytest.CaptureFixture[str]
                                                      ) -> None:
    """The ``can`` backend announces the bus-load budget and the SYNC counter on stderr at
    configure; a driver made otherwise (the simulated rig's) prints nothing."""
    config = override(load_config(), "master.can.interface", "virtual")
    assert create_hardware("can", config).announce_bus_load is True
    with _inactive() as hardware:
        hardware.configure()
        assert capsys.readouterr().err == ""
        hardware.cleanup()
        hardware.driver.announce_bus_load = True
        hardware.configure()
        err = capsys.readouterr().err
        assert err.startswith("haptic-master: ") and err.endswith("; SYNC counter 1..240\n")


@pytest.mark.parametrize("error", [can.CanError("no such bus"), OSError("no device"),
                                   ValueError("bad channel"), ImportError("no driver")])
def test_a_bus_that_cannot_be_opened_is_one_hardware_error(monkeypatch, error) -> None:
    """Any of python-can's ways to refuse a bus is a HardwareError naming the options; the
    driver stays unconfigured."""
    def refuse(**_options):
        raise error

    hardware = _inactive()
    monkeypatch.setattr(can, "Bus", refuse)
    with pytest.raises(HardwareError, match=r"^cannot open the CAN bus \(interface=virtual, "
                       r"channel=test-[0-9a-f]+\): " + str(error)):
        hardware.driver.configure()
    assert hardware.driver.lifecycle_state is LifecycleState.UNCONFIGURED


# --- the command's range -----------------------------------------------------------------


INT32_MAX = 2**31 - 1  # the drives' 0x607A range, independent of the driver's constant


@pytest.mark.parametrize("axis", [0, 1])
@pytest.mark.parametrize(("counts", "sent"), [(INT32_MAX, True), (-INT32_MAX, True),
                                              (INT32_MAX + 1, False), (-INT32_MAX - 1, False)])
def test_the_int32_range_edge_of_a_command(axis: int, counts: int, sent: bool) -> None:
    """A target of +-(2**31 - 1) counts is sent; one count further is refused, both targets
    held."""
    with _active() as hardware:
        before = [drive.target_counts for drive in hardware.rig.drives]
        metres_per_count = hardware.driver.settings.metres_per_count
        command = [before[0] * metres_per_count, before[1] * metres_per_count]
        command[axis] = counts * metres_per_count
        hardware.write(np.array(command))
        faults = hardware.read().faults
        after = [drive.target_counts for drive in hardware.rig.drives]
        refused = "position command beyond the drives' int32 range" in faults
        assert refused is not sent
        expected = list(before)
        if sent:
            expected[axis] = counts
        assert after == expected


# --- configure's NMT sequence and its failures -------------------------------------------


def test_configure_puts_the_drives_pre_operational_first_and_starts_them_last() -> None:
    """NMT pre-operational to both drives before the first SDO request (a drive left
    operational by an earlier master stops its PDOs while it is configured), NMT start to
    both after the last."""
    with _inactive() as hardware:
        channel = hardware.driver.bus_options["channel"]
        nodes = hardware.driver.settings.node_ids
        with can.Bus(interface="virtual", channel=channel) as listener:
            hardware.configure()
            heard = _frames(listener)
        kinds = []
        for message in heard:
            if message.arbitration_id == cia402.NMT_COB_ID:
                kinds.append(("nmt", message.data[0], message.data[1]))
            elif message.arbitration_id - cia402.SDO_RX_BASE in nodes:
                kinds.append(("sdo",))
        nmt = [kind for kind in kinds if kind[0] == "nmt"]
        assert nmt == [("nmt", cia402.NMT_PRE_OPERATIONAL, nodes[0]),
                       ("nmt", cia402.NMT_PRE_OPERATIONAL, nodes[1]),
                       ("nmt", cia402.NMT_START, nodes[0]), ("nmt", cia402.NMT_START, nodes[1])]
        assert kinds[:2] == nmt[:2] and kinds[-2:] == nmt[2:] and ("sdo",) in kinds


def _nmt_states(hardware: SimulatedRigHardware, expected: str) -> list[str]:
    """The rig's drives' NMT states, once both are ``expected`` or after 2 s."""
    deadline = time.monotonic() + 2.0
    while True:
        states = [drive.nmt_state for drive in hardware.rig.drives]
        if set(states) == {expected} or time.monotonic() > deadline:
            return states
        time.sleep(0.005)


def test_no_position_after_start_is_a_hardware_error_and_leaves_the_drives_pre_operational(
        ) -> None:
    """A drive that sends no TPDO1 once started fails configure with the reading's faults;
    both drives go back to pre-operational and the bus is closed."""
    with _inactive() as hardware:
        hardware.rig.drop_tpdo(0, 10**6)
        with pytest.raises(HardwareError, match=r"^no position from the drives after start: "
                           r"missing TPDO1 from the x drive \(node 1\)"):
            hardware.configure()
        assert hardware.lifecycle_state is LifecycleState.UNCONFIGURED
        assert hardware.driver._bus is None
        assert _nmt_states(hardware, NMT_PRE_OPERATIONAL_STATE) == [
            NMT_PRE_OPERATIONAL_STATE] * 2


@pytest.mark.parametrize("kind", [OSError, can.CanError])
def test_a_bus_gone_while_configure_fails_keeps_the_first_error(monkeypatch, kind) -> None:
    """When the NMT commands of the failure path cannot be sent either, configure raises the
    error that stopped it, not the later one, and closes the bus."""
    hardware = _inactive()
    driver = hardware.driver
    failures = iter(("first", "second", "third"))

    def broken_nmt(_command: int, _node: int) -> None:
        raise kind(next(failures))

    monkeypatch.setattr(driver, "_nmt", broken_nmt)
    try:
        with pytest.raises(kind, match="^first$"):
            driver.configure()
        assert driver._bus is None
        assert driver.lifecycle_state is LifecycleState.UNCONFIGURED
    finally:
        hardware.cleanup()


@pytest.mark.parametrize("axis", [0, 1])
def test_a_drive_silent_from_the_start_is_reported_once(monkeypatch, axis: int) -> None:
    """A drive that never sends a heartbeat is a fault once its timeout has passed after
    configure, reported once; the other drive's heartbeat keeps it quiet."""
    with _inactive(**{"master.can.heartbeat_timeout_s": 0.3}) as hardware:
        device = hardware.rig.devices[axis]
        refresh = device.refresh

        def silent_refresh() -> None:
            refresh()
            device.heartbeat_producer_ms = 0

        monkeypatch.setattr(device, "refresh", silent_refresh)
        hardware.configure()
        faults: list[str] = []
        deadline = time.monotonic() + 3.0
        while time.monotonic() < deadline:
            faults += hardware.read().faults
            time.sleep(0.01)
            if any("heartbeat" in f for f in faults) and time.monotonic() > deadline - 2.0:
                break
        name, other = ("x", "y") if axis == 0 else ("y", "x")
        lost = [f for f in faults
                if f.startswith(f"no heartbeat from the {name} drive (node {axis + 1}) for ")]
        assert len(lost) == 1 and lost[0].endswith(" s (timeout 0.3 s)"), faults
        assert not any(f"{other} drive" in f for f in faults), faults


# --- the drives' EDS ---------------------------------------------------------------------


def test_an_eds_that_cannot_be_read_is_named_in_one_hardware_error(tmp_path) -> None:
    """An EDS file gone since the configuration was checked names the axis and the file."""
    missing = tmp_path / "gone.eds"
    settings = dataclasses.replace(master_settings(load_config()).can, x_eds_file=str(missing))
    driver = CanHandleDriver(settings,
                             {"interface": "virtual", "channel": "unused"}, 0.01, 0.00054)
    with pytest.raises(HardwareError, match=rf"^cannot read the x drive's EDS \({missing}\): "):
        driver.configure()
    assert driver.lifecycle_state is LifecycleState.UNCONFIGURED


@pytest.mark.parametrize("error", [OSError("unreadable"), ValueError("not an EDS"),
                                   KeyError("0x1000")])
def test_each_way_an_eds_fails_to_load_is_one_hardware_error(monkeypatch, error) -> None:
    """Whatever the EDS loader raises for a bad file (OSError, ValueError, KeyError) is a
    HardwareError before the bus is opened."""
    def broken(_eds: str, _node: int):
        raise error

    monkeypatch.setattr(can_driver, "load_drive_dictionary", broken)
    driver = CanHandleDriver(master_settings(load_config()).can,
                             {"interface": "virtual", "channel": "unused"}, 0.01, 0.00054)
    with pytest.raises(HardwareError, match=r"^cannot read the x drive's EDS \(packaged\): "):
        driver.configure()
    assert driver._bus is None


def test_a_configured_dbc_sets_the_sensor_frame(tmp_path) -> None:
    """The sensor frame's id comes from the configured DBC, not the packaged one."""
    text = importlib.resources.files("haptic.master.hardware").joinpath(
        "dbc/force_sensor.dbc").read_text()
    path = tmp_path / "sensor.dbc"
    path.write_text(text.replace(" 400 ", " 401 "))
    config = override(load_config(), "master.can.dbc_file", str(path))
    driver = CanHandleDriver(master_settings(config).can,
                             {"interface": "virtual", "channel": "unused"}, 0.01, 0.00054)
    assert driver.codec.frame_id == 401
    assert CanHandleDriver(master_settings(load_config()).can, {"interface": "virtual"},
                           0.01, 0.00054).codec.frame_id == 400


def test_configure_writes_the_following_error_window_in_counts() -> None:
    """0x6065 gets ``following_error_window_m`` in encoder counts."""
    with _inactive() as hardware:
        hardware.configure()
        settings = hardware.driver.settings
        expected = round(settings.following_error_window_m / settings.metres_per_count)
        assert expected > 1
        assert [d.following_error_window_counts for d in hardware.rig.devices] == [expected] * 2


# --- the SYNC ----------------------------------------------------------------------------


@pytest.mark.parametrize(("overflow", "fd"), [(0, False), (0, True), (240, False), (240, True)])
def test_sync_puts_the_sync_on_the_bus_at_once(overflow: int, fd: bool) -> None:
    """``sync()`` sends the SYNC there and then: a standard frame 0x080, without data or with
    the counter, an FD frame (bit-rate switch) on CAN FD; a second ``sync()`` before the
    read sends nothing."""
    period = {} if fd else {"model.sample_period_s": 0.001}  # classical CAN's bus load
    with _inactive(**{"master.can.sync_counter_overflow": overflow, "master.can.fd": fd},
                   **period) as hardware:
        hardware.driver.sample_period_s = 0.00054 if fd else 0.001
        hardware.configure()
        channel = hardware.driver.bus_options["channel"]
        with can.Bus(interface="virtual", channel=channel) as listener:
            hardware.driver.sync()
            hardware.driver.sync()
            syncs = [m for m in _frames(listener) if m.arbitration_id == cia402.SYNC_COB_ID]
        assert len(syncs) == 1
        sync = syncs[0]
        assert sync.is_extended_id is False and (sync.is_fd, sync.bitrate_switch) == (fd, fd)
        assert len(sync.data) == (1 if overflow else 0)


def _plans_of(**overrides) -> CanHandleDriver:
    """A driver whose plans were made (the EDS read, no bus) under ``overrides``."""
    config = load_config()
    for key, value in overrides.items():
        config = override(config, key, value)
    driver = CanHandleDriver(master_settings(config).can,
                             {"interface": "virtual", "channel": "unused"}, 0.01, 0.00054)
    driver._plans()
    return driver


def test_the_sync_counter_is_on_only_when_configured_and_every_eds_has_0x1019(tmp_path
                                                                            ) -> None:
    """Configured and in both EDS: on, 1..overflow. Configured off: off, saying so. An EDS
    without 0x1019: off for the bus, naming the EDS, whichever axis it is."""
    eds = packaged_eds_path().read_text()
    path = tmp_path / "no1019.eds"  # canopen reads the object sections, not the lists
    path.write_text(eds.replace(eds[eds.index("[1019]"):eds.index("[1400]")], ""))
    driver = _plans_of(**{"master.can.sync_counter_overflow": 17})
    assert (driver.sync_counter_overflow, driver.sync_counter_note) == (17, "SYNC counter 1..17")
    driver = _plans_of(**{"master.can.sync_counter_overflow": 0})
    assert (driver.sync_counter_overflow, driver.sync_counter_note) == (
        0, "SYNC counter off ([master.can] sync_counter_overflow = 0)")
    for axis in ("x", "y"):
        driver = _plans_of(**{f"master.can.{axis}_eds_file": str(path)})
        assert (driver.sync_counter_overflow, driver.sync_counter_note) == (
            0, f"SYNC counter off: the {axis} drive's EDS ({path}) has no 0x1019")
    driver = _plans_of(**{"master.can.x_eds_file": str(path), "master.can.y_eds_file": str(path)})
    assert driver.sync_counter_note == (f"SYNC counter off: the x drive's EDS ({path}) and the "
                                        f"y drive's EDS ({path}) have no 0x1019")
    driver = _plans_of(**{"master.can.x_eds_file": str(path),
                          "master.can.sync_counter_overflow": 0})
    assert driver.sync_counter_note == "SYNC counter off ([master.can] sync_counter_overflow = 0)"


# --- configure's identity check and activate ---------------------------------------------


def _set_object(device, index: int, subindex: int, value: int) -> None:
    """Store ``value`` in an emulated drive's object as if it were its own (a read-only one
    too)."""
    device.node.set_data(index, subindex, device._variable(index, subindex).encode_raw(value))


def test_configure_reads_each_drives_identity() -> None:
    """``identities`` holds each drive's 0x1000 and 0x1018:1-4, as the drive answers them."""
    with _inactive() as hardware:
        for axis, device in enumerate(hardware.rig.devices):
            _set_object(device, 0x1018, 4, 0x5E000 + axis)  # a serial number of its own
        hardware.configure()
        expected = [{"device_type": device.raw(0x1000), "vendor_id": device.raw(0x1018, 1),
                     "product_code": device.raw(0x1018, 2), "revision": device.raw(0x1018, 3),
                     "serial_number": device.raw(0x1018, 4)} for device in hardware.rig.devices]
        assert len(set(expected[0].values())) == 5
        assert hardware.driver.identities == expected


def _configure_error(hardware: SimulatedRigHardware) -> str:
    with pytest.raises(HardwareError) as error:
        hardware.configure()
    assert hardware.lifecycle_state is LifecycleState.UNCONFIGURED
    return str(error.value)


def test_a_device_that_is_not_a_cia402_drive_is_refused() -> None:
    """0x1000's low word must be 402; the high word (the drive's type) is free."""
    with _inactive() as hardware:
        _set_object(hardware.rig.devices[1], 0x1000, 0, 0x00020191)
        assert _configure_error(hardware) == ("y drive (node 2) is not a CiA 402 drive (0x1000 "
                                              "device type 0x00020191)")
    with _inactive() as hardware:
        _set_object(hardware.rig.devices[1], 0x1000, 0, 0x00FF0192)
        hardware.configure()
        assert hardware.driver.identities[1]["device_type"] == 0x00FF0192


def test_a_drive_with_another_vendor_or_product_than_its_eds_is_refused(tmp_path) -> None:
    """The vendor and product code the drive reports must be its EDS's, where the EDS gives
    them (a vendor number 0 is not checked)."""
    with _inactive() as hardware:
        _set_object(hardware.rig.devices[0], 0x1018, 2, 0x4C03)
        assert _configure_error(hardware) == (
            "x drive (node 1) reports product_code 0x00004C03, its EDS describes 0x00004C02: "
            "another device or EDS")
    with _inactive() as hardware:
        _set_object(hardware.rig.devices[0], 0x1018, 1, 0xAB)  # the EDS's vendor is 0
        hardware.configure()
    eds = packaged_eds_path().read_text().replace("VendorNumber=0x00000000",
                                                  "VendorNumber=0x000000AB")
    path = tmp_path / "vendor.eds"
    path.write_text(eds)
    overrides = {"master.can.x_eds_file": str(path), "master.can.y_eds_file": str(path)}
    with _inactive(**overrides) as hardware:
        for device in hardware.rig.devices:
            _set_object(device, 0x1018, 1, 0xAB)
        hardware.configure()
        assert [i["vendor_id"] for i in hardware.driver.identities] == [0xAB, 0xAB]
    with _inactive(**overrides) as hardware:
        _set_object(hardware.rig.devices[0], 0x1018, 1, 0xAB)
        _set_object(hardware.rig.devices[1], 0x1018, 1, 0xAC)
        assert _configure_error(hardware) == (
            "y drive (node 2) reports vendor_id 0x000000AC, its EDS describes 0x000000AB: "
            "another device or EDS")


def _answering(device, index: int, value: int) -> None:
    """The emulated drive answers reads of ``index`` with ``value`` from now on."""
    read_index = index

    def answer(index: int, subindex: int, od) -> int | None:  # canopen's keywords
        return value if index == read_index else None

    device.node._read_callbacks.insert(0, answer)


def test_a_write_that_does_not_read_back_or_a_mode_not_8_is_refused() -> None:
    """Every configuration write is read back; a drive that keeps another value, or reports
    a mode other than cyclic synchronous position, fails configure naming it."""
    with _inactive() as hardware:
        _answering(hardware.rig.devices[0], 0x1017, 7)
        message = _configure_error(hardware)
        assert re.fullmatch(r"x drive \(node 1\): .* reads back 7 after writing \d+", message), (
            message)
    with _inactive() as hardware:
        _answering(hardware.rig.devices[1], 0x6061, 1)
        assert _configure_error(hardware) == ("y drive (node 2) reports mode 1, not cyclic "
                                              "synchronous position (8)")


def _sdo_downloads(heard: list[can.Message], index: int) -> list[tuple[int, int]]:
    """(node, value) of each expedited SDO download of ``index`` among ``heard``."""
    found = []
    for message in heard:
        node = message.arbitration_id - cia402.SDO_RX_BASE
        if 1 <= node <= 127 and len(message.data) == 8 and message.data[0] & 0xE0 == 0x20 and (
                int.from_bytes(message.data[1:3], "little") == index):
            found.append((node, int.from_bytes(message.data[4:8], "little", signed=True)))
    return found


def test_activate_sets_each_drives_target_to_its_actual_position_first() -> None:
    """Before the enable sequence, 0x607A of each drive is written by SDO with its actual
    position (the sequence never moves the handle)."""
    with _inactive() as hardware:
        hardware.configure()
        channel = hardware.driver.bus_options["channel"]
        with can.Bus(interface="virtual", channel=channel) as listener:
            hardware.activate()
            heard = _frames(listener)
        positions = [drive.position_counts for drive in hardware.rig.drives]
        nodes = hardware.driver.settings.node_ids
        assert _sdo_downloads(heard, 0x607A) == list(zip(nodes, positions, strict=True))


def test_activate_without_positions_is_refused_and_the_idle_heartbeat_goes_on() -> None:
    """No TPDO1 at activate: a HardwareError with the reading's faults; the driver stays
    inactive and its heartbeat goes on from the idle task."""
    with _inactive() as hardware:
        hardware.configure()
        hardware.rig.drop_tpdo(1, 10**6)
        with pytest.raises(HardwareError, match=r"^cannot activate without positions: missing "
                           r"TPDO1 from the y drive \(node 2\)"):
            hardware.activate()
        assert hardware.lifecycle_state is LifecycleState.INACTIVE
        assert hardware.driver._idle_heartbeat is not None


def test_a_drive_faulted_once_is_reset_once_and_one_faulting_again_stops_activation() -> None:
    """One fault before activate: one fault reset, then enabled. A fault that comes back
    after its reset: activation stops at the transition into it, naming it."""
    with _inactive() as hardware:
        hardware.configure()
        hardware.rig.inject_drive_fault(1, 0x2310)
        hardware.read()
        hardware.activate()
        assert hardware.driver.drive_states == (DriveState.OPERATION_ENABLED,) * 2
    with _inactive() as hardware:
        hardware.configure()
        hardware.rig.inject_drive_fault(0, 0x7305, persistent=True)
        hardware.read()
        with pytest.raises(HardwareError, match=r"^activation stopped: x drive went from switch "
                           r"on disabled to fault on controlword 0x0006 \(x: fault, y: [a-z ]+; "
                           r"EMCY x 0x7305\)$"):
            hardware.activate()
        assert hardware.lifecycle_state is LifecycleState.INACTIVE
        assert hardware.driver._idle_heartbeat is not None


def _rpdo_controlwords(heard: list[can.Message], node: int) -> list[int]:
    return [int.from_bytes(m.data[0:2], "little") for m in heard
            if m.arbitration_id == cia402.RPDO1_BASE + node]


@pytest.mark.parametrize("axis", [0, 1])
def test_a_drive_that_stays_in_fault_gets_two_resets_then_activation_stops(monkeypatch,
                                                                           axis: int) -> None:
    """A fault whose cause persists keeps the drive in Fault through a fault reset: the
    driver resets it twice (each on a rising edge of bit 7), then stops."""
    transition = cia402.next_drive_state

    def fault_stays(state, controlword, previous):
        return state if state is DriveState.FAULT else transition(state, controlword, previous)

    monkeypatch.setattr(cia402, "next_drive_state", fault_stays)
    with _inactive() as hardware:
        hardware.configure()
        hardware.rig.inject_drive_fault(axis, 0x7305)
        hardware.read()
        channel = hardware.driver.bus_options["channel"]
        with can.Bus(interface="virtual", channel=channel) as listener:
            with pytest.raises(HardwareError, match=r"^activation stopped: a drive faulted "
                               r"again after its fault reset \(x: "):
                hardware.activate()
            heard = _frames(listener)
        assert hardware.driver.drive_states[axis] is DriveState.FAULT
        words = _rpdo_controlwords(heard, axis + 1)
        assert words.count(cia402.CW_FAULT_RESET) == 2, [hex(w) for w in words]
        first = words.index(cia402.CW_FAULT_RESET)
        assert words[first + 1] == cia402.CW_DISABLE_VOLTAGE  # bit 7 low before the next
        assert words[-1] == cia402.CW_DISABLE_VOLTAGE  # both shut down at the stop
        monkeypatch.undo()  # the cause is gone: the next activate resets it at once
        with can.Bus(interface="virtual", channel=channel) as listener:
            hardware.activate()
            words = _rpdo_controlwords(_frames(listener), axis + 1)
        assert words[0] == cia402.CW_FAULT_RESET, [hex(w) for w in words]
        assert hardware.driver.drive_states == (DriveState.OPERATION_ENABLED,) * 2


@pytest.mark.parametrize(("y_faulted_first", "fault_after", "named"), [
    (False, 2, "ready to switch on to fault on controlword 0x0007"),
    (True, 4, "switched on to fault on controlword 0x000F")])
def test_an_unexpected_transition_during_the_enable_sequence_stops_it(
        monkeypatch, y_faulted_first: bool, fault_after: int, named: str) -> None:
    """A drive that faults in the middle of the enable sequence: the sequence stops at that
    step, naming the transition and the controlword, and shuts both drives down; also when
    the other drive is enabled already (the y drive one step behind after its reset)."""
    with _inactive() as hardware:
        hardware.configure()
        driver = hardware.driver
        if y_faulted_first:
            hardware.rig.inject_drive_fault(1, 0x2310)
            hardware.read()
        send_rpdo = driver._send_rpdo
        sent: list[tuple[int, int]] = []

        def fault_y_at_a_step(axis: int, controlword: int) -> None:
            sent.append((axis, controlword))
            send_rpdo(axis, controlword)
            if sum(a == 1 for a, _ in sent) == fault_after:
                hardware.rig.inject_drive_fault(1, 0x5530)

        monkeypatch.setattr(driver, "_send_rpdo", fault_y_at_a_step)
        with pytest.raises(HardwareError, match=rf"^activation stopped: y drive went from "
                           rf"{named} \("):
            hardware.activate()
        assert hardware.lifecycle_state is LifecycleState.INACTIVE
        if y_faulted_first:
            assert hardware.driver.drive_states[0] is DriveState.OPERATION_ENABLED


# --- SDO exchanges against a scripted peer -----------------------------------------------


class _SdoPeer:
    """A second bus member that answers each SDO request to node 1 with the frames
    ``answer(request_number, request)`` gives (none: the request is lost)."""

    def __init__(self, channel: str, answer) -> None:
        self.requests: list[bytes] = []
        self._answer = answer
        self._bus = can.Bus(interface="virtual", channel=channel)
        self._notifier = can.Notifier(self._bus, [self._on_message], timeout=0.01)

    def _on_message(self, message: can.Message) -> None:
        if message.arbitration_id != cia402.SDO_RX_BASE + 1:
            return
        self.requests.append(bytes(message.data))
        for frame_id, data in self._answer(len(self.requests), bytes(message.data)):
            self._bus.send(can.Message(arbitration_id=frame_id, data=data,
                                       is_extended_id=False))

    def close(self) -> None:
        self._notifier.stop()
        self._bus.shutdown()


def _sdo_driver(pdo_timeout_s: float = 0.01) -> tuple[CanHandleDriver, str]:
    driver, channel = _bare_driver()
    driver.pdo_timeout_s = pdo_timeout_s  # the SDO deadline is 200 of these
    return driver, channel


_TX = cia402.SDO_TX_BASE + 1


def _exchange(answer, action, pdo_timeout_s: float = 0.01):
    """Run ``action(driver, dictionary)`` against a peer answering with ``answer``; the
    result (or the HardwareError), the driver and the requests the peer saw."""
    driver, channel = _sdo_driver(pdo_timeout_s)
    peer = _SdoPeer(channel, answer)
    dictionary = can_driver.load_drive_dictionary("", 1)
    try:
        try:
            result = action(driver, dictionary)
        except HardwareError as error:
            result = error
        return result, driver, peer.requests
    finally:
        peer.close()
        driver._close_bus()


def test_a_lost_sdo_request_is_sent_again_and_counted() -> None:
    """No reply within SDO_RESEND_S: the same request again, counted in ``sdo_resends``."""
    def second_only(number: int, request: bytes):
        if number < 2:
            return []
        return [(_TX, cia402.sdo_upload_response(dictionary_1017, 250))]

    dictionary_1017 = can_driver.load_drive_dictionary("", 1)[0x1017]
    result, driver, requests = _exchange(
        second_only, lambda d, od: d._sdo_read(1, od[0x1017], "x drive"))
    assert result == 250
    assert len(requests) >= 2 and set(requests) == {requests[0]}
    assert driver.sdo_resends == len(requests) - 1


def test_no_sdo_reply_by_the_deadline_is_one_hardware_error() -> None:
    """Nothing answers: the request is sent again every SDO_RESEND_S until the deadline
    (``pdo_timeout_s`` x ``enable_timeout_cycles``: 0.4 s here, so once), then an error
    naming the node and the object."""
    result, driver, requests = _exchange(
        lambda n, r: [], lambda d, od: d._sdo_read(1, od[0x1017], "x drive"),
        pdo_timeout_s=0.002)
    assert str(result) == ("x drive read: no SDO reply from node 1 for 0x1017:00 (Producer "
                           "heartbeat time)")
    assert len(requests) == 2 and driver.sdo_resends == 1


def test_an_sdo_exchange_skips_what_is_not_its_reply() -> None:
    """Skipped while waiting: a reply of another node, one that is not 8 bytes, a reply
    for another object; taken: the reply for the object, of which only the variable's size
    counts (UNSIGNED16 here)."""
    def noisy(number: int, request: bytes):
        return [(cia402.SDO_TX_BASE + 2, bytes([0x4B, 0x17, 0x10, 0, 1, 0, 0, 0])),
                (_TX, b"\x4b\x17\x10"),
                (_TX, bytes([0x4B, 0x18, 0x10, 0, 2, 0, 0, 0])),
                (_TX, bytes([0x43, 0x17, 0x10, 0, 0x34, 0x12, 0xFF, 0xFF]))]

    result, driver, requests = _exchange(
        noisy, lambda d, od: d._sdo_read(1, od[0x1017], "x drive"))
    assert result == 0x1234 and len(requests) == 1 and driver.late_frames == 0


def test_an_sdo_abort_names_the_object_and_its_code() -> None:
    def abort(number: int, request: bytes):
        return [(_TX, cia402.sdo_abort(0x1017, 0, 0x06090030))]

    result, _, _ = _exchange(abort, lambda d, od: d._sdo_write(1, od[0x1017], 9, "x drive"))
    assert str(result) == ("x drive write: SDO abort 0x06090030 (value out of range) on "
                           "0x1017:00 (Producer heartbeat time)")


@pytest.mark.parametrize(("command", "named"), [
    (0x41, "0x41"), (0x60, "0x60"), (0x4F, None), (0x4B, None), (0x43, None), (0x42, None)])
def test_an_sdo_read_takes_only_an_expedited_upload(command: int, named: str | None) -> None:
    """An upload reply must be expedited (0x4?, bit 1 set); a segmented one (0x41) or a
    download reply (0x60) is refused, naming the command."""
    def reply(number: int, request: bytes):
        return [(_TX, bytes([command, 0x17, 0x10, 0, 0x64, 0, 0, 0]))]

    result, _, _ = _exchange(reply, lambda d, od: d._sdo_read(1, od[0x1017], "x drive"))
    if named is None:
        assert result == 100
    else:
        assert str(result) == (f"x drive: 0x1017:00 answered with SDO command {named}, not an "
                               "expedited upload")


@pytest.mark.parametrize("command", [0x43, 0x40, 0x61])
def test_an_sdo_write_takes_only_a_download_reply(command: int) -> None:
    def reply(number: int, request: bytes):
        return [(_TX, bytes([command, 0x17, 0x10, 0, 0, 0, 0, 0]))]

    result, _, _ = _exchange(reply, lambda d, od: d._sdo_write(1, od[0x1017], 9, "x drive"))
    assert str(result) == (f"x drive: unexpected SDO reply 0x{command:02X} to the write of "
                           "0x1017:00")
    result, _, requests = _exchange(
        lambda n, r: [(_TX, cia402.sdo_download_response(0x1017, 0))],
        lambda d, od: d._sdo_write(1, od[0x1017], 9, "x drive"))
    assert result is None and requests == [cia402.sdo_download_request(
        can_driver.load_drive_dictionary("", 1)[0x1017], 9)]


def test_supervision_frames_during_an_sdo_exchange_are_kept_for_the_next_read() -> None:
    """An EMCY while waiting for an SDO reply is logged and kept as a fault; a heartbeat
    notes the drive as heard, whatever state it reports (not a fault while configuring)."""
    def with_emcy(number: int, request: bytes):
        return [(cia402.EMCY_BASE + 1, cia402.emcy_frame(0x5530)),
                (HEARTBEAT_BASE + 2, b"\x7f"),
                (_TX, cia402.sdo_upload_response(
                    can_driver.load_drive_dictionary("", 1)[0x1017], 5))]

    before = time.monotonic()
    result, driver, _ = _exchange(with_emcy, lambda d, od: d._sdo_read(1, od[0x1017], "x"))
    assert result == 5
    assert driver.emcy_log == [("x", 0x5530)]
    assert driver._pending_faults == ["x drive EMCY error code 0x5530 (register 0x01)"]
    assert driver._heartbeat_seen_s[1] >= before and driver._heartbeat_seen_s[0] == 0.0


def test_a_drive_that_faults_silently_once_enabled_is_reset_directly(monkeypatch) -> None:
    """A drive already enabled that faults without an EMCY while the other drive is still
    being enabled: its next step is the fault reset itself (bit 7 was low: the controlword
    before was enable operation), then the sequence again."""
    with _inactive() as hardware:
        hardware.configure()
        hardware.rig.inject_drive_fault(1, 0x2310)  # the y drive one step behind
        hardware.read()
        driver = hardware.driver
        send_rpdo = driver._send_rpdo
        x_words: list[int] = []

        def fault_x_when_enabled(axis: int, controlword: int) -> None:
            send_rpdo(axis, controlword)
            if axis == 0:
                x_words.append(controlword)
                if len(x_words) == 4:  # x enabled after three steps, y not yet
                    with hardware.rig._lock:
                        hardware.rig.drives[0].state = DriveState.FAULT  # no EMCY

        monkeypatch.setattr(driver, "_send_rpdo", fault_x_when_enabled)
        hardware.activate()
        assert driver.drive_states == (DriveState.OPERATION_ENABLED,) * 2
        assert x_words == [cia402.CW_SHUTDOWN, cia402.CW_SWITCH_ON, cia402.CW_ENABLE_OPERATION,
                           cia402.CW_ENABLE_OPERATION, cia402.CW_FAULT_RESET,
                           cia402.CW_SHUTDOWN, cia402.CW_SWITCH_ON,
                           cia402.CW_ENABLE_OPERATION][:len(x_words)]
        assert len(x_words) >= 8


# --- deactivate and cleanup --------------------------------------------------------------


@pytest.mark.parametrize("tripped", [False, True])
def test_deactivate_disables_then_shuts_down_and_the_idle_heartbeat_resumes(tripped: bool
                                                                           ) -> None:
    """From operation enabled: disable operation (from quick stop: disable voltage, as
    disable operation is no transition there), then shutdown; the driver is inactive and
    its idle heartbeat runs. Inactive, deactivate sends nothing."""
    with _inactive() as hardware:
        hardware.configure()
        hardware.deactivate()  # inactive: nothing
        hardware.activate()
        if tripped:
            hardware.stop_motion("test")
            hardware.read()
        channel = hardware.driver.bus_options["channel"]
        with can.Bus(interface="virtual", channel=channel) as listener:
            hardware.deactivate()
            heard = _frames(listener)
            hardware.deactivate()  # inactive now: nothing more
            assert _rpdo_controlwords(_frames(listener), 1) == []
        first = cia402.CW_DISABLE_VOLTAGE if tripped else cia402.CW_DISABLE_OPERATION
        for node in (1, 2):
            assert _rpdo_controlwords(heard, node) == [first, cia402.CW_SHUTDOWN]
        assert hardware.lifecycle_state is LifecycleState.INACTIVE
        assert hardware.driver._idle_heartbeat is not None
        assert hardware.driver.drive_states == (DriveState.READY_TO_SWITCH_ON,) * 2


# --- the master's own quick stop and its resume ------------------------------------------


def test_the_masters_stop_is_an_event_once_and_holds_the_drives_at_their_positions() -> None:
    """stop_motion: quick stop on both drives at once, an event (not a fault) once however
    often it is called, each drive's taking it an event once; writes meanwhile send quick
    stop with the targets held where the drives were. Inactive, it does nothing."""
    with _inactive() as hardware:
        hardware.configure()
        hardware.stop_motion("early")
        assert hardware.read().events == ()
        hardware.activate()
        hardware.read()
        channel = hardware.driver.bus_options["channel"]
        with can.Bus(interface="virtual", channel=channel) as listener:
            hardware.stop_motion("watchdog tripped")
            hardware.stop_motion("again")
            held = [drive.position_counts for drive in hardware.rig.drives]
            events: list[str] = []
            faults: list[str] = []
            for _ in range(10):
                hardware.write(np.array([0.01, 0.01]))
                reading = hardware.read()
                events += reading.events
                faults += reading.faults
            heard = _frames(listener)
        assert faults == []
        assert events.count("quick stop on both drives: watchdog tripped") == 1
        assert not any("again" in e for e in events)
        for name in ("x", "y"):  # once, though the drive goes on to switch on disabled
            took = [e for e in events if e.startswith(f"{name} drive took the quick stop")]
            assert took == [f"{name} drive took the quick stop (quick stop active)"], events
        for axis, node in enumerate((1, 2)):
            frames = [m for m in heard if m.arbitration_id == cia402.RPDO1_BASE + node]
            assert frames and all(
                tuple(m.data) == tuple(struct.pack("<Hi", cia402.CW_QUICK_STOP, held[axis]))
                for m in frames)


def test_resume_reenables_at_the_actual_positions_and_only_after_a_stop() -> None:
    """resume_motion without a stop does nothing; after one, the enable sequence from quick
    stop, the targets at the actual positions, an event, and the drives follow again."""
    with _active() as hardware:
        hardware.read()
        hardware.resume_motion()
        assert hardware.read().events == ()
        hardware.stop_motion("node trip")
        for _ in range(5):
            hardware.read()
        hardware.resume_motion()
        assert hardware.driver.drive_states == (DriveState.OPERATION_ENABLED,) * 2
        reading = hardware.read()
        assert "drives re-enabled at their actual positions after the quick stop" in \
            reading.events
        assert reading.faults == ()
        for drive in hardware.rig.drives:
            assert drive.target_counts == drive.position_counts
        hardware.resume_motion()  # once is enough
        assert hardware.read().events == ()
        channel = hardware.driver.bus_options["channel"]
        target = [drive.position_counts + 40 for drive in hardware.rig.drives]
        per_count = hardware.driver.settings.metres_per_count
        with can.Bus(interface="virtual", channel=channel) as listener:
            hardware.write(np.array(target) * per_count)  # the drives follow again
            heard = _frames(listener)
        for axis, node in enumerate((1, 2)):
            assert [bytes(m.data) for m in heard if m.arbitration_id == cia402.RPDO1_BASE
                    + node] == [struct.pack("<Hi", cia402.CW_ENABLE_OPERATION, target[axis])]


def test_a_resume_that_fails_is_a_fault_and_the_drives_stay_stopped(monkeypatch) -> None:
    """A drive that faults again while re-enabled: the reading says so and write() keeps
    sending quick stop."""
    with _active() as hardware:
        hardware.read()
        hardware.stop_motion("node trip")
        for _ in range(5):
            hardware.read()
        hardware.rig.inject_drive_fault(0, 0x7305, persistent=True)
        hardware.resume_motion()
        reading = hardware.read()
        failed = [f for f in reading.faults
                  if f.startswith("re-enabling after the quick stop failed: activation stopped")]
        assert len(failed) == 1, reading.faults
        assert not any("re-enabled" in e for e in reading.events)
        channel = hardware.driver.bus_options["channel"]
        with can.Bus(interface="virtual", channel=channel) as listener:
            hardware.write(np.array([0.01, 0.01]))
            assert set(_rpdo_controlwords(_frames(listener), 1)) == {cia402.CW_QUICK_STOP}


@pytest.mark.parametrize("axis", [0, 1])
def test_a_drive_that_does_not_take_the_stop_is_one_fault_after_the_enable_timeout(
        axis: int) -> None:
    """Not in quick stop active or switch on disabled after ``enable_timeout_cycles`` SYNCs
    of the stop: one fault naming the drive, its state and the SYNCs; the other drive took
    it."""
    with _active(**{"master.can.enable_timeout_cycles": 5}) as hardware:
        hardware.read()
        with hardware.rig._lock:
            hardware.rig.drives[axis].mode = 1  # profile position: CSP's state machine ignores it
        hardware.stop_motion("node trip")
        faults: list[tuple[int, str]] = []
        events: list[str] = []
        for number in range(1, 13):
            reading = hardware.read()
            faults += [(number, fault) for fault in reading.faults]
            events += reading.events
        name, other = ("x", "y") if axis == 0 else ("y", "x")
        assert faults == [(6, f"{name} drive did not take the quick stop (operation enabled "
                              "after 6 SYNCs)")]
        assert f"{other} drive took the quick stop (quick stop active)" in events


def test_a_drive_fault_while_active_quick_stops_both_once() -> None:
    """A drive fault while active: quick stop on both drives, as a fault of that reading,
    once; the driver holds quick stop until re-activated."""
    with _active() as hardware:
        hardware.read()
        hardware.rig.inject_drive_fault(1, 0x2310)
        faults: list[str] = []
        for _ in range(4):
            hardware.write(np.zeros(2))
            faults += hardware.read().faults
        assert faults.count("quick stop on both drives: a drive fault") == 1
        assert "y drive in fault" in faults
        hardware.driver.quick_stop("again")  # tripped: nothing more
        assert "quick stop on both drives: again" not in hardware.read().faults


# --- the cycle's frames ------------------------------------------------------------------


def _read_with_tpdo(hardware: SimulatedRigHardware, axis: int, payload: bytes):
    """A reading whose ``axis`` TPDO1 is ``payload`` from another bus member (the drive's
    own dropped for that SYNC)."""
    return _read_with_tpdo_id(hardware, axis, cia402.TPDO1_BASE + axis + 1, payload)


def _read_with_tpdo_id(hardware: SimulatedRigHardware, axis: int, frame_id: int,
                       payload: bytes):
    """A reading for which the ``axis`` drive's TPDO1 is dropped and another bus member sends
    ``payload`` on ``frame_id`` after the SYNC."""
    hardware.rig.drop_tpdo(axis, 1)
    hardware.driver.sync()
    channel = hardware.driver.bus_options["channel"]
    with can.Bus(interface="virtual", channel=channel) as other:
        other.send(can.Message(arbitration_id=frame_id, data=payload, is_extended_id=False))
    return hardware.read()


def test_statusword_warning_bits_are_events_once_per_change() -> None:
    """Bits 7, 11 and 13 on, bits 9 and 12 off (12 only while enabled) are events, each when
    it changes, in bit order."""
    sod = cia402.statusword_for(DriveState.SWITCH_ON_DISABLED)  # remote bit set
    enabled = cia402.statusword_for(DriveState.OPERATION_ENABLED, following_target=True)
    steps = [
        (sod | 0x0080, ["x drive statusword: warning (bit 7) on"]),
        (sod | 0x0080, []),
        (sod | 0x0880, ["x drive statusword: internal limit active (bit 11) on"]),
        ((sod & ~0x0200) | 0x0800, ["x drive statusword: warning (bit 7) off",
                                    "x drive statusword: not remote (bit 9 clear) on"]),
        (sod, ["x drive statusword: not remote (bit 9 clear) off",
               "x drive statusword: internal limit active (bit 11) off"]),
        (sod | 0x2000, ["x drive statusword: following error (bit 13) on"]),
        (sod & ~0x1000, ["x drive statusword: following error (bit 13) off"]),
        (enabled, []),
        (enabled & ~0x1000, ["x drive statusword: target ignored (bit 12 clear) on"]),
        (enabled, ["x drive statusword: target ignored (bit 12 clear) off"]),
    ]
    with _inactive() as hardware:
        hardware.configure()
        hardware.read()
        for statusword, events in steps:
            reading = _read_with_tpdo(hardware, 0, struct.pack("<Hi", statusword, 1234))
            assert list(reading.events) == events, (hex(statusword), reading.events)
            assert reading.position_m[0] == 1234 * hardware.driver.settings.metres_per_count


@pytest.mark.parametrize("size", [5, 7, 0])
def test_a_tpdo1_of_the_wrong_size_is_a_fault_not_a_sample(size: int) -> None:
    """A TPDO1 that is not 6 bytes: a malformed-frame fault, and the drive's sample is
    missing."""
    with _inactive() as hardware:
        hardware.configure()
        hardware.read()
        reading = _read_with_tpdo(hardware, 1, bytes(size))
        assert f"y drive TPDO1 malformed: PDO payload of {size} bytes, expected 6" in \
            reading.faults
        assert "missing TPDO1 from the y drive (node 2)" in reading.faults
        assert np.isnan(reading.position_m[1]) and np.isfinite(reading.position_m[0])


# --- the idle heartbeat ------------------------------------------------------------------


def test_the_idle_heartbeat_beats_while_configured_and_stops_when_active() -> None:
    """Configured and waiting, a background task sends the master's heartbeat (standard id
    0x700 + its node id, operational) without any read; once active only read() sends it,
    so a loop that stalls stops the drives (their consumer). No second task is left over."""
    with _inactive() as hardware:
        driver = hardware.driver
        channel = driver.bus_options["channel"]
        master_heartbeat = HEARTBEAT_BASE + driver.settings.master_node_id
        hardware.configure()
        with can.Bus(interface="virtual", channel=channel) as listener:
            time.sleep(0.35)
            beats = [m for m in _frames(listener) if m.arbitration_id == master_heartbeat]
            assert len(beats) >= 2
            assert all(not m.is_extended_id and bytes(m.data) == b"\x05" for m in beats)
            hardware.activate()
            _frames(listener)  # what configure and activate sent
            time.sleep(0.35)
            assert [m for m in _frames(listener) if m.arbitration_id == master_heartbeat] == []


def test_a_bus_gone_under_the_idle_heartbeat_stops_it_with_one_error() -> None:
    """The bus closed under the idle heartbeat: its task notes the error once and stops
    (never an exception in a background thread)."""
    hardware = _inactive()
    driver = hardware.driver
    try:
        hardware.configure()
        driver._bus.shutdown()
        time.sleep(0.35)
        assert len(driver.idle_heartbeat_errors) == 1, driver.idle_heartbeat_errors
    finally:
        driver._bus = None
        driver._idle_heartbeat = None
        hardware.cleanup()


# --- cleanup -----------------------------------------------------------------------------


@pytest.mark.parametrize("active", [False, True])
def test_cleanup_deactivates_puts_the_drives_pre_operational_and_closes(active: bool) -> None:
    """cleanup from active: disable and shut down the drives first; from either state NMT
    pre-operational to both (their PDOs stop), the bus closed, unconfigured."""
    with _inactive() as hardware:
        hardware.configure()
        if active:
            hardware.activate()
        channel = hardware.driver.bus_options["channel"]
        with can.Bus(interface="virtual", channel=channel) as listener:
            hardware.cleanup()
            heard = _frames(listener)
        words = _rpdo_controlwords(heard, 1)
        assert words == ([cia402.CW_DISABLE_OPERATION, cia402.CW_SHUTDOWN] if active else [])
        nmt = [tuple(m.data) for m in heard if m.arbitration_id == cia402.NMT_COB_ID]
        assert nmt == [(cia402.NMT_PRE_OPERATIONAL, 1), (cia402.NMT_PRE_OPERATIONAL, 2)]
        assert hardware.lifecycle_state is LifecycleState.UNCONFIGURED
        assert hardware.driver._bus is None
        assert _nmt_states(hardware, NMT_PRE_OPERATIONAL_STATE) == [
            NMT_PRE_OPERATIONAL_STATE] * 2


@pytest.mark.parametrize("error", [can.CanError("bus off"), HardwareError("gone")])
def test_cleanup_closes_the_bus_even_when_the_drives_cannot_be_told(monkeypatch, error
                                                                    ) -> None:
    """A bus error or a hardware error while deactivating: cleanup still closes the bus and
    leaves the driver unconfigured, without raising."""
    with _active() as hardware:
        def failing() -> None:
            raise error

        monkeypatch.setattr(hardware.driver, "deactivate", failing)
        hardware.cleanup()
        assert hardware.lifecycle_state is LifecycleState.UNCONFIGURED
        assert hardware.driver._bus is None


def test_a_driver_not_configured_refuses_to_sync_or_read() -> None:
    """Before configure (even with its bus open, as inside configure) sync() and read()
    raise; nothing is sent."""
    driver, channel = _bare_driver()
    try:
        with can.Bus(interface="virtual", channel=channel) as listener:
            with pytest.raises(HardwareError, match="^sync needs a configured driver$"):
                driver.sync()
            with pytest.raises(HardwareError, match="^read needs a configured driver$"):
                driver.read()
            assert _frames(listener) == []
    finally:
        driver._close_bus()
    with pytest.raises(HardwareError, match="^sync needs a configured driver$"):
        driver.sync()
    with pytest.raises(HardwareError, match="^read needs a configured driver$"):
        driver.read()


def test_while_active_read_sends_the_masters_heartbeat_once_per_period() -> None:
    """Active, the master's heartbeat goes out from the cycle when due: once per
    ``heartbeat_period_s`` (0.1 s), never more often, however often read() runs."""
    with _active() as hardware:
        driver = hardware.driver
        master_heartbeat = HEARTBEAT_BASE + driver.settings.master_node_id
        channel = driver.bus_options["channel"]
        with can.Bus(interface="virtual", channel=channel) as listener:
            start = time.monotonic()
            while time.monotonic() - start < 0.5:
                hardware.write(np.zeros(2))
                hardware.read()
                time.sleep(0.002)
            elapsed = time.monotonic() - start
            beats = [m for m in _frames(listener) if m.arbitration_id == master_heartbeat]
        # one due time per period after the first (which may catch up a late one)
        assert 2 <= len(beats) <= elapsed / 0.1 + 2, (len(beats), elapsed)
        assert all(bytes(m.data) == b"\x05" and not m.is_extended_id for m in beats)


def test_a_plain_variable_exists_at_sub_index_0_only() -> None:
    """The plan's objects: 0x1000 is a plain variable, so 0x1000:01 does not exist (an SDO
    request for it would be aborted 0x06090011 by a drive); a record's sub-indices do."""
    from haptic.master.hardware.canopen_setup import PlanError, variable

    dictionary = can_driver.load_drive_dictionary("", 1)
    assert variable(dictionary, 0x1000, 0, "x").index == 0x1000
    assert variable(dictionary, 0x1018, 2, "x").subindex == 2
    with pytest.raises(PlanError, match=r"^x has no object 0x1000:01$"):
        variable(dictionary, 0x1000, 1, "x")
    with pytest.raises(PlanError, match=r"^x has no object 0x1018:09$"):
        variable(dictionary, 0x1018, 9, "x")
    with pytest.raises(PlanError, match=r"^x has no object 0x5FFF:00$"):
        variable(dictionary, 0x5FFF, 0, "x")


# --- supervision in read() ---------------------------------------------------------------


def _set_drive_state(hardware: SimulatedRigHardware, axis: int, state: DriveState) -> None:
    """The emulated drive goes to ``state`` by itself (no EMCY)."""
    with hardware.rig._lock:
        hardware.rig.drives[axis].state = state
        hardware.rig._discard_prepared()


def test_a_drive_in_fault_while_inactive_is_a_fault_without_a_quick_stop() -> None:
    """Inactive, a drive in Fault (or Fault reaction active) is a fault of each reading;
    nothing is commanded."""
    with _inactive() as hardware:
        hardware.configure()
        hardware.read()
        _set_drive_state(hardware, 0, DriveState.FAULT)
        channel = hardware.driver.bus_options["channel"]
        with can.Bus(interface="virtual", channel=channel) as listener:
            assert hardware.read().faults == ("x drive in fault",)
            _set_drive_state(hardware, 0, DriveState.FAULT_REACTION_ACTIVE)
            _set_drive_state(hardware, 1, DriveState.FAULT)
            assert hardware.read().faults == ("x drive in fault reaction active",
                                              "y drive in fault")
            assert _rpdo_controlwords(_frames(listener), 1) == []


@pytest.mark.parametrize("axis", [0, 1])
def test_a_drive_leaving_operation_enabled_while_active_quick_stops_both(axis: int) -> None:
    """Active and not stopped by the master, a drive out of operation enabled is a fault
    naming its state, and quick stop goes to both drives, once."""
    with _active() as hardware:
        hardware.read()
        _set_drive_state(hardware, axis, DriveState.SWITCHED_ON)
        name = "xy"[axis]
        faults = hardware.read().faults
        assert faults == (f"{name} drive left operation enabled (switched on)",
                          "quick stop on both drives: a drive fault")
        for _ in range(5):  # tripped: the drives in quick stop are no fault, nor events
            reading = hardware.read()
            assert not any("quick stop on both" in f for f in reading.faults), reading.faults
            assert reading.events == ()


def test_a_drive_in_fault_while_active_quick_stops_both() -> None:
    with _active() as hardware:
        hardware.read()
        _set_drive_state(hardware, 1, DriveState.FAULT)
        assert hardware.read().faults == ("y drive in fault",
                                          "quick stop on both drives: a drive fault")


def test_a_lost_heartbeat_is_reported_once_per_loss() -> None:
    """A drive's heartbeat missing for longer than ``heartbeat_timeout_s`` is one fault; heard
    again and lost again, it is reported again."""
    with _inactive(**{"master.can.heartbeat_timeout_s": 0.3}) as hardware:
        hardware.configure()
        driver, device = hardware.driver, hardware.rig.devices[1]

        def lost_after_silence() -> list[str]:
            driver._sdo_write(2, device.dictionary[0x1017], 0, "y drive")  # y goes quiet
            found: list[str] = []
            deadline = time.monotonic() + 1.5
            while time.monotonic() < deadline:
                found += [f for f in hardware.read().faults if "heartbeat" in f]
                time.sleep(0.01)
            driver._sdo_write(2, device.dictionary[0x1017], 50, "y drive")  # and back
            time.sleep(0.15)
            hardware.read()
            return found

        for _ in range(2):
            found = lost_after_silence()
            assert len(found) == 1, found
            match = re.fullmatch(r"no heartbeat from the y drive \(node 2\) for (\d+\.\d{3}) s "
                                 r"\(timeout 0.3 s\)", found[0])
            assert match and 0.3 <= float(match.group(1)) < 1.5, found


def test_a_lost_heartbeat_while_active_quick_stops_both() -> None:
    with _active(**{"master.can.heartbeat_timeout_s": 0.3}) as hardware:
        driver, device = hardware.driver, hardware.rig.devices[0]
        hardware.read()
        driver._sdo_write(1, device.dictionary[0x1017], 0, "x drive")  # x goes quiet
        deadline = time.monotonic() + 2.0
        while time.monotonic() < deadline:
            hardware.write(np.zeros(2))
            faults = hardware.read().faults
            if faults:
                break
            time.sleep(0.01)
        assert len(faults) == 2 and faults[0].startswith("no heartbeat from the x drive")
        assert faults[1] == "quick stop on both drives: a drive fault"


# --- the sensor frame, the command, late frames ------------------------------------------


@pytest.mark.parametrize("status", [1, 2])
def test_a_sensor_sample_not_ok_is_a_fault_and_nan(status: int) -> None:
    """A sensor frame whose status is overload (1) or invalid (2): NaN force and a fault
    naming the status; the next good frame counts on without a jump."""
    with _inactive() as hardware:
        hardware.configure()
        hardware.read()
        hardware.rig.set_sensor_status(status, 1)
        reading = hardware.read()
        assert reading.faults == (f"force sensor status {status} (not ok)",)
        assert np.isnan(reading.force_N).all()
        reading = hardware.read()
        assert reading.faults == () and np.isfinite(reading.force_N).all()


def test_the_sensor_counter_wraps_at_256_without_a_jump() -> None:
    with _inactive() as hardware:
        hardware.configure()
        for _ in range(260):
            assert hardware.read().faults == ()


def test_a_malformed_sensor_frame_is_a_fault_and_nan() -> None:
    with _inactive() as hardware:
        hardware.configure()
        hardware.read()
        hardware.rig.drop_sensor_frames(1)
        hardware.driver.sync()
        channel = hardware.driver.bus_options["channel"]
        with can.Bus(interface="virtual", channel=channel) as other:
            other.send(can.Message(arbitration_id=hardware.driver.codec.frame_id,
                                   data=b"\x01\x02", is_extended_id=False))
        reading = hardware.read()
        assert [f.startswith("force sensor frame malformed: ") for f in reading.faults] == [True]
        assert np.isnan(reading.force_N).all()


def test_a_non_finite_command_axis_keeps_its_target_and_is_reported() -> None:
    """write() with NaN on one axis sends that drive its previous target and the other its
    new one; the next reading reports the refusal. Inactive, write() sends nothing."""
    with _inactive() as hardware:
        hardware.configure()
        channel = hardware.driver.bus_options["channel"]
        with can.Bus(interface="virtual", channel=channel) as listener:
            hardware.write(np.array([0.001, 0.001]))
            assert _rpdo_controlwords(_frames(listener), 1) == []
        hardware.activate()
        hardware.read()
        per_count = hardware.driver.settings.metres_per_count
        before = [drive.target_counts for drive in hardware.rig.drives]
        with can.Bus(interface="virtual", channel=channel) as listener:
            hardware.write(np.array([math.nan, (before[1] + 30) * per_count]))
            heard = _frames(listener)
        sent = {m.arbitration_id: bytes(m.data) for m in heard}
        assert sent[cia402.RPDO1_BASE + 1] == struct.pack("<Hi", cia402.CW_ENABLE_OPERATION,
                                                          before[0])
        assert sent[cia402.RPDO1_BASE + 2] == struct.pack("<Hi", cia402.CW_ENABLE_OPERATION,
                                                          before[1] + 30)
        assert hardware.read().faults == ("non-finite position command refused",)
        hardware.write(np.array([before[0] * per_count, math.inf]))
        assert hardware.read().faults == ("non-finite position command refused",)


def test_frames_left_from_an_earlier_cycle_are_counted_and_supervision_is_kept() -> None:
    """Before its SYNC the driver drops what an earlier cycle left: a TPDO or a sensor frame
    is a late frame; an EMCY among them is still a fault of the next reading, not late."""
    with _inactive() as hardware:
        hardware.configure()
        hardware.read()
        channel = hardware.driver.bus_options["channel"]
        with can.Bus(interface="virtual", channel=channel) as other:
            for frame_id, data in ((cia402.EMCY_BASE + 2, cia402.emcy_frame(0x5530)),
                                   (cia402.TPDO1_BASE + 1, bytes(6)),
                                   (HEARTBEAT_BASE + 1, b"\x05"),
                                   (hardware.driver.codec.frame_id, bytes(8))):
                other.send(can.Message(arbitration_id=frame_id, data=data,
                                       is_extended_id=False))
        reading = hardware.read()
        assert hardware.driver.late_frames == 2
        assert reading.faults == ("y drive EMCY error code 0x5530 (register 0x01)",)
        assert hardware.driver.emcy_log == [("y", 0x5530)]


def test_a_heartbeat_in_another_state_while_active_quick_stops_both() -> None:
    with _active() as hardware:
        hardware.read()
        faults = _faults_after(hardware, [(HEARTBEAT_BASE + 1, b"\x7f")])
        assert faults == ("x drive heartbeat reports NMT state pre-operational, not operational",
                          "quick stop on both drives: a drive fault")


def test_on_can_fd_only_the_cycles_frames_are_fd() -> None:
    """On CAN FD the SYNC and the RPDOs go as FD frames (bit-rate switch); NMT, SDO and the
    master's heartbeat stay classical (devices that speak FD for PDOs only still hear
    them); an extra frame is standard unless asked for extended."""
    with _inactive(**{"master.can.fd": True}) as hardware:
        channel = hardware.driver.bus_options["channel"]
        with can.Bus(interface="virtual", channel=channel) as listener:
            hardware.configure()
            hardware.activate()
            for _ in range(3):
                hardware.write(np.zeros(2))
                hardware.read()
            hardware.driver.send_frame(0x321, b"\x01")
            heard = _frames(listener)
        mine = [m for m in heard if m.arbitration_id in (
            cia402.NMT_COB_ID, cia402.SYNC_COB_ID, HEARTBEAT_BASE + 127, 0x201, 0x202, 0x601,
            0x602, 0x321)]
        classical = {cia402.NMT_COB_ID, HEARTBEAT_BASE + 127, 0x601, 0x602, 0x321}
        assert {m.arbitration_id for m in mine} == classical | {cia402.SYNC_COB_ID, 0x201,
                                                                0x202}
        for message in mine:
            fd = message.arbitration_id not in classical
            assert (message.is_fd, message.bitrate_switch) == (fd, fd), message
            assert not message.is_extended_id


@pytest.mark.parametrize("axis", [0, 1])
def test_sensor_counts_that_scale_beyond_a_float_are_a_fault_and_nan(axis: int) -> None:
    """An offset or scale so large that a valid sample is not finite in N (a configuration
    error the key limits let through): a fault naming the keys, and both channels NaN."""
    with _inactive() as hardware:
        hardware.configure()
        hardware.read()
        offset = [0.0, 0.0]
        offset[axis] = -1.7e308
        hardware.driver.codec = ForceSensorCodec((10.0, 10.0), tuple(offset), load_database())
        reading = hardware.read()
        assert len(reading.faults) == 1 and re.fullmatch(
            r"force sensor counts \(-?\d+, -?\d+\) are not finite in N: see \[master.can\] "
            r"force_scale_N_per_count and force_offset_count", reading.faults[0]), reading.faults
        assert np.isnan(reading.force_N).all()


def test_a_following_error_window_beyond_32_bits_is_written_as_the_largest() -> None:
    """0x6065 is UNSIGNED32: a window (m) beyond it in counts is written as 0xFFFFFFFF (off,
    for CiA 402 drives), not refused by the EDS's encoding."""
    for window_m, expected in ((1e4, 0xFFFFFFFF), (0.01, None)):
        driver = _plans_of(**{"master.can.following_error_window_m": window_m})
        steps = {(step.variable.index, step.variable.subindex): step.value
                 for step in driver._plans()[0][1]}
        settings = driver.settings
        assert steps[(0x6065, 0)] == (expected if expected is not None else round(
            window_m / settings.metres_per_count))


def _transition_then(state_after_reset, late: bool):
    """cia402.next_drive_state for a drive whose fault reset leads to ``state_after_reset``,
    at once or (``late``) one SYNC later, whatever that SYNC's controlword."""
    transition = cia402.next_drive_state
    pending = [False]

    def patched(state, controlword, previous):
        if state is DriveState.FAULT and pending[0]:
            pending[0] = False
            return state_after_reset
        if state is DriveState.FAULT and controlword & 0x80 and not previous & 0x80:
            if late:
                pending[0] = True
                return DriveState.FAULT
            return state_after_reset
        return transition(state, controlword, previous)

    return patched


def test_a_fault_reset_that_completes_one_sync_late_is_no_unexpected_transition(
        monkeypatch) -> None:
    """A drive that leaves Fault only at the SYNC after its reset, while the driver already
    sends disable voltage (to take bit 7 low for a second reset): that step into switch on
    disabled is expected, and the drive is enabled after one reset."""
    monkeypatch.setattr(cia402, "next_drive_state",
                        _transition_then(DriveState.SWITCH_ON_DISABLED, late=True))
    with _inactive() as hardware:
        hardware.configure()
        hardware.rig.inject_drive_fault(0, 0x2310)
        hardware.read()
        channel = hardware.driver.bus_options["channel"]
        with can.Bus(interface="virtual", channel=channel) as listener:
            hardware.activate()
            words = _rpdo_controlwords(_frames(listener), 1)
        assert hardware.driver.drive_states == (DriveState.OPERATION_ENABLED,) * 2
        assert words[:3] == [cia402.CW_FAULT_RESET, cia402.CW_DISABLE_VOLTAGE,
                             cia402.CW_SHUTDOWN]


def test_a_fault_reset_into_another_state_than_switch_on_disabled_stops_activation(
        monkeypatch) -> None:
    """A fault reset that lands anywhere but switch on disabled is an unexpected transition
    (the exception for a late reset is for disable voltage only)."""
    monkeypatch.setattr(cia402, "next_drive_state",
                        _transition_then(DriveState.READY_TO_SWITCH_ON, late=False))
    with _inactive() as hardware:
        hardware.configure()
        hardware.rig.inject_drive_fault(1, 0x2310)
        hardware.read()
        with pytest.raises(HardwareError, match=r"^activation stopped: y drive went from fault "
                           r"to ready to switch on on controlword 0x0080 \("):
            hardware.activate()


def test_the_targets_follow_the_actual_positions_until_both_drives_are_enabled(
        monkeypatch) -> None:
    """A handle that moves while the drives are being enabled (pushed on a backdrivable
    screw): each step's RPDO carries the position last read, so no drive is enabled with a
    stale target."""
    with _inactive() as hardware:
        hardware.configure()
        rig = hardware.rig
        counts = rig._position_counts
        calls = [0]

        def drifting(axis: int, sample=None) -> int:
            calls[0] += axis == 0
            return counts(axis, sample) + (100 * calls[0] if axis == 0 else 0)

        monkeypatch.setattr(rig, "_position_counts", drifting)
        channel = hardware.driver.bus_options["channel"]
        with can.Bus(interface="virtual", channel=channel) as listener:
            hardware.activate()
            targets = [struct.unpack("<Hi", bytes(m.data))[1] for m in _frames(listener)
                       if m.arbitration_id == cia402.RPDO1_BASE + 1]
        assert len(targets) >= 3 and len(set(targets)) == len(targets), targets


class _SilentBus:
    """A bus on which nothing answers, with its own clock: each receive waits exactly its
    timeout (s) of that clock."""

    def __init__(self) -> None:
        self.now_s = 100.0
        self.sent: list[bytes] = []
        self.waits_s: list[float] = []

    def monotonic(self) -> float:
        return self.now_s

    def recv(self, timeout: float) -> None:
        self.waits_s.append(timeout)
        self.now_s += timeout

    def send(self, message: can.Message) -> None:
        self.sent.append(bytes(message.data))


@pytest.mark.parametrize(("deadline_s", "requests"), [(0.2, 1), (0.6, 3), (0.5, 2)])
def test_an_sdo_exchange_waits_no_longer_than_its_deadline(monkeypatch, deadline_s: float,
                                                           requests: int) -> None:
    """With nothing answering, the exchange waits until its deadline exactly, never beyond
    it (not until a resend due later), sending the request again every SDO_RESEND_S (0.25 s)
    before it."""
    bus = _SilentBus()
    monkeypatch.setattr(can_driver, "time", bus)  # the driver's clock is the bus's
    driver = CanHandleDriver(master_settings(load_config()).can,
                             {"interface": "virtual", "channel": "unused"},
                             deadline_s / 200, 0.00054)  # enable_timeout_cycles = 200
    driver._bus = bus
    dictionary = can_driver.load_drive_dictionary("", 1)
    start = bus.now_s
    with pytest.raises(HardwareError, match=r"^x: no SDO reply from node 1 for 0x1017:00"):
        driver._sdo_exchange(1, cia402.sdo_upload_request(dictionary[0x1017]),
                             dictionary[0x1017], "x")
    assert bus.now_s - start == pytest.approx(deadline_s, abs=1e-9)
    assert len(bus.sent) == requests and driver.sdo_resends == requests - 1


def test_a_frame_of_an_unknown_id_in_the_cycle_is_ignored() -> None:
    """A stranger's frame (any id the driver does not know, TPDO-sized) while the driver
    collects its cycle is neither a sample nor a fault: the drive whose TPDO is missing
    stays missing."""
    with _inactive() as hardware:
        hardware.configure()
        hardware.read()
        for frame_id in (0x123, 0x183, cia402.TPDO1_BASE + 5):
            reading = _read_with_tpdo_id(hardware, 0, frame_id, struct.pack("<Hi", 0x0237, 77))
            assert reading.faults == ("missing TPDO1 from the x drive (node 1)",)
            assert np.isnan(reading.position_m[0]) and np.isfinite(reading.position_m[1])


@pytest.mark.parametrize("fd", [False, True])
def test_the_can_backend_opens_the_configured_bus(fd: bool) -> None:
    """``haptic-master --rig can``: the bus named by ``[master.can]`` (interface, channel,
    bit rate; on CAN FD also ``fd`` and the data bit rate), the configured PDO timeout and Ts,
    and the bus-load line announced."""
    config = override(load_config(), "master.can.interface", "virtual")
    config = override(config, "master.can.channel", "rig0")
    config = override(config, "master.can.fd", fd)
    driver = create_hardware("can", config)
    settings = master_settings(config).can
    expected = {"interface": "virtual", "channel": "rig0", "bitrate": settings.bitrate}
    if fd:
        expected.update(fd=True, data_bitrate=settings.data_bitrate)
    assert driver.bus_options == expected
    assert driver.pdo_timeout_s == settings.pdo_timeout_s
    assert driver.sample_period_s == config["model"]["sample_period_s"]
    assert driver.announce_bus_load is True
