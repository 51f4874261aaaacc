"""The CAN driver at unit level, from configure to cleanup: what a new driver starts from,
the NMT sequence and its failures, the EDS, each drive's identity and written objects, the
enable sequence with its faults and resets, deactivate, the idle heartbeat and cleanup,
against the in-process emulated rig (python-can's virtual bus)."""

from __future__ import annotations

import dataclasses
import importlib.resources
import re
import struct
import time

import can
import pytest

from haptic.common.config import load_config, override
from haptic.master.hardware import cia402, drive_commissioning
from haptic.master.hardware.bus_load import bus_load, cycle_frames
from haptic.master.hardware.can_driver import CanHandleDriver
from haptic.master.hardware.cia402 import DriveState
from haptic.master.hardware.drive_device import load_drive_dictionary, packaged_eds_path
from haptic.master.hardware.interface import HardwareError, LifecycleState, create_hardware
from haptic.master.settings import master_settings
from haptic.master.simulated_rig.can_devices import NMT_PRE_OPERATIONAL_STATE, SimulatedRigHardware
from tests.master.hardware.can_driver_helpers import (
    HEARTBEAT_BASE,
    active_rig,
    answering,
    bare_driver,
    frames_heard,
    inactive_rig,
    plans_of,
    rpdo_controlwords,
    sdo_downloads,
    set_object,
)

# --- what a new driver starts from, and what it sends at configure -----------------------


def test_a_new_driver_has_counted_nothing_and_its_first_cycle_is_1() -> None:
    """Before configure nothing is counted; configure's first reading is cycle 1, and its
    SYNC carries counter 1, again after a cleanup and a second configure."""
    hardware = inactive_rig()
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
            syncs = [m.data for m in frames_heard(listener)
                     if m.arbitration_id == cia402.SYNC_COB_ID]
            assert syncs[0] == b"\x01", syncs
            hardware.cleanup()


def test_the_masters_heartbeat_reports_operational() -> None:
    """The master's heartbeat (0x700 + its node id) carries NMT state 0x05, configured and
    active."""
    with inactive_rig() as hardware:
        channel = hardware.driver.bus_options["channel"]
        master_heartbeat = HEARTBEAT_BASE + hardware.driver.settings.master_node_id
        with can.Bus(interface="virtual", channel=channel) as listener:
            hardware.configure()
            hardware.activate()
            for _ in range(3):
                hardware.read()
            beats = [bytes(m.data) for m in frames_heard(listener)
                     if m.arbitration_id == master_heartbeat]
        assert beats and set(beats) == {b"\x05"}, beats


def test_the_drive_states_are_per_axis() -> None:
    """``drive_states`` is (x, y): a fault of the y drive shows in the second place only."""
    with inactive_rig() as hardware:
        hardware.configure()
        hardware.rig.inject_drive_fault(1, 0x2310)
        hardware.read()
        x_state, y_state = hardware.driver.drive_states
        assert y_state is DriveState.FAULT and x_state is not DriveState.FAULT


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
    with inactive_rig() as hardware:
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

    hardware = inactive_rig()
    monkeypatch.setattr(can, "Bus", refuse)
    with pytest.raises(HardwareError, match=r"^cannot open the CAN bus \(interface=virtual, "
                       r"channel=test-[0-9a-f]+\): " + str(error)):
        hardware.driver.configure()
    assert hardware.driver.lifecycle_state is LifecycleState.UNCONFIGURED


# --- configure's NMT sequence and its failures -------------------------------------------


