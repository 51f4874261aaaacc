"""What the CAN driver does with a drive whose EDS lacks an optional CiA 301/402 object: each
fallback taken, said in one line at configure and listed in the summary, and the run that
follows; a drive left without any drive-side watchdog refused unless
``[master.can] allow_no_drive_watchdog``; against emulated drives built from variants of the
packaged EDS (canopen ``LocalNode``s, python-can's virtual bus)."""

from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np
import pytest

from haptic.common.config import ConfigError, load_config, override
from haptic.master.hardware.canopen_setup import PlanError
from haptic.master.hardware.interface import HardwareError, LifecycleState
from tests.master.hardware.can_driver_helpers import (
    answering,
    inactive_rig,
    moves_towards_an_offset,
    sdo_downloads,
)
from tests.master.hardware.eds_variants import (
    entry_set,
    packaged,
    variable,
    without,
    without_sections,
    written,
)

X = "x drive (node 1): "


def _x_eds(tmp_path: Path, text: str, **overrides):
    """The in-process rig whose x drive (the emulated drive and the driver's EDS) is
    ``text``, not configured yet."""
    path = written(tmp_path, "x.eds", text)
    return inactive_rig(**{"master.can.x_eds_file": str(path), **overrides})



def _configured_with(tmp_path: Path, text: str, caplog, **overrides):
    """:func:`_x_eds`'s rig configured, with the fallback lines logged at configure."""
    hardware = _x_eds(tmp_path, text, **overrides)
    with caplog.at_level(logging.WARNING, logger="haptic.master.hardware.can_driver"):
        hardware.configure()
    return hardware, [r.getMessage() for r in caplog.records
                      if r.name == "haptic.master.hardware.can_driver"]


def _says(hardware, logged: list[str], line: str) -> None:
    """``line`` is a fallback of the driver: in its list, its summary, and logged once."""
    assert line in hardware.driver.fallbacks
    assert line in hardware.summary()["fallbacks"]
    assert logged.count(f"haptic-master: {line}") == 1


def test_the_packaged_eds_needs_no_fallback_and_says_what_it_uses() -> None:
    with inactive_rig() as hardware:
        assert hardware.summary() == {}  # nothing before configure
        hardware.configure()
        assert hardware.driver.fallbacks == []
        drives = hardware.summary()["can_drives"]
        assert drives["x"] == {"rpdo": "RPDO1 0x201", "tpdo": "TPDO1 0x181", "fallbacks": [],
                               "watchdogs": ["heartbeat consumer (0x1016)",
                                             "RPDO deadline (0x1400:05)"]}


def test_a_drive_without_the_rpdo_deadline_runs_on_its_heartbeat_consumer(
        tmp_path: Path, caplog) -> None:
    """The reported case: a LocalNode drive whose EDS has no 0x1400:05 made configure fail;
    now the deadline is left out, named, and the heartbeat consumer watches the master."""
    text = without_sections(packaged(), "1400sub5")
    hardware, logged = _configured_with(tmp_path, text, caplog)
    with hardware:
        _says(hardware, logged, X + "no RPDO deadline (0x1400:05): the drive does not watch "
                                    "the targets' arrival")
        assert hardware.summary()["can_drives"]["x"]["watchdogs"] == ["heartbeat consumer (0x1016)"]
        assert hardware.rig.devices[0].rpdo_deadline_ms == 0
        assert hardware.rig.devices[1].rpdo_deadline_ms == 100
        moves_towards_an_offset(hardware, 20)


@pytest.mark.parametrize(("index", "line"), [
    (0x60C2, "no interpolation period (0x60C2): the drive takes its cycle from the SYNCs"),
    (0x1005, "no settable SYNC COB-ID (0x1005): the drive is taken to consume SYNC on 0x080"),
    (0x6065, "no following error window (0x6065): the drive keeps its own"),
    (0x6502, "no supported drive modes (0x6502): mode 8 is checked by 0x6061 only"),
])
def test_a_drive_without_an_optional_object_runs_with_its_fallback(
        tmp_path: Path, caplog, index: int, line: str) -> None:
    hardware, logged = _configured_with(tmp_path, without(packaged(), index), caplog)
    with hardware:
        _says(hardware, logged, X + line)
        assert len(hardware.driver.fallbacks) == 1
        assert all(step.variable.index != index for step in hardware.driver.plans[0].steps)
        device = hardware.rig.devices[0]
        if index == 0x60C2:  # the emulated drive's cycle is the SYNC's
            assert device.interpolation_period_s == pytest.approx(0.00054)
        if index == 0x6065:
            assert device.following_error_window_counts == 0xFFFFFFFF  # CiA 402: off
        moves_towards_an_offset(hardware, 20)


