"""The CiA 301 configuration the CAN driver writes to each drive by SDO, planned from the
drive's own object dictionary (its EDS or DCF, :mod:`haptic.master.hardware.eds_reader`).

:func:`plan_drive` requires only what the cyclic synchronous position loop cannot run
without: the CiA 402 objects 0x6040, 0x6041, 0x6060 (writable), 0x6061, 0x607A and 0x6064,
0x1000, mode 8 in 0x6502 where the EDS gives it, one RPDO that can carry the controlword and
the target position and one TPDO that can carry the statusword and the position actual value
at every SYNC, and a drive-side watchdog. Every other object is used where the EDS has it
(writable, or already at the value wanted) and otherwise replaced by a named fallback
(:attr:`DrivePlan.fallbacks`, one line each):

- 0x60C2 interpolation period = Ts; without it the drive takes its cycle from the SYNCs;
- 0x1005 SYNC COB-ID = 0x80; without it the drive is taken to consume SYNC on 0x80;
- 0x1019 SYNC counter (the driver decides it for the bus, see ``sync_counter_overflow``);
- 0x1017 heartbeat producer; without it the master watches the drive by its TPDO only;
- 0x1016:01 heartbeat consumer of the master's heartbeat; without it life guarding
  (0x100C guard time, 0x100D life time factor, the master sending guarding requests) where
  the drive has that;
- 0x14xx:05 RPDO deadline (``rpdo_timeout_s``); 0x6065 following error window;
- 0x1018:02-04 identity (0x1018:01 and the EDS's product code are checked where given).

A drive left with no drive-side watchdog at all (no heartbeat consumer, no RPDO deadline, no
life guarding) is refused unless ``allow_no_drive_watchdog``.

PDOs: RPDO1/TPDO1 are mapped the standard way where their mapping is writable (disable with
COB-ID bit 31, transmission type 1, count 0, the entries, the count, the deadline, enable).
A static mapping (read-only in the EDS) that already carries the loop's objects, in PDO 1 or
another number, is used as it is: configure reads it back instead of writing it. Other PDOs
the EDS starts enabled are disabled. An object the loop needs that the EDS lacks, declares
read-only or not mappable is a :class:`PlanError` naming it, before anything is sent.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

from canopen import objectdictionary as od

from haptic.master.hardware import cia402
from haptic.master.hardware.eds_reader import file_value
from haptic.master.hardware.interface import HardwareError

PDO_INVALID = 0x80000000
#: What the loop maps: an RPDO with controlword + target position, a TPDO with statusword +
#: position actual value (in that order where the driver maps them itself).
RPDO1_OBJECTS = ((0x6040, 0), (0x607A, 0))
TPDO1_OBJECTS = ((0x6041, 0), (0x6064, 0))
#: The CiA 402 objects the loop cannot run without (0x6060 must be writable too).
REQUIRED_OBJECTS = ((0x1000, 0), (0x6040, 0), (0x6041, 0), (0x6060, 0), (0x6061, 0),
                    (0x607A, 0), (0x6064, 0))
#: 0x6502 bit of cyclic synchronous position (mode 8).
CSP_SUPPORTED = 1 << 7
#: PDO payload limits, bytes: classical CAN and CAN FD.
CLASSIC_PDO_BYTES, FD_PDO_BYTES = 8, 64


class PlanError(HardwareError):
    """The EDS does not describe what the loop needs."""


@dataclass(frozen=True)
class SdoStep:
    """One SDO step: write ``value`` to the EDS's variable and read it back, or (``write``
    False: an object the EDS fixes, e.g. a static mapping) only read it and expect
    ``value``."""

    variable: od.ODVariable
    value: int
    write: bool = True

    @property
    def label(self) -> str:
        """``0xIIII:SS (name)``."""
        return (f"0x{self.variable.index:04X}:{self.variable.subindex:02X} "
                f"({self.variable.name})")


@dataclass(frozen=True)
class PlanSettings:
    """What a plan takes from ``[master.can]`` and the model: Ts (s), the master's node id,
    heartbeat period and timeout (s), RPDO deadline (s; 0 off), following error window
    (counts), SYNC counter overflow (0 off), whether a drive without a watchdog is accepted,
    CAN FD (PDOs up to 64 bytes instead of 8)."""

    sample_period_s: float
    master_node_id: int
    heartbeat_period_s: float
    heartbeat_timeout_s: float
    rpdo_timeout_s: float
    following_error_window_counts: int
    sync_counter_overflow: int = 0
    allow_no_drive_watchdog: bool = False
    fd: bool = True


@dataclass(frozen=True)
class CyclicPdo:
    """The PDO the loop uses in one direction: its name (``RPDO1``), communication object
    (0x1400 + n or 0x1800 + n), COB-ID, mapping ((index, subindex, bits), in payload order),
    and whether it is the EDS's static mapping."""

    name: str
    comm_index: int
    cob_id: int
    mapping: tuple[tuple[int, int, int], ...]
    static: bool = False

    @property
    def size(self) -> int:
        """Payload length, bytes."""
        return sum(bits for _, _, bits in self.mapping) // 8

    def codec(self, dictionary: od.ObjectDictionary,
              objects: tuple[tuple[int, int], ...]) -> tuple[struct.Struct, bool]:
        """The payload as one ``struct`` whose values are ``objects`` (the loop's two, typed
        by ``dictionary``; any other mapped object is padding), and whether they come in the
        reverse order of ``objects``."""
        fmt = "<"
        order = []
        for index, subindex, bits in self.mapping:
            if (index, subindex) in objects:
                var = variable(dictionary, index, subindex, self.name)
                fmt += var.STRUCT_TYPES[var.data_type].format.lstrip("<")
                order.append((index, subindex))
            else:
                fmt += f"{bits // 8}x"
        return struct.Struct(fmt), order == list(reversed(objects))