def test_configure_puts_the_drives_pre_operational_first_and_starts_them_last() -> None:
    """NMT pre-operational to both drives before the first SDO request (a drive left
    operational by an earlier master stops its PDOs while it is configured), NMT start to
    both after the last."""
    with inactive_rig() as hardware:
        channel = hardware.driver.bus_options["channel"]
        nodes = hardware.driver.settings.node_ids
        with can.Bus(interface="virtual", channel=channel) as listener:
            hardware.configure()
            heard = frames_heard(listener)
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
    with inactive_rig() as hardware:
        hardware.rig.drop_tpdo(0, 10**6)
        with pytest.raises(HardwareError, match=r"^no position from the drives after start: "
                           r"missing TPDO1 from the x drive \(node 1\)"):
            hardware.configure()
        assert hardware.lifecycle_state is LifecycleState.UNCONFIGURED
        assert hardware.driver.frames.bus is None
        assert _nmt_states(hardware, NMT_PRE_OPERATIONAL_STATE) == [
            NMT_PRE_OPERATIONAL_STATE] * 2


@pytest.mark.parametrize("kind", [OSError, can.CanError])
def test_a_bus_gone_while_configure_fails_keeps_the_first_error(monkeypatch, kind) -> None:
    """When the NMT commands of the failure path cannot be sent either, configure raises the
    error that stopped it, not the later one, and closes the bus."""
    hardware = inactive_rig()
    driver = hardware.driver
    failures = iter(("first", "second", "third"))

    def broken_nmt(_command: int, _node: int) -> None:
        raise kind(next(failures))

    monkeypatch.setattr(driver, "_nmt", broken_nmt)
    try:
        with pytest.raises(kind, match="^first$"):
            driver.configure()
        assert driver.frames.bus is None
        assert driver.lifecycle_state is LifecycleState.UNCONFIGURED
    finally:
        hardware.cleanup()


@pytest.mark.parametrize("axis", [0, 1])
def test_a_drive_silent_from_the_start_is_reported_once(monkeypatch, axis: int) -> None:
    """A drive that never sends a heartbeat is a fault once its timeout has passed after
    configure, reported once; the other drive's heartbeat keeps it quiet."""
    with inactive_rig(**{"master.can.heartbeat_timeout_s": 0.3}) as hardware:
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

    monkeypatch.setattr(drive_commissioning, "load_drive_dictionary", broken)
    driver = CanHandleDriver(master_settings(load_config()).can,
                             {"interface": "virtual", "channel": "unused"}, 0.01, 0.00054)
    with pytest.raises(HardwareError, match=r"^cannot read the x drive's EDS \(packaged\): "):
        driver.configure()
    assert driver.frames.bus is None


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
    with inactive_rig() as hardware:
        hardware.configure()
        settings = hardware.driver.settings
        expected = round(settings.following_error_window_m / settings.metres_per_count)
        assert expected > 1
        assert [d.following_error_window_counts for d in hardware.rig.devices] == [expected] * 2


# --- configure's identity check and activate ---------------------------------------------


def test_configure_reads_each_drives_identity() -> None:
    """``identities`` holds each drive's 0x1000 and 0x1018:1-4, as the drive answers them."""
    with inactive_rig() as hardware:
        for axis, device in enumerate(hardware.rig.devices):
            set_object(device, 0x1018, 4, 0x5E000 + axis)  # a serial number of its own
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
    with inactive_rig() as hardware:
        set_object(hardware.rig.devices[1], 0x1000, 0, 0x00020191)
        assert _configure_error(hardware) == ("y drive (node 2) is not a CiA 402 drive (0x1000 "
                                              "device type 0x00020191)")
    with inactive_rig() as hardware:
        set_object(hardware.rig.devices[1], 0x1000, 0, 0x00FF0192)
        hardware.configure()
        assert hardware.driver.identities[1]["device_type"] == 0x00FF0192


