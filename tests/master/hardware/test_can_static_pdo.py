"""Static PDO mappings: a drive whose EDS fixes its PDO mappings (read-only mapping objects)
is run through the mapping it has, read back at configure instead of written, in PDO 1 or
another number, in whatever order and with whatever else a TPDO carries; one that cannot
carry what the loop needs is refused naming the objects. Against emulated drives built from
variants of the packaged EDS (canopen ``LocalNode``s, python-can's virtual bus)."""

from __future__ import annotations

from pathlib import Path

import can
import pytest

from haptic.master.hardware.canopen_setup import PlanError
from haptic.master.hardware.interface import HardwareError, LifecycleState
from tests.master.hardware.can_driver_helpers import (
    frames_heard,
    inactive_rig,
    moves_towards_an_offset,
    sdo_downloads,
)
from tests.master.hardware.eds_variants import packaged, pdo, without, written

CONTROLWORD, TARGET = 0x60400010, 0x607A0020
STATUSWORD, MODE_DISPLAY, POSITION, VELOCITY = 0x60410010, 0x60610008, 0x60640020, 0x606C0020
#: 0x60FF, which the packaged EDS lacks (a velocity-mode RPDO maps it).
TARGET_VELOCITY = ("[60FF]\nParameterName=Target velocity\nObjectType=0x7\nDataType=0x0004\n"
                   "AccessType=rw\nDefaultValue=0\nPDOMapping=1\n\n")


def _rig(tmp_path: Path, text: str):
    """The in-process rig whose x drive (emulated and in the driver) is ``text``."""
    return inactive_rig(**{"master.can.x_eds_file": str(written(tmp_path, "x.eds", text))})


def _replaced(*pdos: str, drop: tuple[int, ...] = (0x1400, 0x1600, 0x1800, 0x1A00)) -> str:
    """The packaged EDS with its PDO objects ``drop`` replaced by ``pdos``."""
    return without(packaged(), *drop) + "".join(pdos)



def test_static_pdo1_mappings_are_read_back_and_used(tmp_path: Path) -> None:
    """RPDO1 fixed to controlword + target, TPDO1 to statusword, mode display (8 bits) and
    position: nothing is written to the mappings, each entry is read back, the TPDO's extra
    object is skipped and the bus-load budget counts its 7 bytes."""
    text = _replaced(pdo(0x1400, "$NODEID+0x80000200", 255, (CONTROLWORD, TARGET)),
                     pdo(0x1800, "$NODEID+0x80000180", 255, (STATUSWORD, MODE_DISPLAY,
                                                                 POSITION)))
    hardware = _rig(tmp_path, text)
    channel = hardware.driver.bus_options["channel"]
    with can.Bus(interface="virtual", channel=channel) as listener, hardware:
        hardware.configure()
        heard = frames_heard(listener)
        assert [node for node, _ in sdo_downloads(heard, 0x1600)] == [2, 2, 2, 2]
        assert [node for node, _ in sdo_downloads(heard, 0x1A00)] == [2, 2, 2, 2]
        reads = [m for m in heard if m.arbitration_id == 0x601 and m.data[0] == 0x40]
        assert {bytes(m.data[1:4]) for m in reads} >= {
            bytes([0x00, 0x16, sub]) for sub in (0, 1, 2)} | {
            bytes([0x00, 0x1A, sub]) for sub in (0, 1, 2, 3)}
        drives = hardware.summary()["can_drives"]["x"]
        assert (drives["rpdo"], drives["tpdo"]) == ("RPDO1 0x201 static", "TPDO1 0x181 static")
        assert "RPDO1 (0x1400) used with its static mapping 0x1600, read back" in \
            drives["fallbacks"]
        frames = dict(hardware.driver.bus_load.frames)
        assert frames["TPDO1 x"] > frames["TPDO1 y"]  # 7 bytes against 6
        moves_towards_an_offset(hardware, 60)


