"""Reading EDS and DCF files as CiA 306 says (master/hardware/eds_reader.py): canopen's
importer for what it does (``ParameterValue`` over ``DefaultValue``, simple ``$NODEID``
formulas), and the gaps it leaves filled: formulas of more than one constant, empty
``[DeviceInfo]`` entries, a DCF's ``[DeviceComissioning] NodeID``; and a DCF's values used by
the driver's plan and served by the emulated drive."""

from __future__ import annotations

from pathlib import Path

import canopen
import pytest

from haptic.master.hardware.canopen_setup import PlanError
from haptic.master.hardware.drive_device import DriveObjects, DriveRuntime
from haptic.master.hardware.eds_reader import file_value, node_formula, read_dictionary
from haptic.master.hardware.interface import HardwareError
from tests.master.hardware.can_driver_helpers import inactive_rig, plans_of
from tests.master.hardware.eds_variants import entry_set, packaged, written

CORPUS = Path(__file__).parent / "eds_corpus"


@pytest.mark.parametrize(("text", "node", "value"), [
    ("$NODEID+0x180", 5, 0x185), ("0x180+$NODEID", 5, 0x185), ("$NodeID + 0x200", 3, 0x203),
    ("$nodeid+384", 1, 385), ("0x80000000+$NODEID+0x180", 2, 0x80000182),
    ("$NODEID", 7, 7), ("0x40000000 + 0x180 + $NODEID", 1, 0x40000181)])
def test_a_nodeid_formula_is_the_sum_of_its_terms(text: str, node: int, value: int) -> None:
    assert node_formula(text, node) == value


@pytest.mark.parametrize("text", ["$NODEID*2", "$NODEID+$NODEID", "0x180", "$NODEID+",
                                  "$NODEID-1", "$NODEID+x"])
def test_anything_else_is_not_a_nodeid_formula(text: str) -> None:
    with pytest.raises(ValueError):
        node_formula(text, 1)


def _with_cob_formula(tmp_path: Path, formula: str, suffix: str = ".eds") -> Path:
    return written(tmp_path, f"drive{suffix}",
                   entry_set(packaged(), "1800sub1", "DefaultValue", formula))


def test_a_formula_canopen_leaves_without_a_value_is_resolved(tmp_path: Path) -> None:
    path = _with_cob_formula(tmp_path, "0x80000000+$NODEID+0x180")
    assert canopen.import_od(str(path), 4)[0x1800][1].default is None  # the gap
    assert read_dictionary(path, 4)[0x1800][1].default == 0x80000184
    device = DriveObjects(4, path, lambda *_: None, DriveRuntime(4), lambda: 0)
    assert device.raw(0x1800, 1) == 0x80000184 and not device.tpdo.enabled


def test_empty_device_info_entries_are_read_as_absent() -> None:
    """CANopenNode's editor writes ``VendorNumber=``: canopen alone cannot read the file."""
    path = CORPUS / "DS301_profile.eds"
    with pytest.raises(ValueError):
        canopen.import_od(str(path), 1)
    dictionary = read_dictionary(path, 1)
    assert dictionary.device_information.vendor_number is None
    assert dictionary.device_information.product_name == "New Product"
    assert file_value(dictionary[0x1017]) == 0


def _dcf(tmp_path: Path, node: int | str, parameter_values: dict[str, str]) -> Path:
    """The packaged EDS as the DCF of ``node``: commissioning section and ParameterValues."""
    text = packaged().replace("[DeviceInfo]", f"[DeviceComissioning]\nNodeID={node}\n"
                              "Baudrate=1000\nNodeName=x axis\n\n[DeviceInfo]")
    for section, value in parameter_values.items():
        text = text.replace(f"[{section}]\n", f"[{section}]\nParameterValue={value}\n")
    return written(tmp_path, "drive.dcf", text)


def test_a_dcf_gives_its_parameter_values_over_the_defaults(tmp_path: Path) -> None:
    path = _dcf(tmp_path, "0x05", {"1017": "250", "1800sub1": "$NODEID+0x180"})
    dictionary = read_dictionary(path, 5)
    assert (dictionary[0x1017].default, file_value(dictionary[0x1017])) == (0, 250)
    assert file_value(dictionary[0x1800][1]) == 0x185
    device = DriveObjects(5, path, lambda *_: None, DriveRuntime(5), lambda: 0)
    assert device.heartbeat_producer_ms == 250 and device.tpdo.enabled  # canopen serves them


def test_a_dcf_of_another_node_is_refused_and_an_eds_section_is_not(tmp_path: Path) -> None:
    path = _dcf(tmp_path, 5, {})
    with pytest.raises(ValueError, match=r"^it is the DCF of node 5 \(\[DeviceComissioning\] "
                                         r"NodeID\), not of node 3$"):
        read_dictionary(path, 3)
    eds = written(tmp_path, "drive.eds", path.read_text())  # CiA 306: a DCF's section only
    assert read_dictionary(eds, 3)[0x1800][1].default == 0x80000183
    with pytest.raises(ValueError, match="NodeID 'five' is not a number"):
        read_dictionary(_dcf(tmp_path, "five", {}), 5)


def test_the_driver_refuses_a_dcf_for_another_node_naming_it(tmp_path: Path) -> None:
    path = _dcf(tmp_path, 9, {})
    with pytest.raises(HardwareError, match=r"^cannot read the y drive's EDS \(.*drive\.dcf\): "
                                            r"it is the DCF of node 9 \(\[DeviceComissioning\] "
                                            r"NodeID\), not of node 2$"):
        plans_of(**{"master.can.y_eds_file": str(path)})


def test_the_plan_takes_the_dcfs_values(tmp_path: Path) -> None:
    """A DCF that sets 0x6502 to profile position only (its EDS default has mode 8): the
    configured drive cannot run the loop, and the plan says so before the bus."""
    path = _dcf(tmp_path, 1, {"6502": "0x00000001"})
    hardware = inactive_rig(**{"master.can.x_eds_file": str(path)})
    with pytest.raises(PlanError, match=r"0x6502 \(supported drive modes\) = 0x00000001"):
        hardware.configure()
    hardware.cleanup()


def test_a_vendor_dcf_is_served_with_its_configured_values() -> None:
    """Elmo's DCF (ros_canopen) configures RPDO1 for every SYNC (ParameterValue 1 over the
    EDS's DefaultValue 255) and RPDO2 with another mapping: the emulated drive starts so."""
    path = CORPUS / "Elmo.dcf"
    dictionary = read_dictionary(path, 1)
    assert (dictionary[0x1400][2].default, file_value(dictionary[0x1400][2])) == (255, 1)
    device = DriveObjects(1, path, lambda *_: None, DriveRuntime(1), lambda: 0)
    assert device.raw(0x1400, 2) == 1 and device.rpdo.transmission_type == 1
    assert [v.index for v in device.rpdo.mapping] == [0x6040, 0x6060]