def test_a_drive_with_another_vendor_or_product_than_its_eds_is_refused(tmp_path) -> None:
    """The vendor and product code the drive reports must be its EDS's, where the EDS gives
    them (a vendor number 0 is not checked)."""
    with inactive_rig() as hardware:
        set_object(hardware.rig.devices[0], 0x1018, 2, 0x4C03)
        assert _configure_error(hardware) == (
            "x drive (node 1) reports product_code 0x00004C03, its EDS describes 0x00004C02: "
            "another device or EDS")
    with inactive_rig() as hardware:
        set_object(hardware.rig.devices[0], 0x1018, 1, 0xAB)  # the EDS's vendor is 0
        hardware.configure()
    eds = packaged_eds_path().read_text().replace("VendorNumber=0x00000000",
                                                  "VendorNumber=0x000000AB")
    path = tmp_path / "vendor.eds"
    path.write_text(eds)
    overrides = {"master.can.x_eds_file": str(path), "master.can.y_eds_file": str(path)}
    with inactive_rig(**overrides) as hardware:
        for device in hardware.rig.devices:
            set_object(device, 0x1018, 1, 0xAB)
        hardware.configure()
        assert [i["vendor_id"] for i in hardware.driver.identities] == [0xAB, 0xAB]
    with inactive_rig(**overrides) as hardware:
        set_object(hardware.rig.devices[0], 0x1018, 1, 0xAB)
        set_object(hardware.rig.devices[1], 0x1018, 1, 0xAC)
        assert _configure_error(hardware) == (
            "y drive (node 2) reports vendor_id 0x000000AC, its EDS describes 0x000000AB: "
            "another device or EDS")


def test_a_write_that_does_not_read_back_or_a_mode_not_8_is_refused() -> None:
    """Every configuration write is read back; a drive that keeps another value, or reports
    a mode other than cyclic synchronous position, fails configure naming it."""
    with inactive_rig() as hardware:
        answering(hardware.rig.devices[0], 0x1017, 7)
        message = _configure_error(hardware)
        assert re.fullmatch(r"x drive \(node 1\): .* reads back 7 after writing \d+", message), (
            message)
    with inactive_rig() as hardware:
        answering(hardware.rig.devices[1], 0x6061, 1)
        assert _configure_error(hardware) == ("y drive (node 2) reports mode 1, not cyclic "
                                              "synchronous position (8)")


def test_activate_sets_each_drives_target_to_its_actual_position_first() -> None:
    """Before the enable sequence, 0x607A of each drive is written by SDO with its actual
    position (the sequence never moves the handle)."""
    with inactive_rig() as hardware:
        hardware.configure()
        channel = hardware.driver.bus_options["channel"]
        with can.Bus(interface="virtual", channel=channel) as listener:
            hardware.activate()
            heard = frames_heard(listener)
        positions = [drive.position_counts for drive in hardware.rig.drives]
        nodes = hardware.driver.settings.node_ids
        assert sdo_downloads(heard, 0x607A) == list(zip(nodes, positions, strict=True))


def test_activate_without_positions_is_refused_and_the_idle_heartbeat_goes_on() -> None:
    """No TPDO1 at activate: a HardwareError with the reading's faults; the driver stays
    inactive and its heartbeat goes on from the idle task."""
    with inactive_rig() as hardware:
        hardware.configure()
        hardware.rig.drop_tpdo(1, 10**6)
        with pytest.raises(HardwareError, match=r"^cannot activate without positions: missing "
                           r"TPDO1 from the y drive \(node 2\)"):
            hardware.activate()
        assert hardware.lifecycle_state is LifecycleState.INACTIVE
        assert hardware.driver.heartbeats.idle_task is not None


def test_a_drive_faulted_once_is_reset_once_and_one_faulting_again_stops_activation() -> None:
    """One fault before activate: one fault reset, then enabled. A fault that comes back
    after its reset: activation stops at the transition into it, naming it."""
    with inactive_rig() as hardware:
        hardware.configure()
        hardware.rig.inject_drive_fault(1, 0x2310)
        hardware.read()
        hardware.activate()
        assert hardware.driver.drive_states == (DriveState.OPERATION_ENABLED,) * 2
    with inactive_rig() as hardware:
        hardware.configure()
        hardware.rig.inject_drive_fault(0, 0x7305, persistent=True)
        hardware.read()
        with pytest.raises(HardwareError, match=r"^activation stopped: x drive went from switch "
                           r"on disabled to fault on controlword 0x0006 \(x: fault, y: [a-z ]+; "
                           r"EMCY x 0x7305\)$"):
            hardware.activate()
        assert hardware.lifecycle_state is LifecycleState.INACTIVE
        assert hardware.driver.heartbeats.idle_task is not None


