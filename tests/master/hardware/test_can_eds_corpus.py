"""The CAN driver against drives built from EDS and DCF files nobody in this project wrote
(tests/master/hardware/eds_corpus/, SOURCES.md says where each comes from): both drives emulated
from
the file (canopen's ``LocalNode`` with its object dictionary, master/hardware/drive_device.py),
then configure, activate, 200 cycles and deactivate with the fallbacks the file calls for,
or a refusal in one line that names why. docs/master.md has the table these tests pin."""

from __future__ import annotations

import logging
import re
from pathlib import Path

import numpy as np
import pytest

from haptic.master.hardware.cia402 import DriveState
from haptic.master.hardware.interface import HardwareError, LifecycleState
from tests.master.hardware.can_driver_helpers import inactive_rig

CORPUS = Path(__file__).parent / "eds_corpus"
DOCS = Path(__file__).parents[3] / "docs" / "master.md"
DRIVER_LOG = "haptic.master.hardware.can_driver"
DEADLINE = "no RPDO deadline (0x1400:05): the drive does not watch the targets' arrival"
#: The files that run, and the fallbacks each drive takes.
RUNS = {
    "Elmo.dcf": ["no settable SYNC COB-ID (0x1005): the drive is taken to consume SYNC on "
                 "0x080", DEADLINE],
    "e35.eds": ["no heartbeat consumer (0x1016): life guarding (0x100C/0x100D) watches the "
                "master instead", DEADLINE],
    "cia402_slave.eds": [DEADLINE],
}
#: The files refused, and why (after "x drive's EDS (path)").
REFUSED = {
    "ISD860.dcf": " has no cyclic synchronous position: 0x6502 (supported drive modes) = "
                  "0x00000065, bit 7 (mode 8) clear",
    "prbt_0_1.dcf": " has no cyclic synchronous position: 0x6502 (supported drive modes) = "
                    "0x00000043, bit 7 (mode 8) clear",
    "sample.eds": " has no object 0x6040:00: the cyclic synchronous position loop cannot run "
                  "without it",
    "DS301_profile.eds": " has no object 0x6040:00: the cyclic synchronous position loop "
                         "cannot run without it",
}


def _rig(name: str):
    path = str(CORPUS / name)
    return inactive_rig(**{"master.can.x_eds_file": path, "master.can.y_eds_file": path})


def test_the_corpus_is_every_file_here_each_with_its_source() -> None:
    files = sorted(p.name for p in CORPUS.iterdir() if p.suffix in (".eds", ".dcf"))
    assert files == sorted([*RUNS, *REFUSED])
    assert len(RUNS) >= 3 and len(files) >= 5
    sources = (CORPUS / "SOURCES.md").read_text()
    for name in files:
        assert re.search(rf"^\| `{re.escape(name)}` \| \[[\w-]+/[\w-]+\]\(https://github\.com/",
                         sources, re.MULTILINE), name


@pytest.mark.parametrize("name", sorted(RUNS))
def test_a_corpus_drive_runs_with_the_fallbacks_its_file_calls_for(name: str, caplog) -> None:
    hardware = _rig(name)
    path = CORPUS / name
    expected = [f"{axis} drive (node {node}): {line}" for axis, node in (("x", 1), ("y", 2))
                for line in RUNS[name]]
    expected.append(f"SYNC counter off: the x drive's EDS ({path}) and the y drive's EDS "
                    f"({path}) have no 0x1019")
    with hardware, caplog.at_level(logging.WARNING, logger=DRIVER_LOG):
        hardware.configure()
        assert hardware.driver.fallbacks == expected
        assert hardware.summary()["fallbacks"] == expected
        assert [r.getMessage() for r in caplog.records if r.name == DRIVER_LOG] == [
            f"haptic-master: {line}" for line in expected]
        for device in hardware.rig.devices:  # the PDOs the file starts enabled are off
            assert list(device.rpdos_by_id) == [device.rpdo.cob_id]
            assert [tpdo.cob_id for tpdo in device.tpdos] == [device.tpdo.cob_id]
        hardware.activate()
        start = hardware.read().position_m
        for _ in range(200):
            hardware.write(start + np.array([0.0005, -0.0005]))
            reading = hardware.read()
            assert reading.ok, reading.faults
        assert np.allclose(reading.position_m, start + [0.0005, -0.0005], atol=5e-5)
        hardware.deactivate()
        assert hardware.driver.drive_states == (DriveState.READY_TO_SWITCH_ON,) * 2
        assert hardware.rig.errors == [] and hardware.driver.late_frames == 0


@pytest.mark.parametrize("name", sorted(REFUSED))
def test_a_corpus_file_that_cannot_run_the_loop_is_refused_in_one_line(name: str) -> None:
    hardware = _rig(name)
    with pytest.raises(HardwareError) as error:
        hardware.configure()
    assert str(error.value) == f"x drive's EDS ({CORPUS / name})" + REFUSED[name]
    assert hardware.lifecycle_state is LifecycleState.UNCONFIGURED
    assert hardware.rig.last_sample is None  # refused before the bus: no SYNC, nothing moved
    hardware.cleanup()


def test_the_docs_table_says_what_the_corpus_does() -> None:
    """docs/master.md's corpus table has a row per file: "runs" with its fallbacks, or
    "refused" with the reason's object."""
    rows = {m.group(1): m.group(2) for m in re.finditer(
        r"^\| `([^`/]+\.(?:eds|dcf))` \|[^|]*\|([^|]*)\|", DOCS.read_text(), re.MULTILINE)}
    assert set(rows) == {*RUNS, *REFUSED}
    for name in RUNS:
        assert rows[name].strip().startswith("runs"), name
    for name, reason in REFUSED.items():
        assert rows[name].strip().startswith("refused"), name
        assert re.search(r"0x6502|0x6040", rows[name]) and re.search(r"0x6502|0x6040", reason)
