"""Typed views of the validated ``[master]`` configuration (units in the field names)."""

from __future__ import annotations

import ipaddress
import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from haptic.common.config import ConfigError
from haptic.common.model.work_area import SharedWorkArea
from haptic.master.simulated_rig.operator import OperatorModel, parse_operator_spec


@dataclass(frozen=True)
class CanSettings:
    """The CAN bus, the two CiA 402 drives, the force sensor and the unit conversions."""

    interface: str
    channel: str
    bitrate: int
    x_node_id: int
    y_node_id: int
    dbc_file: str
    pdo_timeout_s: float
    enable_timeout_cycles: int
    lead_screw_pitch_m_per_rev: float
    encoder_counts_per_rev: int
    force_scale_N_per_count: tuple[float, float]
    force_offset_count: tuple[float, float]
    x_eds_file: str = ""
    y_eds_file: str = ""
    master_node_id: int = 127
    heartbeat_period_s: float = 0.1
    heartbeat_timeout_s: float = 0.3
    rpdo_timeout_s: float = 0.1
    following_error_window_m: float = 0.01
    bus_load_limit: float = 0.7
    fd: bool = True
    data_bitrate: int = 5_000_000
    sync_counter_overflow: int = 240
    sync_lead_s: float = 0.0
    allow_no_drive_watchdog: bool = False

    @property
    def eds_files(self) -> tuple[str, str]:
        """EDS/DCF files of the x and y drives (empty: the packaged emulated drive's)."""
        return (self.x_eds_file, self.y_eds_file)

    @property
    def node_ids(self) -> tuple[int, int]:
        """Node ids of the x and y drives."""
        return (self.x_node_id, self.y_node_id)

    @property
    def metres_per_count(self) -> float:
        """Handle travel per encoder count, m."""
        return self.lead_screw_pitch_m_per_rev / self.encoder_counts_per_rev

    def counts_from_metres(self, position_m: np.ndarray) -> np.ndarray:
        """Encoder counts (int64) for positions in m, rounded to the nearest count."""
        return np.rint(np.asarray(position_m, float) / self.metres_per_count).astype(np.int64)

    def metres_from_counts(self, counts: np.ndarray) -> np.ndarray:
        """Positions in m for encoder counts."""
        return np.asarray(counts, float) * self.metres_per_count

    def count_from_metres(self, position_m: float) -> int:
        """:meth:`counts_from_metres` of one position, m (a Python int; the emulated drives'
        per-SYNC path, where numpy's call costs more than the arithmetic)."""
        counts = float(position_m) / self.metres_per_count
        if not math.isfinite(counts):
            return int(self.counts_from_metres(np.array(position_m)))
        return round(counts)

    def metres_from_count(self, count: int) -> float:
        """:meth:`metres_from_counts` of one count, m."""
        return float(count) * self.metres_per_count


@dataclass(frozen=True)
class EmulatorSettings:
    """The bus between the ``sim`` backend's CAN driver and its emulator process
    (``haptic-rig-sim``). A run's private bus: ``channel`` "" (unix_datagram: a temporary
    directory) or ``port`` 0 (udp_multicast: a free UDP port)."""

    interface: str
    channel: str
    port: int
    start_timeout_s: float

    def bus_options(self, channel: str, port: int) -> dict[str, Any]:
        """``can.Bus`` keyword arguments for ``channel`` (and UDP ``port``: udp_multicast
        only takes one)."""
        options: dict[str, Any] = {"interface": self.interface, "channel": channel}
        if self.interface == "udp_multicast":
            options["port"] = port
        return options


@dataclass(frozen=True)
class SimSettings:
    """The simulated rig: the operator and sensor it simulates, the virtual bus channel of
    the in-process variant and the emulator process's bus."""

    channel: str
    pdo_timeout_s: float
    operator: OperatorModel
    force_noise_std_N: float
    seed: int
    initial_position_m: tuple[float, float]
    emulator: EmulatorSettings


@dataclass(frozen=True)
class SafetySettings:
    """Limits the master node enforces before anything reaches a drive."""

    force_limit_N: float
    force_trip_N: float
    velocity_limit_m_per_s: float
    velocity_trip_m_per_s: float
    workspace_min_m: tuple[float, float]
    workspace_max_m: tuple[float, float]
    workspace_trip_margin_m: float
    ramp_small_force_N: float
    ramp_small_samples: int
    ramp_time_s: float


@dataclass(frozen=True)
class MasterSettings:
    """The whole ``[master]`` section."""

    rig: str
    can: CanSettings
    sim: SimSettings
    safety: SafetySettings


