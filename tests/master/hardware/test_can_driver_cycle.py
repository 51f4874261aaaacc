"""The CAN driver's cycle at unit level: the SYNC and its counter, the command's range,
the exact fault text of each EMCY, heartbeat and sensor frame a drive or a stranger on the
bus may send, supervision in read(), the master's own quick stop and resume, and frames that
are not the cycle's, against the in-process emulated rig with a second bus member where the
rig cannot produce the frames."""

from __future__ import annotations

import math
import re
import struct
import time
import uuid

import can
import numpy as np
import pytest

from haptic.common.config import load_config, override
from haptic.master.hardware import cia402
from haptic.master.hardware.cia402 import DriveState
from haptic.master.hardware.drive_device import packaged_eds_path
from haptic.master.hardware.force_sensor import ForceSensorCodec, load_database
from haptic.master.hardware.interface import create_hardware
from tests.master.hardware.can_driver_helpers import (
    HEARTBEAT_BASE,
    active_rig,
    bare_driver,
    faults_after,
    frames_heard,
    inactive_rig,
    plans_of,
    read_with_tpdo,
    read_with_tpdo_id,
    rpdo_controlwords,
    set_drive_state,
)


def test_an_emcy_names_its_axis_code_register_and_known_meaning() -> None:
    """``<axis> drive EMCY error code 0xCODE (register 0xRR; meaning)``, the meaning only for
    the codes the loop knows; the drives are quick-stopped and the EMCY logged."""
    with active_rig() as hardware:
        hardware.read()
        faults = faults_after(hardware, [(cia402.EMCY_BASE + 2, cia402.emcy_frame(0x8611, 0x81)),
                                          (cia402.EMCY_BASE + 1, cia402.emcy_frame(0x5530))])
        assert "y drive EMCY error code 0x8611 (register 0x81; following error)" in faults
        assert "x drive EMCY error code 0x5530 (register 0x01)" in faults
        assert "quick stop on both drives: a drive fault" in faults
        assert hardware.driver.emcy_log[-2:] == [("y", 0x8611), ("x", 0x5530)]


def test_an_emcy_error_reset_is_no_fault_and_a_short_one_is_malformed() -> None:
    """Code 0 (error reset) is neither a fault nor logged; an EMCY under 3 bytes is a
    malformed-frame fault of its axis."""
    with active_rig() as hardware:
        hardware.read()
        faults = faults_after(hardware, [(cia402.EMCY_BASE + 1, cia402.emcy_frame(0))])
        assert faults == () and hardware.driver.emcy_log == []
        faults = faults_after(hardware, [(cia402.EMCY_BASE + 2, b"\x11\x22")])
        assert any(f.startswith("y drive EMCY malformed: ") for f in faults), faults
        assert hardware.driver.emcy_log == []


@pytest.mark.parametrize(("payload", "named"), [
    (b"\x7f", "pre-operational"), (b"\x04", "stopped"), (b"\x00", "boot-up"),
    (b"\x42", "0x42"), (b"", "-0x1")])
def test_a_heartbeat_in_another_nmt_state_is_a_fault_naming_it(payload, named) -> None:
    """A drive's heartbeat reporting anything but operational (0x05) is a fault naming the
    state (an unknown state in hex, an empty payload as -0x1)."""
    with active_rig() as hardware:
        hardware.read()
        faults = faults_after(hardware, [(HEARTBEAT_BASE + 1, payload)])
        assert f"x drive heartbeat reports NMT state {named}, not operational" in faults


def test_an_operational_heartbeat_from_a_stranger_is_no_fault() -> None:
    """An operational heartbeat is the healthy case, whoever sends it."""
    with active_rig() as hardware:
        hardware.read()
        assert faults_after(hardware, [(HEARTBEAT_BASE + 2, b"\x05")]) == ()


def test_a_lost_sensor_frame_then_its_counter_jump_are_reported() -> None:
    """A missing sensor frame is a fault of its cycle; the next frame's counter, two ahead,
    is a jump ``from N to N+2``."""
    with active_rig() as hardware:
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


@pytest.mark.parametrize(("code", "meaning"), [
    (0x8130, "heartbeat or life guard lost"), (0x8210, "PDO shorter than mapped"),
    (0x8220, "PDO longer than mapped"),
    (0x8240, "unexpected SYNC data length: the drive's 0x1019 does not match the SYNC counter"),
    (0x8250, "RPDO deadline missed"), (0x8611, "following error")])