def test_a_read_only_interpolation_period_at_another_value_is_a_fallback(
        tmp_path: Path, caplog) -> None:
    text = entry_set(entry_set(packaged(), "60C2sub1", "AccessType", "ro"), "60C2sub2",
                     "AccessType", "ro")
    hardware, logged = _configured_with(tmp_path, text, caplog)
    with hardware:
        _says(hardware, logged, X + "interpolation period (0x60C2) not settable to Ts: the "
                                    "drive keeps its own")
        assert (hardware.rig.devices[0].raw(0x60C2, 1),
                hardware.rig.devices[0].raw(0x60C2, 2)) == (10, -3)  # its own 10 ms


def test_a_drive_without_a_heartbeat_producer_is_watched_by_its_tpdo(
        tmp_path: Path, caplog) -> None:
    """No 0x1017: the master expects no heartbeat from it (a silent drive is no fault); its
    TPDO at each SYNC shows it alive, the y drive's heartbeat is still watched."""
    hardware, logged = _configured_with(tmp_path, without(packaged(), 0x1017), caplog,
                                        **{"master.can.heartbeat_timeout_s": 0.3})
    with hardware:
        _says(hardware, logged, X + "no heartbeat producer (0x1017): the master watches the "
                                    "drive by its TPDO at each SYNC")
        time.sleep(0.5)  # beyond the timeout: no heartbeat came from x
        reading = hardware.read()
        assert reading.ok, reading.faults
        hardware.rig.drop_tpdo(0, 1)
        assert "missing TPDO1 from the x drive (node 1)" in hardware.read().faults


def test_life_guarding_watches_the_master_where_the_drive_has_no_heartbeat_consumer(
        tmp_path: Path, caplog) -> None:
    """No 0x1016 but 0x100C/0x100D: heartbeat producer off, guard time = heartbeat period,
    life time factor covering the heartbeat timeout; the master sends guarding requests (with
    its heartbeat, and while idle), watches the answers, and a stalled master stops the
    drive (EMCY 0x8130, then its 0x6007 reaction)."""
    guarding = (variable(0x100C, None, "Guard time", 6, "rw", "0")
                + variable(0x100D, None, "Life time factor", 5, "rw", "0"))
    text = without(packaged(), 0x1016) + guarding
    hardware, logged = _configured_with(tmp_path, text, caplog,
                                        **{"master.can.heartbeat_timeout_s": 0.3})
    with hardware:
        _says(hardware, logged, X + "no heartbeat consumer (0x1016): life guarding (0x100C/"
                                    "0x100D) watches the master instead")
        device = hardware.rig.devices[0]
        assert (device.guard_time_ms, device.life_time_factor) == (100, 3)
        assert device.heartbeat_producer_ms == 0  # CiA 301: guarding only without it
        assert hardware.summary()["can_drives"]["x"]["watchdogs"] == [
            "life guarding (0x100C/0x100D)", "RPDO deadline (0x1400:05)"]
        time.sleep(0.5)  # idle: the idle task's requests keep it guarded
        assert hardware.rig.network.guarded_at[0] is not None
        reading = hardware.read()
        assert reading.ok, reading.faults  # its answers count as its heartbeat
        hardware.activate()
        for _ in range(10):
            hardware.write(np.zeros(2))
            assert hardware.read().ok
        time.sleep(0.6)  # the master stalls: no requests beyond guard time x factor
        faults = hardware.read().faults
        assert "x drive EMCY error code 0x8130 (register 0x01; heartbeat or life guard lost)" \
            in faults


def _no_watchdog(rpdo_deadline: bool = False) -> str:
    text = without(packaged(), 0x1016)
    return text if rpdo_deadline else without_sections(text, "1400sub5")


def test_a_drive_without_any_watchdog_is_refused_in_one_line(tmp_path: Path) -> None:
    hardware = _x_eds(tmp_path, _no_watchdog())
    with pytest.raises(PlanError) as error:
        hardware.configure()
    text = str(error.value)
    assert "\n" not in text
    assert text == (f"x drive's EDS ({tmp_path / 'x.eds'}) would run without a drive-side "
                    "watchdog: no heartbeat consumer (0x1016), RPDO deadline (0x14xx:05) or "
                    "life guarding (0x100C/0x100D); [master.can] allow_no_drive_watchdog = "
                    "true accepts it")
    assert hardware.lifecycle_state is LifecycleState.UNCONFIGURED
    assert hardware.rig.last_sample is None  # refused before the bus: nothing moved


