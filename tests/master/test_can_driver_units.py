"""The CAN driver's supervision messages and frame checks at unit level, fast: the exact
fault text for each EMCY, heartbeat and sensor frame a drive or a stranger on the bus may
send, the SDO abort texts, and the SYNC counter's wrap, against the in-process emulated rig
(python-can's virtual bus) with the frames of a second bus member where the rig cannot
produce them."""

from __future__ import annotations

import re
import uuid

import can
import numpy as np
import pytest

from haptic.common.config import load_config, override
from haptic.master.hardware import cia402
from haptic.master.hardware.can_driver import HEARTBEAT_BASE, _abort_text
from haptic.master.hardware.interface import create_hardware
from haptic.master.sim.sim_rig import SimulatedRigHardware


def _active() -> SimulatedRigHardware:
    config = load_config()
    config = override(config, "master.sim.operator", "constant:fx=0,fy=0")
    config = override(config, "master.sim.channel", f"test-{uuid.uuid4().hex}")
    config = override(config, "master.can.heartbeat_timeout_s", 5.0)  # unpaced steps
    hardware = create_hardware("sim-inproc", config)
    assert isinstance(hardware, SimulatedRigHardware)
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


def test_the_sdo_abort_texts() -> None:
    """Known CiA 301 abort codes get their meaning, any other the pointer to the standard."""
    assert _abort_text(0x06090030) == "value out of range"
    assert _abort_text(0x06040041) == "object cannot be mapped to the PDO"
    assert _abort_text(0x12345678) == "see CiA 301"


def test_the_sync_counter_runs_1_to_overflow_and_wraps() -> None:
    """With the counter on (0x1019 = 240), each SYNC carries 1..240 and then 1 again."""
    config = override(load_config(), "master.sim.channel", f"test-{uuid.uuid4().hex}")
    driver = create_hardware("sim-inproc", config).driver
    driver._plans()  # reads the EDS only: the counter is on when every drive has 0x1019
    assert (driver.sync_counter_overflow, driver.sync_counter_note) == (240, "SYNC counter 1..240")
    counts = [driver._next_sync().data[0] for _ in range(481)]
    assert counts == [*range(1, 241), *range(1, 241), 1]