def test_each_known_emcy_code_is_named_with_its_meaning(code: int, meaning: str) -> None:
    """The CiA 301/402 EMCY codes the loop meets (CiA 301 table 21, CiA 402) are named."""
    with inactive_rig() as hardware:
        hardware.configure()
        hardware.read()
        faults = faults_after(hardware, [(cia402.EMCY_BASE + 1, cia402.emcy_frame(code))])
        assert faults == (f"x drive EMCY error code 0x{code:04X} (register 0x01; {meaning})",)


def test_the_sync_counter_runs_1_to_overflow_and_wraps() -> None:
    """With the counter on (0x1019 = 240), each SYNC carries 1..240 and then 1 again."""
    config = override(load_config(), "master.sim.channel", f"test-{uuid.uuid4().hex}")
    driver = create_hardware("sim-inproc", config).driver
    driver._plans()  # reads the EDS only: the counter is on when every drive has 0x1019
    assert (driver.sync_counter_overflow, driver.sync_counter_note) == (240, "SYNC counter 1..240")
    counts = [driver.pdos.next_sync().data[0] for _ in range(481)]
    assert counts == [*range(1, 241), *range(1, 241), 1]


# --- frames that are not the cycle's -----------------------------------------------------


def test_the_drivers_own_frames_echoed_back_are_not_late_frames() -> None:
    """An interface that hands a process its own frames back (udp_multicast) must not make
    the NMT, SYNC, heartbeat, RPDO1 and SDO requests this driver sent late frames; any other
    frame left from an earlier cycle is one, and so is a standard frame with the number of
    an extended id this driver sent."""
    driver, channel = bare_driver()
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


# --- the command's range -----------------------------------------------------------------


INT32_MAX = 2**31 - 1  # the drives' 0x607A range, independent of the driver's constant


@pytest.mark.parametrize("axis", [0, 1])
@pytest.mark.parametrize(("counts", "sent"), [(INT32_MAX, True), (-INT32_MAX, True),
                                              (INT32_MAX + 1, False), (-INT32_MAX - 1, False)])
def test_the_int32_range_edge_of_a_command(axis: int, counts: int, sent: bool) -> None:
    """A target of +-(2**31 - 1) counts is sent; one count further is refused, both targets
    held."""
    with active_rig() as hardware:
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


# --- the SYNC ----------------------------------------------------------------------------


@pytest.mark.parametrize(("overflow", "fd"), [(0, False), (0, True), (240, False), (240, True)])
def test_sync_puts_the_sync_on_the_bus_at_once(overflow: int, fd: bool) -> None:
    """``sync()`` sends the SYNC there and then: a standard frame 0x080, without data or with
    the counter, an FD frame (bit-rate switch) on CAN FD; a second ``sync()`` before the
    read sends nothing."""
    period = {} if fd else {"model.sample_period_s": 0.001}  # classical CAN's bus load
    with inactive_rig(**{"master.can.sync_counter_overflow": overflow, "master.can.fd": fd},
                   **period) as hardware:
        hardware.driver.sample_period_s = 0.00054 if fd else 0.001
        hardware.configure()
        channel = hardware.driver.bus_options["channel"]
        with can.Bus(interface="virtual", channel=channel) as listener:
            hardware.driver.sync()
            hardware.driver.sync()
            syncs = [m for m in frames_heard(listener) if m.arbitration_id == cia402.SYNC_COB_ID]
        assert len(syncs) == 1
        sync = syncs[0]
        assert sync.is_extended_id is False and (sync.is_fd, sync.bitrate_switch) == (fd, fd)
        assert len(sync.data) == (1 if overflow else 0)