def test_an_rpdo_deadline_turned_off_leaves_no_watchdog_and_says_so(tmp_path: Path) -> None:
    hardware = _x_eds(tmp_path, _no_watchdog(rpdo_deadline=True),
                      **{"master.can.rpdo_timeout_s": 0.0})
    with pytest.raises(PlanError, match=r"\(rpdo_timeout_s = 0 turns the deadline off\); "):
        hardware.configure()
    hardware.cleanup()
    hardware = _x_eds(tmp_path, _no_watchdog(rpdo_deadline=True))
    with hardware:
        hardware.configure()  # the deadline is a watchdog
        assert hardware.summary()["can_drives"]["x"]["watchdogs"] == ["RPDO deadline (0x1400:05)"]


def test_allow_no_drive_watchdog_accepts_it_with_the_fallback_named(
        tmp_path: Path, caplog) -> None:
    hardware, logged = _configured_with(tmp_path, _no_watchdog(), caplog,
                                        **{"master.can.allow_no_drive_watchdog": True})
    with hardware:
        _says(hardware, logged, X + "no drive-side watchdog: a stalled master leaves the drive "
                                    "following its last target (allowed by [master.can] "
                                    "allow_no_drive_watchdog)")
        assert hardware.summary()["can_drives"]["x"]["watchdogs"] == []
        moves_towards_an_offset(hardware, 20)


def test_allow_no_drive_watchdog_is_a_validated_key_off_by_default() -> None:
    assert load_config()["master"]["can"]["allow_no_drive_watchdog"] is False
    for value in (1, "yes", None):
        with pytest.raises(ConfigError) as caught:
            override(load_config(), "master.can.allow_no_drive_watchdog", value)
        assert caught.value.key == "master.can.allow_no_drive_watchdog"


def test_no_mode_8_in_0x6502_is_refused_from_the_eds_or_from_the_drive(tmp_path: Path) -> None:
    hardware = _x_eds(tmp_path, entry_set(packaged(), "6502", "DefaultValue", "0x00000001"))
    with pytest.raises(PlanError, match=r"has no cyclic synchronous position: 0x6502 "
                                        r"\(supported drive modes\) = 0x00000001, bit 7 \(mode "
                                        r"8\) clear$"):
        hardware.configure()
    hardware.cleanup()
    with inactive_rig() as hardware:  # the EDS says 0x81, the drive answers 0x01
        answering(hardware.rig.devices[1], 0x6502, 0x01)
        with pytest.raises(HardwareError, match=r"^y drive \(node 2\) has no cyclic "
                                                r"synchronous position: 0x6502 reads "
                                                r"0x00000001 \(bit 7, mode 8, clear\)$"):
            hardware.configure()


def test_mode_limits_in_the_eds_that_exclude_8_are_refused(tmp_path: Path) -> None:
    text = packaged().replace("[6060]\n", "[6060]\nLowLimit=0\nHighLimit=7\n")
    hardware = _x_eds(tmp_path, text)
    with pytest.raises(PlanError, match=r"0x6060 \(modes of operation\) takes 0..7 only, not "
                                        r"8 \(cyclic synchronous position\)$"):
        hardware.configure()
    hardware.cleanup()


def test_an_identity_without_its_optional_entries_reads_what_is_there(
        tmp_path: Path, caplog) -> None:
    text = without_sections(packaged(), "1018sub2", "1018sub3", "1018sub4")
    hardware, logged = _configured_with(tmp_path, text, caplog)
    with hardware:
        _says(hardware, logged, X + "identity without 0x1018:02, 0x1018:03, 0x1018:04 in the "
                                    "EDS: not read")
        assert set(hardware.driver.identities[0]) == {"device_type", "vendor_id"}
        assert set(hardware.driver.identities[1]) == {"device_type", "vendor_id", "revision",
                                                      "product_code", "serial_number"}


def test_a_fallback_writes_nothing_to_the_object_it_replaces(tmp_path: Path) -> None:
    import can

    hardware = _x_eds(tmp_path, without(packaged(), 0x6065, 0x1005))
    channel = hardware.driver.bus_options["channel"]
    with can.Bus(interface="virtual", channel=channel) as listener, hardware:
        hardware.configure()
        heard = []
        while (message := listener.recv(timeout=0.0)) is not None:
            heard.append(message)
        assert [n for n, _ in sdo_downloads(heard, 0x6065)] == [2]
        assert [n for n, _ in sdo_downloads(heard, 0x1005)] == [2]