@dataclass(frozen=True)
class DrivePlan:
    """One drive's configuration: its dictionary, the SDO steps in order, the PDOs the loop
    uses, the fallbacks taken (one line each), the drive-side watchdogs in use, whether the
    master supervises the drive's heartbeat (or its guarding answers), whether it sends
    guarding requests (life guarding), the 0x1018 sub-indices to read, whether 0x6502 is
    there to check on the drive, and the COB-IDs of other PDOs that stay on."""

    dictionary: od.ObjectDictionary
    steps: tuple[SdoStep, ...]
    rpdo: CyclicPdo
    tpdo: CyclicPdo
    fallbacks: tuple[str, ...] = ()
    watchdogs: tuple[str, ...] = ()
    heartbeat_supervised: bool = True
    guarded: bool = False
    identity: tuple[int, ...] = (1, 2, 3, 4)
    check_modes: bool = True
    ignored_cob_ids: frozenset[int] = field(default_factory=frozenset)


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


def find(dictionary: od.ObjectDictionary, index: int, subindex: int) -> od.ODVariable | None:
    """The EDS's variable at ``index:subindex``, ``None`` when it has none."""
    try:
        return variable(dictionary, index, subindex, "")
    except PlanError:
        return None


def mapping_entry(variable: od.ODVariable) -> int:
    """The PDO mapping entry of ``variable`` (index << 16 | subindex << 8 | bits)."""
    return (variable.index << 16) | (variable.subindex << 8) | len(variable)


def plan_drive(dictionary: od.ObjectDictionary, node_id: int, settings: PlanSettings,
               what: str) -> DrivePlan:
    """The configuration of one drive (see the module docstring); ``what`` names the drive
    and its EDS in errors. :class:`PlanError` when the EDS lacks what the loop needs."""
    return _Planner(dictionary, node_id, settings, what).plan()


def configuration_steps(dictionary: od.ObjectDictionary, node_id: int,
                        sample_period_s: float, master_node_id: int,
                        heartbeat_period_s: float, heartbeat_timeout_s: float,
                        rpdo_timeout_s: float, following_error_window_counts: int,
                        what: str, sync_counter_overflow: int = 0) -> list[SdoStep]:
    """The SDO steps of :func:`plan_drive` alone, in order (CAN FD, no drive without a
    watchdog)."""
    settings = PlanSettings(sample_period_s, master_node_id, heartbeat_period_s,
                            heartbeat_timeout_s, rpdo_timeout_s, following_error_window_counts,
                            sync_counter_overflow)
    return list(plan_drive(dictionary, node_id, settings, what).steps)


