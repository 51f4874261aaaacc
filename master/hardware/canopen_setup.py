"""The CiA 301 configuration sequence the CAN driver writes to each drive by SDO, planned from
the drive's own object dictionary (its EDS or DCF file, ``canopen.import_od``).

:func:`configuration_steps` lists, in order, every object write the cyclic loop needs, each
typed by the EDS's variable (the driver reads every one back): modes of operation (cyclic
synchronous position), the interpolation period 0x60C2 = Ts, the SYNC COB-ID (and the SYNC
counter's overflow value 0x1019 where the drives have it), the heartbeat
producer (0x1017) and consumer of the master's heartbeat (0x1016), the following error window
(0x6065), then RPDO1 and TPDO1 the standard way (disable the PDO with COB-ID bit 31,
transmission type 1 = every SYNC, mapping count 0, the entries, the count, the RPDO
deadline, enable). An object the EDS lacks or declares read-only is a :class:`PlanError`
before anything is sent.
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

from canopen import objectdictionary as od

from haptic.master.hardware import cia402
from haptic.master.hardware.interface import HardwareError

PDO_INVALID = 0x80000000
#: What the loop maps: RPDO1 controlword + target position, TPDO1 statusword + position.
RPDO1_OBJECTS = ((0x6040, 0), (0x607A, 0))
TPDO1_OBJECTS = ((0x6041, 0), (0x6064, 0))


class PlanError(HardwareError):
    """The EDS does not describe what the loop needs."""


@dataclass(frozen=True)
class SdoStep:
    """One SDO write: the EDS's variable and the value (read back after writing)."""

    variable: od.ODVariable
    value: int

    @property
    def label(self) -> str:
        """``0xIIII:SS (name)``."""
        return (f"0x{self.variable.index:04X}:{self.variable.subindex:02X} "
                f"({self.variable.name})")


def interpolation_period(sample_period_s: float) -> tuple[int, int]:
    """0x60C2's (value, index) with value * 10**index = ``sample_period_s`` exactly (value
    1-255, index -128..63); :class:`PlanError` when Ts has no such form."""
    period = Fraction(str(sample_period_s))
    for index in range(0, -10, -1):
        value = period / Fraction(10) ** index
        if value.denominator == 1 and 1 <= value.numerator <= 255:
            return int(value.numerator), index
    raise PlanError(f"Ts = {sample_period_s} s cannot be written to 0x60C2 as value * "
                    "10^index with value 1-255")


def variable(dictionary: od.ObjectDictionary, index: int, subindex: int,
             what: str) -> od.ODVariable:
    """The EDS's variable at ``index:subindex`` (a plain variable is at sub-index 0 only);
    :class:`PlanError` naming ``what`` (the drive and its EDS) when it is missing."""
    try:
        entry = dictionary[index]
        if isinstance(entry, od.ODVariable):
            if subindex != 0:
                raise KeyError(subindex)
            return entry
        return entry[subindex]
    except KeyError:
        raise PlanError(f"{what} has no object 0x{index:04X}:{subindex:02X}") from None


def mapping_entry(variable: od.ODVariable) -> int:
    """The PDO mapping entry of ``variable`` (index << 16 | subindex << 8 | bits)."""
    return (variable.index << 16) | (variable.subindex << 8) | len(variable)


def configuration_steps(dictionary: od.ObjectDictionary, node_id: int,
                        sample_period_s: float, master_node_id: int,
                        heartbeat_period_s: float, heartbeat_timeout_s: float,
                        rpdo_timeout_s: float, following_error_window_counts: int,
                        what: str, sync_counter_overflow: int = 0) -> list[SdoStep]:
    """The SDO writes that configure one drive (see the module docstring), in order;
    ``sync_counter_overflow`` > 0 writes the SYNC counter's overflow value (0x1019) too."""

    def step(index: int, subindex: int, value: int) -> SdoStep:
        var = variable(dictionary, index, subindex, what)
        if not var.writable:
            raise PlanError(f"{what}: 0x{index:04X}:{subindex:02X} ({var.name}) is not "
                            "writable")
        return SdoStep(var, value)

    value, exponent = interpolation_period(sample_period_s)
    steps = [
        step(0x6060, 0, cia402.MODE_CYCLIC_SYNC_POSITION),
        step(0x60C2, 1, value), step(0x60C2, 2, exponent),
        step(0x1005, 0, cia402.SYNC_COB_ID),
        *([step(0x1019, 0, sync_counter_overflow)] if sync_counter_overflow else []),
        step(0x1017, 0, max(1, round(heartbeat_period_s * 1e3))),
        step(0x1016, 1, (master_node_id << 16) | max(1, round(heartbeat_timeout_s * 1e3))),
        step(0x6065, 0, following_error_window_counts),
    ]
    for comm, mapping, base, objects, rpdo in (
            (0x1400, 0x1600, cia402.RPDO1_BASE, RPDO1_OBJECTS, True),
            (0x1800, 0x1A00, cia402.TPDO1_BASE, TPDO1_OBJECTS, False)):
        cob_id = base + node_id
        steps += [step(comm, 1, PDO_INVALID | cob_id), step(comm, 2, 1), step(mapping, 0, 0)]
        for number, (index, subindex) in enumerate(objects, start=1):
            mapped = variable(dictionary, index, subindex, what)
            if not mapped.pdo_mappable:
                raise PlanError(f"{what}: 0x{index:04X} ({mapped.name}) is not PDO-mappable")
            steps.append(step(mapping, number, mapping_entry(mapped)))
        steps.append(step(mapping, 0, len(objects)))
        if rpdo and rpdo_timeout_s > 0.0:
            steps.append(step(comm, 5, round(rpdo_timeout_s * 1e3)))
        steps.append(step(comm, 1, cob_id))
    return steps