@pytest.mark.parametrize("axis", [0, 1])
def test_a_drive_that_stays_in_fault_gets_two_resets_then_activation_stops(monkeypatch,
                                                                           axis: int) -> None:
    """A fault whose cause persists keeps the drive in Fault through a fault reset: the
    driver resets it twice (each on a rising edge of bit 7), then stops."""
    transition = cia402.next_drive_state

    def fault_stays(state, controlword, previous):
        return state if state is DriveState.FAULT else transition(state, controlword, previous)

    monkeypatch.setattr(cia402, "next_drive_state", fault_stays)
    with inactive_rig() as hardware:
        hardware.configure()
        hardware.rig.inject_drive_fault(axis, 0x7305)
        hardware.read()
        channel = hardware.driver.bus_options["channel"]
        with can.Bus(interface="virtual", channel=channel) as listener:
            with pytest.raises(HardwareError, match=r"^activation stopped: a drive faulted "
                               r"again after its fault reset \(x: "):
                hardware.activate()
            heard = frames_heard(listener)
        assert hardware.driver.drive_states[axis] is DriveState.FAULT
        words = rpdo_controlwords(heard, axis + 1)
        assert words.count(cia402.CW_FAULT_RESET) == 2, [hex(w) for w in words]
        first = words.index(cia402.CW_FAULT_RESET)
        assert words[first + 1] == cia402.CW_DISABLE_VOLTAGE  # bit 7 low before the next
        assert words[-1] == cia402.CW_DISABLE_VOLTAGE  # both shut down at the stop
        monkeypatch.undo()  # the cause is gone: the next activate resets it at once
        with can.Bus(interface="virtual", channel=channel) as listener:
            hardware.activate()
            words = rpdo_controlwords(frames_heard(listener), axis + 1)
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
    with inactive_rig() as hardware:
        hardware.configure()
        driver = hardware.driver
        if y_faulted_first:
            hardware.rig.inject_drive_fault(1, 0x2310)
            hardware.read()
        send_rpdo = driver.pdos.send_rpdo
        sent: list[tuple[int, int]] = []

        def fault_y_at_a_step(axis: int, controlword: int) -> None:
            sent.append((axis, controlword))
            send_rpdo(axis, controlword)
            if sum(a == 1 for a, _ in sent) == fault_after:
                hardware.rig.inject_drive_fault(1, 0x5530)

        monkeypatch.setattr(driver.pdos, "send_rpdo", fault_y_at_a_step)
        with pytest.raises(HardwareError, match=rf"^activation stopped: y drive went from "
                           rf"{named} \("):
            hardware.activate()
        assert hardware.lifecycle_state is LifecycleState.INACTIVE
        if y_faulted_first:
            assert hardware.driver.drive_states[0] is DriveState.OPERATION_ENABLED


# --- deactivate and cleanup --------------------------------------------------------------


@pytest.mark.parametrize("tripped", [False, True])
def test_deactivate_disables_then_shuts_down_and_the_idle_heartbeat_resumes(tripped: bool
                                                                           ) -> None:
    """From operation enabled: disable operation (from quick stop: disable voltage, as
    disable operation is no transition there), then shutdown; the driver is inactive and
    its idle heartbeat runs. Inactive, deactivate sends nothing."""
    with inactive_rig() as hardware:
        hardware.configure()
        hardware.deactivate()  # inactive: nothing
        hardware.activate()
        if tripped:
            hardware.stop_motion("test")
            hardware.read()
        channel = hardware.driver.bus_options["channel"]
        with can.Bus(interface="virtual", channel=channel) as listener:
            hardware.deactivate()
            heard = frames_heard(listener)
            hardware.deactivate()  # inactive now: nothing more
            assert rpdo_controlwords(frames_heard(listener), 1) == []
        first = cia402.CW_DISABLE_VOLTAGE if tripped else cia402.CW_DISABLE_OPERATION
        for node in (1, 2):
            assert rpdo_controlwords(heard, node) == [first, cia402.CW_SHUTDOWN]
        assert hardware.lifecycle_state is LifecycleState.INACTIVE
        assert hardware.driver.heartbeats.idle_task is not None
        assert hardware.driver.drive_states == (DriveState.READY_TO_SWITCH_ON,) * 2