@dataclass(frozen=True)
class _PdoKind:
    """RPDOs or TPDOs: name, communication and mapping bases, predefined COB-ID base, the
    loop's objects."""

    name: str
    comm: int
    mapping: int
    cob_base: int
    objects: tuple[tuple[int, int], ...]

    @property
    def receive(self) -> bool:
        return self.name == "RPDO"


_RPDO = _PdoKind("RPDO", 0x1400, 0x1600, cia402.RPDO1_BASE, RPDO1_OBJECTS)
_TPDO = _PdoKind("TPDO", 0x1800, 0x1A00, cia402.TPDO1_BASE, TPDO1_OBJECTS)


class _Planner:
    """:func:`plan_drive`'s working state: the steps and fallbacks so far."""

    def __init__(self, dictionary: od.ObjectDictionary, node_id: int, settings: PlanSettings,
                 what: str) -> None:
        self.dictionary = dictionary
        self.node_id = node_id
        self.settings = settings
        self.what = what
        self.steps: list[SdoStep] = []
        self.fallbacks: list[str] = []
        self.watchdogs: list[str] = []

    def plan(self) -> DrivePlan:
        self._require_drive()
        self.steps.append(self._writable(0x6060, 0, cia402.MODE_CYCLIC_SYNC_POSITION))
        self._sync_objects()
        guarded, supervised = self._heartbeats()
        settings = self.settings
        window = settings.following_error_window_counts
        if not self._optional(0x6065, 0, window):
            self.fallbacks.append("no following error window (0x6065): the drive keeps its "
                                  "own")
        rpdo, rpdo_steps = _PdoPlanner(self, _RPDO).choose()
        tpdo, tpdo_steps = _PdoPlanner(self, _TPDO).choose()
        ignored = self._other_pdos_off({rpdo.comm_index, tpdo.comm_index})
        self.steps += rpdo_steps + tpdo_steps
        self._deadline_or_none(rpdo)
        identity = self._identity()
        return DrivePlan(self.dictionary, tuple(self.steps), rpdo, tpdo, tuple(self.fallbacks),
                         tuple(self.watchdogs), supervised, guarded, identity,
                         0x6502 in self.dictionary, frozenset(ignored))

    # --- objects ---------------------------------------------------------------------

    def _writable(self, index: int, subindex: int, value: int) -> SdoStep:
        """The write of an object the loop needs: :class:`PlanError` when it is missing or
        read-only."""
        var = variable(self.dictionary, index, subindex, self.what)
        if not var.writable:
            raise PlanError(f"{self.what}: 0x{index:04X}:{subindex:02X} ({var.name}) is not "
                            "writable")
        return SdoStep(var, value)

    def _optional(self, index: int, subindex: int, value: int) -> bool:
        """Plan ``value`` for an optional object: written where writable, read back where
        the EDS fixes it at ``value`` already; False (nothing planned) otherwise."""
        var = find(self.dictionary, index, subindex)
        if var is None:
            return False
        if var.writable:
            self.steps.append(SdoStep(var, value))
            return True
        if file_value(var) == value and var.readable:
            self.steps.append(SdoStep(var, value, write=False))
            return True
        return False

    def _require_drive(self) -> None:
        """The objects the loop cannot run without, the device type and mode 8 in 0x6502
        where the EDS gives them."""
        for index, subindex in REQUIRED_OBJECTS:
            if find(self.dictionary, index, subindex) is None:
                raise PlanError(f"{self.what} has no object 0x{index:04X}:{subindex:02X}: "
                                "the cyclic synchronous position loop cannot run without it")
        device_type = file_value(self.dictionary[0x1000])
        if isinstance(device_type, int) and device_type & 0xFFFF != 402:
            raise PlanError(f"{self.what} is not a CiA 402 drive (0x1000 device type "
                            f"0x{device_type:08X})")
        modes_var = find(self.dictionary, 0x6502, 0)
        modes = file_value(modes_var) if modes_var is not None else None
        if modes_var is None:
            self.fallbacks.append("no supported drive modes (0x6502): mode 8 is checked by "
                                  "0x6061 only")
        elif isinstance(modes, int) and not modes & CSP_SUPPORTED:
            raise PlanError(f"{self.what} has no cyclic synchronous position: 0x6502 "
                            f"(supported drive modes) = 0x{modes:08X}, bit 7 (mode 8) clear")
        mode = self.dictionary[0x6060]
        low, high = getattr(mode, "min", None), getattr(mode, "max", None)
        if (low is not None and low > cia402.MODE_CYCLIC_SYNC_POSITION) or (
                high is not None and high < cia402.MODE_CYCLIC_SYNC_POSITION):
            raise PlanError(f"{self.what}: 0x6060 (modes of operation) takes {low}..{high} "
                            "only, not 8 (cyclic synchronous position)")

    def _optional_all(self, values: list[tuple[int, int, int]]) -> bool:
        """:meth:`_optional` of every (index, subindex, value), or of none of them."""
        planned = len(self.steps)
        if all(self._optional(*entry) for entry in values):
            return True
        del self.steps[planned:]
        return False

    def _sync_objects(self) -> None:
        """0x60C2 = Ts, 0x1005 = 0x80 and the SYNC counter 0x1019, or their fallbacks."""
        if 0x60C2 not in self.dictionary:
            self.fallbacks.append("no interpolation period (0x60C2): the drive takes its "
                                  "cycle from the SYNCs")
        else:
            value, exponent = interpolation_period(self.settings.sample_period_s)
            if not self._optional_all([(0x60C2, 1, value), (0x60C2, 2, exponent)]):
                self.fallbacks.append("interpolation period (0x60C2) not settable to Ts: the "
                                      "drive keeps its own")
        if not self._optional(0x1005, 0, cia402.SYNC_COB_ID):
            self.fallbacks.append("no settable SYNC COB-ID (0x1005): the drive is taken to "
                                  "consume SYNC on 0x080")
        overflow = self.settings.sync_counter_overflow
        if overflow:
            self.steps.append(self._writable(0x1019, 0, overflow))

    def _heartbeats(self) -> tuple[bool, bool]:
        """The heartbeat producer (0x1017) and the consumer of the master's heartbeat
        (0x1016:01), or life guarding in its place; returns (guarded, the master supervises
        the drive's heartbeat or guarding answers)."""
        settings = self.settings
        period_ms = max(1, round(settings.heartbeat_period_s * 1e3))
        timeout_ms = max(1, round(settings.heartbeat_timeout_s * 1e3))
        consumer = find(self.dictionary, 0x1016, 1)
        if consumer is not None and consumer.writable:
            produced = self._optional(0x1017, 0, period_ms)
            if not produced:
                self.fallbacks.append("no heartbeat producer (0x1017): the master watches "
                                      "the drive by its TPDO at each SYNC")
            self.steps.append(SdoStep(consumer, (settings.master_node_id << 16) | timeout_ms))
            self.watchdogs.append("heartbeat consumer (0x1016)")
            return False, produced
        if self._guarding(period_ms):
            self.fallbacks.append("no heartbeat consumer (0x1016): life guarding (0x100C/"
                                  "0x100D) watches the master instead")
            self.watchdogs.append("life guarding (0x100C/0x100D)")
            return True, True
        produced = self._optional(0x1017, 0, period_ms)
        self.fallbacks.append("no heartbeat consumer (0x1016) and no life guarding (0x100C/"
                              "0x100D): the drive does not watch the master's heartbeat")
        if not produced:
            self.fallbacks.append("no heartbeat producer (0x1017): the master watches the "
                                  "drive by its TPDO at each SYNC")
        return False, produced

    def _guarding(self, period_ms: int) -> bool:
        """Plan life guarding (0x1017 = 0, 0x100C = the heartbeat period, 0x100D so that
        guard time x factor covers the heartbeat timeout); False where the drive cannot."""
        guard, factor = find(self.dictionary, 0x100C, 0), find(self.dictionary, 0x100D, 0)
        producer = find(self.dictionary, 0x1017, 0)
        if guard is None or factor is None or not (guard.writable and factor.writable):
            return False
        if producer is not None and not producer.writable and file_value(producer) != 0:
            return False  # a fixed heartbeat producer: the drive does not do node guarding
        lives = min(255, max(2, math.ceil(self.settings.heartbeat_timeout_s * 1e3 / period_ms)))
        if producer is not None:
            self._optional(0x1017, 0, 0)  # heartbeat off: CiA 301 guards only without it
        self.steps += [SdoStep(guard, period_ms), SdoStep(factor, lives)]
        return True

    def _deadline_or_none(self, rpdo: CyclicPdo) -> None:
        """Note the RPDO deadline as a watchdog; refuse a drive left with none (unless
        allowed)."""
        if any(s.variable.index == rpdo.comm_index and s.variable.subindex == 5
               for s in self.steps):
            self.watchdogs.append(f"RPDO deadline (0x{rpdo.comm_index:04X}:05)")
        elif self.settings.rpdo_timeout_s > 0.0:
            self.fallbacks.append(f"no RPDO deadline (0x{rpdo.comm_index:04X}:05): the drive "
                                  "does not watch the targets' arrival")
        if self.watchdogs:
            return
        off = (" (rpdo_timeout_s = 0 turns the deadline off)"
               if self.settings.rpdo_timeout_s <= 0.0 else "")
        if not self.settings.allow_no_drive_watchdog:
            raise PlanError(f"{self.what} would run without a drive-side watchdog: no "
                            "heartbeat consumer (0x1016), RPDO deadline (0x14xx:05) or life "
                            f"guarding (0x100C/0x100D){off}; [master.can] "
                            "allow_no_drive_watchdog = true accepts it")
        self.fallbacks.append("no drive-side watchdog: a stalled master leaves the drive "
                              "following its last target (allowed by [master.can] "
                              "allow_no_drive_watchdog)")

    def _identity(self) -> tuple[int, ...]:
        present = tuple(sub for sub in (1, 2, 3, 4) if find(self.dictionary, 0x1018, sub))
        missing = [f"0x1018:{sub:02X}" for sub in (1, 2, 3, 4) if sub not in present]
        if missing:
            self.fallbacks.append(f"identity without {', '.join(missing)} in the EDS: not "
                                  "read")
        return present

    def _other_pdos_off(self, used: set[int]) -> set[int]:
        """Disable the PDOs other than ``used`` that the EDS starts enabled; returns the
        COB-IDs of those that stay on (read-only COB-ID), noted as fallbacks."""
        ignored = set()
        for kind in (_RPDO, _TPDO):
            for number in range(512):
                cob = find(self.dictionary, kind.comm + number, 1)
                value = file_value(cob) if cob is not None else None
                if kind.comm + number in used or not isinstance(value, int) or (
                        value & PDO_INVALID):
                    continue
                if cob.writable:
                    self.steps.append(SdoStep(cob, value | PDO_INVALID))
                    continue
                ignored.add(value & 0x7FF)
                self.fallbacks.append(f"{kind.name}{number + 1} (0x{kind.comm + number:04X}) "
                                      "stays on (read-only COB-ID): its frames are ignored")
        return ignored


