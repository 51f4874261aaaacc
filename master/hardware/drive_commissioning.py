"""From the drives' EDS files to configured drives: each drive's plan
(:mod:`haptic.master.hardware.canopen_setup`) with the fallbacks it takes and the SYNC
counter the bus can use, then each drive configured by SDO from its plan (identity checked,
every write read back, every object the EDS fixes read).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from haptic.master.hardware import cia402
from haptic.master.hardware.canopen_setup import (
    CSP_SUPPORTED,
    DrivePlan,
    PlanSettings,
    plan_drive,
    variable,
)
from haptic.master.hardware.drive_device import load_drive_dictionary
from haptic.master.hardware.interface import AXES, HardwareError
from haptic.master.hardware.sdo_client import SdoClient
from haptic.master.settings import CanSettings


@dataclass(frozen=True)
class DrivePlans:
    """Both drives' plans, the fallbacks taken (one line each, naming the drive), the SYNC
    counter's overflow value in use (0 off) and why."""

    plans: list[DrivePlan]
    fallbacks: list[str]
    sync_counter_overflow: int
    sync_counter_note: str


def plan_drives(settings: CanSettings, sample_period_s: float, fd: bool) -> DrivePlans:
    """Each drive's plan from its EDS; :class:`HardwareError` when an EDS cannot be read.
    The SYNC counter (0x1019) is on when configured and every drive's EDS has the object
    writable (one SYNC serves all: a drive without it expects SYNCs without data)."""
    window_counts = int(round(settings.following_error_window_m / settings.metres_per_count))
    dictionaries = []
    for axis, (node, eds) in enumerate(zip(settings.node_ids, settings.eds_files,
                                           strict=True)):
        what = f"{AXES[axis]} drive's EDS ({eds or 'packaged'})"
        try:
            dictionaries.append((load_drive_dictionary(eds, node), what))
        except (OSError, ValueError, KeyError) as error:
            raise HardwareError(f"cannot read the {what}: {error}") from None
    overflow, note = _sync_counter(settings.sync_counter_overflow, dictionaries)
    plan_settings = PlanSettings(
        sample_period_s, settings.master_node_id, settings.heartbeat_period_s,
        settings.heartbeat_timeout_s, settings.rpdo_timeout_s,
        min(window_counts, 0xFFFFFFFF), overflow, settings.allow_no_drive_watchdog, fd)
    plans = [plan_drive(dictionary, node, plan_settings, what)
             for node, (dictionary, what) in zip(settings.node_ids, dictionaries, strict=True)]
    fallbacks = [f"{AXES[axis]} drive (node {settings.node_ids[axis]}): {line}"
                 for axis, plan in enumerate(plans) for line in plan.fallbacks]
    if note.startswith("SYNC counter off: the"):
        fallbacks.append(note)
    return DrivePlans(plans, fallbacks, overflow, note)


def _sync_counter(overflow: int, dictionaries: list[tuple[Any, str]]) -> tuple[int, str]:
    """The SYNC counter's overflow value in use (0 off) and its note."""
    lacking = [what for dictionary, what in dictionaries
               if 0x1019 not in dictionary or not dictionary[0x1019].writable]
    if overflow and lacking:
        return 0, (f"SYNC counter off: the {' and the '.join(lacking)} "
                   f"{'have' if len(lacking) > 1 else 'has'} no 0x1019")
    return overflow, (f"SYNC counter 1..{overflow}" if overflow
                      else "SYNC counter off ([master.can] sync_counter_overflow = 0)")


def configure_drive(sdo: SdoClient, node: int, plan: DrivePlan, name: str) -> None:
    """Configure the drive ``name`` (``node``) by SDO from ``plan`` (after
    :func:`read_identity`). :class:`HardwareError` when an object does not read back as
    planned or the drive is not in cyclic synchronous position then."""
    for step in plan.steps:
        if step.write:
            sdo.write(node, step.variable, step.value, name)
        back = sdo.read(node, step.variable, name)
        if back != step.value:
            raise HardwareError(f"{name}: {step.label} reads back {back} after writing "
                                f"{step.value}" if step.write else
                                f"{name}: {step.label} reads {back}, not the EDS's fixed "
                                f"{step.value}")
    mode = sdo.read(node, variable(plan.dictionary, 0x6061, 0, name), name)
    if mode != cia402.MODE_CYCLIC_SYNC_POSITION:
        raise HardwareError(f"{name} reports mode {mode}, not cyclic synchronous "
                            "position (8)")


def read_identity(sdo: SdoClient, node: int, plan: DrivePlan, name: str) -> dict[str, int]:
    """The identity of the drive ``name`` (``node``): 0x1000 and the 0x1018 entries its EDS
    has. :class:`HardwareError` when it is not a CiA 402 drive with cyclic synchronous
    position (where its EDS has 0x6502) or another device than its EDS describes."""
    dictionary = plan.dictionary
    device_type = sdo.read(node, variable(dictionary, 0x1000, 0, name), name)
    if device_type & 0xFFFF != 402:
        raise HardwareError(f"{name} is not a CiA 402 drive (0x1000 device type "
                            f"0x{device_type:08X})")
    if plan.check_modes:
        modes = sdo.read(node, variable(dictionary, 0x6502, 0, name), name)
        if not modes & CSP_SUPPORTED:
            raise HardwareError(f"{name} has no cyclic synchronous position: 0x6502 "
                                f"reads 0x{modes:08X} (bit 7, mode 8, clear)")
    identity = {"device_type": device_type}
    for subindex, key in ((1, "vendor_id"), (2, "product_code"), (3, "revision"),
                          (4, "serial_number")):
        if subindex in plan.identity:
            identity[key] = sdo.read(node, variable(dictionary, 0x1018, subindex, name), name)
    info = dictionary.device_information
    for key, expected in (("vendor_id", info.vendor_number),
                          ("product_code", info.product_number)):
        if expected and key in identity and identity[key] != expected:
            raise HardwareError(f"{name} reports {key} 0x{identity[key]:08X}, its EDS "
                                f"describes 0x{expected:08X}: another device or EDS")
    return identity