def test_the_sync_counter_is_on_only_when_configured_and_every_eds_has_0x1019(tmp_path
                                                                            ) -> None:
    """Configured and in both EDS: on, 1..overflow. Configured off: off, saying so. An EDS
    without 0x1019: off for the bus, naming the EDS, whichever axis it is."""
    eds = packaged_eds_path().read_text()
    path = tmp_path / "no1019.eds"  # canopen reads the object sections, not the lists
    path.write_text(eds.replace(eds[eds.index("[1019]"):eds.index("[1400]")], ""))
    driver = plans_of(**{"master.can.sync_counter_overflow": 17})
    assert (driver.sync_counter_overflow, driver.sync_counter_note) == (17, "SYNC counter 1..17")
    driver = plans_of(**{"master.can.sync_counter_overflow": 0})
    assert (driver.sync_counter_overflow, driver.sync_counter_note) == (
        0, "SYNC counter off ([master.can] sync_counter_overflow = 0)")
    for axis in ("x", "y"):
        driver = plans_of(**{f"master.can.{axis}_eds_file": str(path)})
        assert (driver.sync_counter_overflow, driver.sync_counter_note) == (
            0, f"SYNC counter off: the {axis} drive's EDS ({path}) has no 0x1019")
    driver = plans_of(**{"master.can.x_eds_file": str(path), "master.can.y_eds_file": str(path)})
    assert driver.sync_counter_note == (f"SYNC counter off: the x drive's EDS ({path}) and the "
                                        f"y drive's EDS ({path}) have no 0x1019")
    driver = plans_of(**{"master.can.x_eds_file": str(path),
                          "master.can.sync_counter_overflow": 0})
    assert driver.sync_counter_note == "SYNC counter off ([master.can] sync_counter_overflow = 0)"


# --- the master's own quick stop and its resume ------------------------------------------


def test_the_masters_stop_is_an_event_once_and_holds_the_drives_at_their_positions() -> None:
    """stop_motion: quick stop on both drives at once, an event (not a fault) once however
    often it is called, each drive's taking it an event once; writes meanwhile send quick
    stop with the targets held where the drives were. Inactive, it does nothing."""
    with inactive_rig() as hardware:
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
            heard = frames_heard(listener)
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
    with active_rig() as hardware:
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
            heard = frames_heard(listener)
        for axis, node in enumerate((1, 2)):
            assert [bytes(m.data) for m in heard if m.arbitration_id == cia402.RPDO1_BASE
                    + node] == [struct.pack("<Hi", cia402.CW_ENABLE_OPERATION, target[axis])]


def test_a_resume_that_fails_is_a_fault_and_the_drives_stay_stopped(monkeypatch) -> None:
    """A drive that faults again while re-enabled: the reading says so and write() keeps
    sending quick stop."""
    with active_rig() as hardware:
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
            assert set(rpdo_controlwords(frames_heard(listener), 1)) == {cia402.CW_QUICK_STOP}


@pytest.mark.parametrize("axis", [0, 1])
def test_a_drive_that_does_not_take_the_stop_is_one_fault_after_the_enable_timeout(
        axis: int) -> None:
    """Not in quick stop active or switch on disabled after ``enable_timeout_cycles`` SYNCs
    of the stop: one fault naming the drive, its state and the SYNCs; the other drive took
    it."""
    with active_rig(**{"master.can.enable_timeout_cycles": 5}) as hardware:
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
    with active_rig() as hardware:
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
    with inactive_rig() as hardware:
        hardware.configure()
        hardware.read()
        for statusword, events in steps:
            reading = read_with_tpdo(hardware, 0, struct.pack("<Hi", statusword, 1234))
            assert list(reading.events) == events, (hex(statusword), reading.events)
            assert reading.position_m[0] == 1234 * hardware.driver.settings.metres_per_count


@pytest.mark.parametrize("size", [5, 7, 0])
def test_a_tpdo1_of_the_wrong_size_is_a_fault_not_a_sample(size: int) -> None:
    """A TPDO1 that is not 6 bytes: a malformed-frame fault, and the drive's sample is
    missing."""
    with inactive_rig() as hardware:
        hardware.configure()
        hardware.read()
        reading = read_with_tpdo(hardware, 1, bytes(size))
        assert f"y drive TPDO1 malformed: PDO payload of {size} bytes, expected 6" in \
            reading.faults
        assert "missing TPDO1 from the y drive (node 2)" in reading.faults
        assert np.isnan(reading.position_m[1]) and np.isfinite(reading.position_m[0])


def test_while_active_read_sends_the_masters_heartbeat_once_per_period() -> None:
    """Active, the master's heartbeat goes out from the cycle when due: once per
    ``heartbeat_period_s`` (0.1 s), never more often, however often read() runs."""
    with active_rig() as hardware:
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
            beats = [m for m in frames_heard(listener) if m.arbitration_id == master_heartbeat]
        # one due time per period after the first (which may catch up a late one)
        assert 2 <= len(beats) <= elapsed / 0.1 + 2, (len(beats), elapsed)
        assert all(bytes(m.data) == b"\x05" and not m.is_extended_id for m in beats)