class _PdoPlanner:
    """The choice of the PDO the loop uses in one direction (:meth:`choose`)."""

    def __init__(self, planner: _Planner, kind: _PdoKind) -> None:
        self.planner = planner
        self.dictionary = planner.dictionary
        self.kind = kind
        self.reasons: list[str] = []

    def numbers(self) -> list[int]:
        """The PDO numbers (0-based) whose communication and mapping objects the EDS has."""
        kind = self.kind
        return [n for n in range(512)
                if kind.comm + n in self.dictionary and kind.mapping + n in self.dictionary]

    def choose(self) -> tuple[CyclicPdo, list[SdoStep]]:
        """PDO 1 mapped by the driver where its mapping is writable; else the first static
        mapping that carries the loop's objects; else the first other writable mapping;
        :class:`PlanError` naming what each offers when none fits."""
        numbers = self.numbers()
        if numbers and numbers[0] == 0 and self._mappable(0):
            return self._dynamic(0)
        for number in numbers:
            planned = self._static(number)
            if planned is not None:
                return planned
        for number in numbers:
            if number and self._mappable(number):
                return self._dynamic(number)
        kind = self.kind
        objects = " and ".join(f"0x{i:04X}:{s:02X}" for i, s in kind.objects)
        offers = "; ".join(self.reasons[:4]) or f"the EDS has no {kind.name}"
        raise PlanError(f"{self.planner.what}: no {kind.name} can carry {objects} at every "
                        f"SYNC: {offers}")

    def _cob_id(self, number: int) -> int | None:
        """The COB-ID the loop uses on PDO ``number``: the predefined one for PDOs 1-4, the
        EDS's for others."""
        if number < 4:
            return self.kind.cob_base + 0x100 * number + self.planner.node_id
        cob = find(self.dictionary, self.kind.comm + number, 1)
        value = file_value(cob) if cob is not None else None
        return value & 0x7FF if isinstance(value, int) and value & 0x7FF else None

    def _mappable(self, number: int) -> bool:
        """Whether the driver can map PDO ``number`` itself (COB-ID, count and entries
        writable); :class:`PlanError` when an object of the loop is not mappable."""
        kind, dictionary = self.kind, self.dictionary
        comm, mapping = kind.comm + number, kind.mapping + number
        subs = [find(dictionary, mapping, sub) for sub in range(len(kind.objects) + 1)]
        cob = find(dictionary, comm, 1)
        if cob is None or not cob.writable or any(s is None or not s.writable for s in subs) \
                or self._cob_id(number) is None:
            if subs[0] is not None and subs[0].writable:  # else _static says what it maps
                self.reasons.append(f"0x{mapping:04X} cannot be mapped (a read-only COB-ID or "
                                    "entry, or too few entries)")
            return False
        for index, subindex in kind.objects:
            mapped = variable(dictionary, index, subindex, self.planner.what)
            if not mapped.pdo_mappable:
                raise PlanError(f"{self.planner.what}: 0x{index:04X} ({mapped.name}) is not "
                                "PDO-mappable")
        return True

    def _dynamic(self, number: int) -> tuple[CyclicPdo, list[SdoStep]]:
        """Map PDO ``number`` the standard way."""
        kind, planner = self.kind, self.planner
        comm, mapping = kind.comm + number, kind.mapping + number
        cob_id = self._cob_id(number)
        assert cob_id is not None
        step = planner._writable
        steps = [step(comm, 1, PDO_INVALID | cob_id), self._transmission(number),
                 step(mapping, 0, 0)]
        entries = []
        for sub, (index, subindex) in enumerate(kind.objects, start=1):
            mapped = variable(self.dictionary, index, subindex, planner.what)
            steps.append(step(mapping, sub, mapping_entry(mapped)))
            entries.append((index, subindex, len(mapped)))
        steps += [step(mapping, 0, len(kind.objects)), *self._deadline(number),
                  step(comm, 1, cob_id)]
        if number:
            planner.fallbacks.append(f"{kind.name}1 cannot be mapped: {kind.name}{number + 1} "
                                     f"(0x{comm:04X}) carries the loop's objects")
        return CyclicPdo(f"{kind.name}{number + 1}", comm, cob_id, tuple(entries)), steps

    def _transmission(self, number: int) -> SdoStep:
        """Transmission type 1 (synchronous, every SYNC) on PDO ``number``, written."""
        return self.planner._writable(self.kind.comm + number, 2, 1)

    def _deadline(self, number: int) -> list[SdoStep]:
        """The RPDO deadline (0x14xx:05 = ``rpdo_timeout_s``) where the EDS has it writable."""
        timeout_s = self.planner.settings.rpdo_timeout_s
        deadline = find(self.dictionary, self.kind.comm + number, 5)
        if not self.kind.receive or timeout_s <= 0.0 or deadline is None or (
                not deadline.writable):
            return []
        return [SdoStep(deadline, round(timeout_s * 1e3))]

    def _static(self, number: int) -> tuple[CyclicPdo, list[SdoStep]] | None:
        """PDO ``number`` with the EDS's read-only mapping, where it carries the loop's
        objects (an RPDO nothing else but dummies) at every SYNC; ``None`` otherwise (the
        reason kept for the refusal)."""
        kind, dictionary = self.kind, self.dictionary
        comm, mapping = kind.comm + number, kind.mapping + number
        count_var = find(dictionary, mapping, 0)
        if count_var is None or count_var.writable:
            return None
        entries = self._static_entries(mapping)
        if entries is None:
            return None
        comm_steps = self._static_comm(number)
        if comm_steps is None:
            return None
        cob_id, steps = comm_steps
        checks = [SdoStep(count_var, len(entries), write=False)]
        for sub, (index, subindex, bits) in enumerate(entries, start=1):
            checks.append(SdoStep(variable(dictionary, mapping, sub, ""),
                                  (index << 16) | (subindex << 8) | bits, write=False))
        self.planner.fallbacks.append(f"{kind.name}{number + 1} (0x{comm:04X}) used with its "
                                      f"static mapping 0x{mapping:04X}, read back")
        return (CyclicPdo(f"{kind.name}{number + 1}", comm, cob_id, tuple(entries),
                          static=True), checks + steps)

    def _static_entries(self, mapping: int) -> list[tuple[int, int, int]] | None:
        """The EDS's entries of the read-only ``mapping`` where they fit the loop."""
        kind, dictionary = self.kind, self.dictionary
        count = file_value(find(dictionary, mapping, 0))
        values = [find(dictionary, mapping, sub) for sub in range(1, (count or 0) + 1)]
        raw = [file_value(v) if v is not None else None for v in values]
        if not isinstance(count, int) or not all(isinstance(v, int) for v in raw):
            self.reasons.append(f"0x{mapping:04X} is read-only and its entries are not in "
                                "the EDS")
            return None
        entries = [(v >> 16, (v >> 8) & 0xFF, v & 0xFF) for v in raw]
        named = ", ".join(f"0x{i:04X}:{s:02X}" for i, s, _ in entries) or "nothing"
        found = {(i, s): bits for i, s, bits in entries}
        extra = [(i, s) for i, s, _ in entries if (i, s) not in kind.objects and i > 7]
        limit = FD_PDO_BYTES if self.planner.settings.fd else CLASSIC_PDO_BYTES
        fits = all(found.get(obj) == len(variable(dictionary, *obj, "")) for obj in kind.objects)
        if not fits or (kind.receive and extra) or any(b % 8 for _, _, b in entries) or (
                sum(b for _, _, b in entries) > 8 * limit):
            self.reasons.append(f"0x{mapping:04X} is read-only and maps {named}")
            return None
        return entries

    def _static_comm(self, number: int) -> tuple[int, list[SdoStep]] | None:
        """The COB-ID and the communication steps of a static PDO: enabled and sent (or
        applied) at every SYNC; ``None`` where its fixed parameters do not allow that."""
        kind, dictionary = self.kind, self.dictionary
        comm = kind.comm + number
        cob_var, type_var = find(dictionary, comm, 1), find(dictionary, comm, 2)
        cob_value = file_value(cob_var) if cob_var is not None else None
        kind_value = file_value(type_var) if type_var is not None else None
        if cob_var is not None and cob_var.writable:
            cob_id = self._cob_id(number)
        elif isinstance(cob_value, int) and not cob_value & PDO_INVALID:
            cob_id = cob_value & 0x7FF
        else:
            cob_id = None
        synchronous = (type_var is not None and type_var.writable) or (
            isinstance(kind_value, int) and (kind_value == 1 if not kind.receive
                                             else kind_value <= 240))
        if cob_id is None or not synchronous:
            self.reasons.append(f"0x{comm:04X} cannot be enabled for every SYNC")
            return None
        steps: list[SdoStep] = []
        writable_cob = cob_var is not None and cob_var.writable
        if writable_cob:
            steps.append(SdoStep(cob_var, PDO_INVALID | cob_id))
        if type_var is not None and type_var.writable:
            steps.append(self._transmission(number))
        steps += self._deadline(number)
        if writable_cob:
            steps.append(SdoStep(cob_var, cob_id))
        elif cob_var is not None:
            steps.append(SdoStep(cob_var, cob_value, write=False))
        return cob_id, steps


def describe(plan: DrivePlan) -> dict[str, Any]:
    """A plan as plain data (the run's summary): PDOs, watchdogs, fallbacks."""
    return {"rpdo": f"{plan.rpdo.name} 0x{plan.rpdo.cob_id:03X}"
                    + (" static" if plan.rpdo.static else ""),
            "tpdo": f"{plan.tpdo.name} 0x{plan.tpdo.cob_id:03X}"
                    + (" static" if plan.tpdo.static else ""),
            "watchdogs": list(plan.watchdogs), "fallbacks": list(plan.fallbacks)}