def test_a_static_mapping_in_another_pdo_and_order_is_used(tmp_path: Path) -> None:
    """RPDO1 fixed to something else (velocity mode), RPDO2 fixed to target + controlword:
    the loop runs on RPDO2 (COB-ID 0x300 + node), packing the target first; TPDO3 likewise
    with the position before the statusword."""
    text = _replaced(
        pdo(0x1400, "$NODEID+0x80000200", 255, (0x60FF0020, CONTROLWORD)),
        pdo(0x1401, "$NODEID+0x80000300", 255, (TARGET, CONTROLWORD)),
        pdo(0x1800, "$NODEID+0x80000180", 255, (STATUSWORD,)),
        pdo(0x1802, "$NODEID+0x80000380", 255, (POSITION, STATUSWORD)),
        drop=(0x1400, 0x1600, 0x1800, 0x1A00)) + TARGET_VELOCITY
    hardware = _rig(tmp_path, text)
    with hardware:
        hardware.configure()
        drives = hardware.summary()["can_drives"]["x"]
        assert (drives["rpdo"], drives["tpdo"]) == ("RPDO2 0x301 static", "TPDO3 0x381 static")
        device = hardware.rig.devices[0]
        assert sorted(device.rpdos_by_id) == [0x301]
        assert [p.cob_id for p in device.tpdos] == [0x381]
        assert hardware.driver.pdos.rpdo_frame(0, 0x0F, 7).data == bytes(
            [7, 0, 0, 0, 0x0F, 0])  # target first
        moves_towards_an_offset(hardware, 60)


def test_a_drive_whose_static_mappings_cannot_carry_the_loop_is_refused(tmp_path: Path) -> None:
    text = _replaced(pdo(0x1400, "$NODEID+0x80000200", 255, (0x60FF0020, CONTROLWORD)),
                     pdo(0x1800, "$NODEID+0x80000180", 255, (STATUSWORD, POSITION)))
    hardware = _rig(tmp_path, text + TARGET_VELOCITY)
    with pytest.raises(PlanError) as error:
        hardware.configure()
    assert str(error.value) == (
        f"x drive's EDS ({tmp_path / 'x.eds'}): no RPDO can carry 0x6040:00 and 0x607A:00 "
        "at every SYNC: 0x1600 is read-only and maps 0x60FF:00, 0x6040:00")
    assert hardware.lifecycle_state is LifecycleState.UNCONFIGURED
    hardware.cleanup()


def test_a_static_tpdo_not_sent_at_every_sync_is_refused(tmp_path: Path) -> None:
    text = _replaced(pdo(0x1400, "$NODEID+0x80000200", 255, (CONTROLWORD, TARGET)),
                     pdo(0x1800, "$NODEID+0x180", 255, (STATUSWORD, POSITION),
                         comm_access="ro"))
    hardware = _rig(tmp_path, text)
    with pytest.raises(PlanError, match=r"no TPDO can carry 0x6041:00 and 0x6064:00 at every "
                                        r"SYNC: .*0x1800 cannot be enabled for every SYNC$"):
        hardware.configure()
    hardware.cleanup()


def test_a_drive_whose_mapping_differs_from_its_eds_is_refused_naming_it(
        tmp_path: Path) -> None:
    text = _replaced(pdo(0x1400, "$NODEID+0x80000200", 255, (CONTROLWORD, TARGET)),
                     pdo(0x1800, "$NODEID+0x80000180", 255, (STATUSWORD, POSITION)))
    hardware = _rig(tmp_path, text)
    device = hardware.rig.devices[0]  # its firmware maps another object there
    device.node.data_store.setdefault(0x1600, {})[2] = device._variable(0x1600, 2).encode_raw(
        VELOCITY)
    device.refresh()
    with pytest.raises(HardwareError, match=r"^x drive \(node 1\): 0x1600:02 \(Application "
                                            rf"object 2\) reads {VELOCITY}, not the EDS's "
                                            rf"fixed {TARGET}$"):
        hardware.configure()
    assert hardware.lifecycle_state is LifecycleState.UNCONFIGURED


def test_other_pdos_the_eds_starts_enabled_are_disabled(tmp_path: Path) -> None:
    """An extra TPDO2 enabled by default (event-driven, on a change of the statusword)
    would add frames to every cycle: configure disables it; one with a read-only COB-ID stays
    on, named, and its frames are not late frames."""
    text = packaged() + pdo(0x1801, "$NODEID+0x280", 255, (STATUSWORD,), mapping_access="rw")
    with _rig(tmp_path, text) as hardware:
        hardware.configure()
        assert [p.cob_id for p in hardware.rig.devices[0].tpdos] == [0x181]
        assert hardware.driver.fallbacks == []
    text = packaged() + pdo(0x1801, "$NODEID+0x280", 255, (STATUSWORD,), comm_access="ro")
    with _rig(tmp_path, text) as hardware:
        hardware.configure()
        assert hardware.driver.fallbacks == [
            "x drive (node 1): TPDO2 (0x1801) stays on (read-only COB-ID): its frames are "
            "ignored"]
        assert [p.cob_id for p in hardware.rig.devices[0].tpdos] == [0x181, 0x281]
        # its statusword changes as the drive is enabled: TPDO2 frames
        moves_towards_an_offset(hardware, 60)