def safety_from_table(table: dict[str, Any], prefix: str = "master.safety") -> SafetySettings:
    """:class:`SafetySettings` from a validated table, with the cross-key checks."""
    safety = SafetySettings(
        **{k: (tuple(v) if isinstance(v, list) else v) for k, v in table.items()}
    )
    if not safety.force_trip_N >= safety.force_limit_N:
        raise ConfigError(f"{prefix}.force_trip_N", "must be >= force_limit_N")
    if not safety.velocity_trip_m_per_s >= safety.velocity_limit_m_per_s:
        raise ConfigError(f"{prefix}.velocity_trip_m_per_s", "must be >= velocity_limit_m_per_s")
    if not all(lo < hi for lo, hi in zip(safety.workspace_min_m, safety.workspace_max_m,
                                          strict=True)):
        raise ConfigError(f"{prefix}.workspace_max_m", "must exceed workspace_min_m on each axis")
    if not safety.ramp_small_force_N < safety.force_trip_N:
        raise ConfigError(f"{prefix}.ramp_small_force_N", "must be < force_trip_N")
    return safety


def with_work_area(safety: SafetySettings, area: SharedWorkArea) -> SafetySettings:
    """``safety`` with its workspace box narrowed to the handle's side of the work area both
    sides hold (common/model/work_area.py): the handle stops where the tool does."""
    return replace(safety, workspace_min_m=area.handle_low_m, workspace_max_m=area.handle_high_m)


def emulator_settings(table: dict[str, Any],
                      prefix: str = "master.sim.emulator") -> EmulatorSettings:
    """:class:`EmulatorSettings` from a validated table: the interface must be one python-can
    has here (its own and its plug-ins', this package's unix_datagram among them; checked here,
    on the master's side, so reading a configuration needs no CAN stack), and a udp_multicast
    channel a multicast group (:class:`ConfigError` naming the key)."""
    emulator = EmulatorSettings(**table)
    from can.interfaces import VALID_INTERFACES

    if emulator.interface not in VALID_INTERFACES:
        raise ConfigError(f"{prefix}.interface", f"{emulator.interface!r} is not a python-can "
                          "interface here; one that crosses processes: unix_datagram or "
                          "udp_multicast")
    if emulator.interface == "udp_multicast":
        check_multicast_group(emulator.channel, f"{prefix}.channel")
    return emulator


def check_multicast_group(channel: str, key: str) -> None:
    """:class:`ConfigError` naming ``key`` unless ``channel`` is an IPv4 (224.0.0.0/4) or
    IPv6 (ff00::/8) multicast address, as python-can's udp_multicast needs."""
    try:
        multicast = ipaddress.ip_address(channel).is_multicast
    except ValueError:
        multicast = False
    if not multicast:
        raise ConfigError(key, "udp_multicast needs a multicast IP address, e.g. "
                          f"239.74.163.2 (got {channel!r})")


def master_settings(config: dict[str, Any]) -> MasterSettings:
    """:class:`MasterSettings` from a validated configuration; :class:`ConfigError` names
    the key for cross-key problems."""
    section = config["master"]
    can_table = dict(section["can"])
    for key in ("force_scale_N_per_count", "force_offset_count"):
        can_table[key] = tuple(can_table[key])
    can = CanSettings(**can_table)
    if can.x_node_id == can.y_node_id:
        raise ConfigError("master.can.y_node_id", "must differ from x_node_id")
    if can.master_node_id in can.node_ids:
        raise ConfigError("master.can.master_node_id", "must differ from the drives' node ids")
    if not can.heartbeat_timeout_s > can.heartbeat_period_s:
        raise ConfigError("master.can.heartbeat_timeout_s", "must exceed heartbeat_period_s")
    if any(scale == 0.0 for scale in can.force_scale_N_per_count):
        raise ConfigError("master.can.force_scale_N_per_count", "must not be zero")
    sim_table = dict(section["sim"])
    sim = SimSettings(
        channel=sim_table["channel"], pdo_timeout_s=sim_table["pdo_timeout_s"],
        operator=parse_operator_spec(sim_table["operator"], "master.sim.operator"),
        force_noise_std_N=sim_table["force_noise_std_N"], seed=sim_table["seed"],
        initial_position_m=tuple(sim_table["initial_position_m"]),
        emulator=emulator_settings(sim_table["emulator"]),
    )
    from haptic.master.tool_guard import ToolGuardSettings  # its cross-key check, at start

    ToolGuardSettings.from_config(config)
    return MasterSettings(section["rig"], can, sim, safety_from_table(section["safety"]))