# --- supervision in read() ---------------------------------------------------------------


def test_a_drive_in_fault_while_inactive_is_a_fault_without_a_quick_stop() -> None:
    """Inactive, a drive in Fault (or Fault reaction active) is a fault of each reading;
    nothing is commanded."""
    with inactive_rig() as hardware:
        hardware.configure()
        hardware.read()
        set_drive_state(hardware, 0, DriveState.FAULT)
        channel = hardware.driver.bus_options["channel"]
        with can.Bus(interface="virtual", channel=channel) as listener:
            assert hardware.read().faults == ("x drive in fault",)
            set_drive_state(hardware, 0, DriveState.FAULT_REACTION_ACTIVE)
            set_drive_state(hardware, 1, DriveState.FAULT)
            assert hardware.read().faults == ("x drive in fault reaction active",
                                              "y drive in fault")
            assert rpdo_controlwords(frames_heard(listener), 1) == []


@pytest.mark.parametrize("axis", [0, 1])
def test_a_drive_leaving_operation_enabled_while_active_quick_stops_both(axis: int) -> None:
    """Active and not stopped by the master, a drive out of operation enabled is a fault
    naming its state, and quick stop goes to both drives, once."""
    with active_rig() as hardware:
        hardware.read()
        set_drive_state(hardware, axis, DriveState.SWITCHED_ON)
        name = "xy"[axis]
        faults = hardware.read().faults
        assert faults == (f"{name} drive left operation enabled (switched on)",
                          "quick stop on both drives: a drive fault")
        for _ in range(5):  # tripped: the drives in quick stop are no fault, nor events
            reading = hardware.read()
            assert not any("quick stop on both" in f for f in reading.faults), reading.faults
            assert reading.events == ()


def test_a_drive_in_fault_while_active_quick_stops_both() -> None:
    with active_rig() as hardware:
        hardware.read()
        set_drive_state(hardware, 1, DriveState.FAULT)
        assert hardware.read().faults == ("y drive in fault",
                                          "quick stop on both drives: a drive fault")


def test_a_lost_heartbeat_is_reported_once_per_loss() -> None:
    """A drive's heartbeat missing for longer than ``heartbeat_timeout_s`` is one fault; heard
    again and lost again, it is reported again."""
    with inactive_rig(**{"master.can.heartbeat_timeout_s": 0.3}) as hardware:
        hardware.configure()
        driver, device = hardware.driver, hardware.rig.devices[1]

        def lost_after_silence() -> list[str]:
            driver.sdo.write(2, device.dictionary[0x1017], 0, "y drive")  # y goes quiet
            found: list[str] = []
            deadline = time.monotonic() + 1.5
            while time.monotonic() < deadline:
                found += [f for f in hardware.read().faults if "heartbeat" in f]
                time.sleep(0.01)
            driver.sdo.write(2, device.dictionary[0x1017], 50, "y drive")  # and back
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
    with active_rig(**{"master.can.heartbeat_timeout_s": 0.3}) as hardware:
        driver, device = hardware.driver, hardware.rig.devices[0]
        hardware.read()
        driver.sdo.write(1, device.dictionary[0x1017], 0, "x drive")  # x goes quiet
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
    with inactive_rig() as hardware:
        hardware.configure()
        hardware.read()
        hardware.rig.set_sensor_status(status, 1)
        reading = hardware.read()
        assert reading.faults == (f"force sensor status {status} (not ok)",)
        assert np.isnan(reading.force_N).all()
        reading = hardware.read()
        assert reading.faults == () and np.isfinite(reading.force_N).all()


def test_the_sensor_counter_wraps_at_256_without_a_jump() -> None:
    with inactive_rig() as hardware:
        hardware.configure()
        for _ in range(260):
            assert hardware.read().faults == ()


def test_a_malformed_sensor_frame_is_a_fault_and_nan() -> None:
    with inactive_rig() as hardware:
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
    with inactive_rig() as hardware:
        hardware.configure()
        channel = hardware.driver.bus_options["channel"]
        with can.Bus(interface="virtual", channel=channel) as listener:
            hardware.write(np.array([0.001, 0.001]))
            assert rpdo_controlwords(frames_heard(listener), 1) == []
        hardware.activate()
        hardware.read()
        per_count = hardware.driver.settings.metres_per_count
        before = [drive.target_counts for drive in hardware.rig.drives]
        with can.Bus(interface="virtual", channel=channel) as listener:
            hardware.write(np.array([math.nan, (before[1] + 30) * per_count]))
            heard = frames_heard(listener)
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
    with inactive_rig() as hardware:
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
    with active_rig() as hardware:
        hardware.read()
        faults = faults_after(hardware, [(HEARTBEAT_BASE + 1, b"\x7f")])
        assert faults == ("x drive heartbeat reports NMT state pre-operational, not operational",
                          "quick stop on both drives: a drive fault")