# --- the idle heartbeat ------------------------------------------------------------------


def test_the_idle_heartbeat_beats_while_configured_and_stops_when_active() -> None:
    """Configured and waiting, a background task sends the master's heartbeat (standard id
    0x700 + its node id, operational) without any read; once active only read() sends it,
    so a loop that stalls stops the drives (their consumer). No second task is left over."""
    with inactive_rig() as hardware:
        driver = hardware.driver
        channel = driver.bus_options["channel"]
        master_heartbeat = HEARTBEAT_BASE + driver.settings.master_node_id
        hardware.configure()
        with can.Bus(interface="virtual", channel=channel) as listener:
            time.sleep(0.35)
            beats = [m for m in frames_heard(listener) if m.arbitration_id == master_heartbeat]
            assert len(beats) >= 2
            assert all(not m.is_extended_id and bytes(m.data) == b"\x05" for m in beats)
            hardware.activate()
            frames_heard(listener)  # what configure and activate sent
            time.sleep(0.35)
            assert [m for m in frames_heard(listener) if m.arbitration_id == master_heartbeat] == []


def test_a_bus_gone_under_the_idle_heartbeat_stops_it_with_one_error() -> None:
    """The bus closed under the idle heartbeat: its task notes the error once and stops
    (never an exception in a background thread)."""
    hardware = inactive_rig()
    driver = hardware.driver
    try:
        hardware.configure()
        driver.frames.bus.shutdown()
        time.sleep(0.35)
        assert len(driver.idle_heartbeat_errors) == 1, driver.idle_heartbeat_errors
    finally:
        driver.frames.bus = None
        driver.heartbeats.idle_task = None
        hardware.cleanup()


# --- cleanup -----------------------------------------------------------------------------


@pytest.mark.parametrize("active", [False, True])
def test_cleanup_deactivates_puts_the_drives_pre_operational_and_closes(active: bool) -> None:
    """cleanup from active: disable and shut down the drives first; from either state NMT
    pre-operational to both (their PDOs stop), the bus closed, unconfigured."""
    with inactive_rig() as hardware:
        hardware.configure()
        if active:
            hardware.activate()
        channel = hardware.driver.bus_options["channel"]
        with can.Bus(interface="virtual", channel=channel) as listener:
            hardware.cleanup()
            heard = frames_heard(listener)
        words = rpdo_controlwords(heard, 1)
        assert words == ([cia402.CW_DISABLE_OPERATION, cia402.CW_SHUTDOWN] if active else [])
        nmt = [tuple(m.data) for m in heard if m.arbitration_id == cia402.NMT_COB_ID]
        assert nmt == [(cia402.NMT_PRE_OPERATIONAL, 1), (cia402.NMT_PRE_OPERATIONAL, 2)]
        assert hardware.lifecycle_state is LifecycleState.UNCONFIGURED
        assert hardware.driver.frames.bus is None
        assert _nmt_states(hardware, NMT_PRE_OPERATIONAL_STATE) == [
            NMT_PRE_OPERATIONAL_STATE] * 2


@pytest.mark.parametrize("error", [can.CanError("bus off"), HardwareError("gone")])
def test_cleanup_closes_the_bus_even_when_the_drives_cannot_be_told(monkeypatch, error
                                                                    ) -> None:
    """A bus error or a hardware error while deactivating: cleanup still closes the bus and
    leaves the driver unconfigured, without raising."""
    with active_rig() as hardware:
        def failing() -> None:
            raise error

        monkeypatch.setattr(hardware.driver, "deactivate", failing)
        hardware.cleanup()
        assert hardware.lifecycle_state is LifecycleState.UNCONFIGURED
        assert hardware.driver.frames.bus is None