def test_on_can_fd_only_the_cycles_frames_are_fd() -> None:
    """On CAN FD the SYNC and the RPDOs go as FD frames (bit-rate switch); NMT, SDO and the
    master's heartbeat stay classical (devices that speak FD for PDOs only still hear
    them); an extra frame is standard unless asked for extended."""
    with inactive_rig(**{"master.can.fd": True}) as hardware:
        channel = hardware.driver.bus_options["channel"]
        with can.Bus(interface="virtual", channel=channel) as listener:
            hardware.configure()
            hardware.activate()
            for _ in range(3):
                hardware.write(np.zeros(2))
                hardware.read()
            hardware.driver.send_frame(0x321, b"\x01")
            heard = frames_heard(listener)
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
    with inactive_rig() as hardware:
        hardware.configure()
        hardware.read()
        offset = [0.0, 0.0]
        offset[axis] = -1.7e308
        hardware.driver.sensor.codec = ForceSensorCodec((10.0, 10.0), tuple(offset),
                                                        load_database())
        reading = hardware.read()
        assert len(reading.faults) == 1 and re.fullmatch(
            r"force sensor counts \(-?\d+, -?\d+\) are not finite in N: see \[master.can\] "
            r"force_scale_N_per_count and force_offset_count", reading.faults[0]), reading.faults
        assert np.isnan(reading.force_N).all()


def test_an_error_reset_with_a_low_byte_is_no_fault_and_the_next_group_is() -> None:
    """CiA 301's 00xxh codes are all "error reset or no error": 0x00FF is neither a fault nor
    logged; 0x0100, the smallest code past that group, is a fault: reported, logged and
    quick-stopping the drives, as much as 0x8611."""
    with active_rig() as hardware:
        hardware.read()
        faults = faults_after(hardware, [(cia402.EMCY_BASE + 1, cia402.emcy_frame(0x00FF))])
        assert faults == () and hardware.driver.emcy_log == []
        faults = faults_after(hardware, [(cia402.EMCY_BASE + 1, cia402.emcy_frame(0x0100))])
        assert "x drive EMCY error code 0x0100 (register 0x01)" in faults
        assert hardware.driver.emcy_log == [("x", 0x0100)]
        assert any(fault.startswith("quick stop on both drives") for fault in faults), faults


def test_remote_frames_on_the_supervision_ids_in_the_cycle_are_ignored() -> None:
    """A remote frame (a node guarding request) on a drive's EMCY or heartbeat COB-ID is no
    EMCY and no heartbeat of that drive: neither a malformed EMCY nor a heartbeat without
    a state."""
    with inactive_rig() as hardware:
        hardware.configure()
        hardware.read()
        driver = hardware.driver
        channel = driver.bus_options["channel"]
        driver.sync()  # the frames come while the cycle collects its replies
        with can.Bus(interface="virtual", channel=channel) as other:
            for frame_id in (cia402.EMCY_BASE + 1, HEARTBEAT_BASE + 1):
                other.send(can.Message(arbitration_id=frame_id, is_remote_frame=True, dlc=1,
                                       is_extended_id=False))
        assert hardware.read().faults == ()
        assert driver.emcy_log == []


def test_a_frame_of_an_unknown_id_in_the_cycle_is_ignored() -> None:
    """A stranger's frame (any id the driver does not know, TPDO-sized) while the driver
    collects its cycle is neither a sample nor a fault: the drive whose TPDO is missing
    stays missing."""
    with inactive_rig() as hardware:
        hardware.configure()
        hardware.read()
        for frame_id in (0x123, 0x183, cia402.TPDO1_BASE + 5):
            reading = read_with_tpdo_id(hardware, 0, frame_id, struct.pack("<Hi", 0x0237, 77))
            assert reading.faults == ("missing TPDO1 from the x drive (node 1)",)
            assert np.isnan(reading.position_m[0]) and np.isfinite(reading.position_m[1])