def test_a_driver_not_configured_refuses_to_sync_or_read() -> None:
    """Before configure (even with its bus open, as inside configure) sync() and read()
    raise; nothing is sent."""
    driver, channel = bare_driver()
    try:
        with can.Bus(interface="virtual", channel=channel) as listener:
            with pytest.raises(HardwareError, match="^sync needs a configured driver$"):
                driver.sync()
            with pytest.raises(HardwareError, match="^read needs a configured driver$"):
                driver.read()
            assert frames_heard(listener) == []
    finally:
        driver._close_bus()
    with pytest.raises(HardwareError, match="^sync needs a configured driver$"):
        driver.sync()
    with pytest.raises(HardwareError, match="^read needs a configured driver$"):
        driver.read()


def test_a_plain_variable_exists_at_sub_index_0_only() -> None:
    """The plan's objects: 0x1000 is a plain variable, so 0x1000:01 does not exist (an SDO
    request for it would be aborted 0x06090011 by a drive); a record's sub-indices do."""
    from haptic.master.hardware.canopen_setup import PlanError, variable

    dictionary = load_drive_dictionary("", 1)
    assert variable(dictionary, 0x1000, 0, "x").index == 0x1000
    assert variable(dictionary, 0x1018, 2, "x").subindex == 2
    with pytest.raises(PlanError, match=r"^x has no object 0x1000:01$"):
        variable(dictionary, 0x1000, 1, "x")
    with pytest.raises(PlanError, match=r"^x has no object 0x1018:09$"):
        variable(dictionary, 0x1018, 9, "x")
    with pytest.raises(PlanError, match=r"^x has no object 0x5FFF:00$"):
        variable(dictionary, 0x5FFF, 0, "x")


def test_a_following_error_window_beyond_32_bits_is_written_as_the_largest() -> None:
    """0x6065 is UNSIGNED32: a window (m) beyond it in counts is written as 0xFFFFFFFF (off,
    for CiA 402 drives), not refused by the EDS's encoding."""
    for window_m, expected in ((1e4, 0xFFFFFFFF), (0.01, None)):
        driver = plans_of(**{"master.can.following_error_window_m": window_m})
        steps = {(step.variable.index, step.variable.subindex): step.value
                 for step in driver._plans()[0].steps}
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
    with inactive_rig() as hardware:
        hardware.configure()
        hardware.rig.inject_drive_fault(0, 0x2310)
        hardware.read()
        channel = hardware.driver.bus_options["channel"]
        with can.Bus(interface="virtual", channel=channel) as listener:
            hardware.activate()
            words = rpdo_controlwords(frames_heard(listener), 1)
        assert hardware.driver.drive_states == (DriveState.OPERATION_ENABLED,) * 2
        assert words[:3] == [cia402.CW_FAULT_RESET, cia402.CW_DISABLE_VOLTAGE,
                             cia402.CW_SHUTDOWN]


def test_a_fault_reset_into_another_state_than_switch_on_disabled_stops_activation(
        monkeypatch) -> None:
    """A fault reset that lands anywhere but switch on disabled is an unexpected transition
    (the exception for a late reset is for disable voltage only)."""
    monkeypatch.setattr(cia402, "next_drive_state",
                        _transition_then(DriveState.READY_TO_SWITCH_ON, late=False))
    with inactive_rig() as hardware:
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
    with inactive_rig() as hardware:
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
            targets = [struct.unpack("<Hi", bytes(m.data))[1] for m in frames_heard(listener)
                       if m.arbitration_id == cia402.RPDO1_BASE + 1]
        assert len(targets) >= 3 and len(set(targets)) == len(targets), targets


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
