"""The ``[control]`` table: which control scheme runs (the paper's, with the passivity layer
TDPA, or one of the lane laws: wave variables, four-channel with or without its TDPA,
model-mediated), the passivity layer's limits, the paper mode's drift coupling and the wave
variables' settings."""

from __future__ import annotations

from typing import Any

from haptic.common.config.fields import Field, Schema
from haptic.common.control.law_settings import LANE_CONTROLS, LawSettings
from haptic.common.model.drift import DriftCoupling
from haptic.common.model.errors import ConfigError
from haptic.common.model.passivity import MODES, PassivitySettings

#: Every control mode: the paper's scheme and its passivity layer (the programs' HandleState
#: and ToolState), then the lane laws (their own messages, common/wire/law_messages.py).
CONTROL_MODES = MODES + LANE_CONTROLS

CONTROL_SCHEMA: Schema = {
    "mode": Field("str", "\"paper\": the paper's scheme as published; \"tdpa\": with the "
                  "passivity layer (time domain passivity, docs/control.md); \"wave\", "
                  "\"four-channel\", \"four-channel-tdpa\", \"mmt\": the lane laws "
                  "(docs/architectures.md). Both programs must run the same mode.",
                  choices=CONTROL_MODES),
    "wave_impedance_N_s_per_m": Field("float", "wave: the wave impedance b, N s/m.",
                                      minimum=0.0, exclusive_minimum=True),
    "wave_filter_bandwidth_rad_s": Field("float", "wave: the wave filter's bandwidth, rad/s "
                                         "(0: off).", minimum=0.0),
    "wave_drift_gain_per_s": Field("float", "wave: the drift correction's gain on the wave "
                                   "integrals, 1/s (0: off).", minimum=0.0),
    "force_floor_N": Field("float", "tdpa: below this operator force the master's passivity "
                           "controller does not act, N.", minimum=0.0, exclusive_minimum=True),
    "conductance_max_m_per_N_s": Field("float", "tdpa: cap of the master's adaptive "
                                       "conductance, m/(N s).", minimum=0.0,
                                       exclusive_minimum=True),
    "correction_speed_max_m_per_s": Field("float", "tdpa: cap of the master's correction "
                                          "speed, m/s.", minimum=0.0, exclusive_minimum=True),
    "correction_accel_max_m_per_s2": Field("float", "tdpa: how fast the master's correction "
                                           "speed may grow, m/s^2.", minimum=0.0,
                                           exclusive_minimum=True),
    "velocity_floor_m_per_s": Field("float", "tdpa: below this tool speed the slave's damper "
                                    "does not act, m/s.", minimum=0.0, exclusive_minimum=True),
    "damper_max_N_s_per_m": Field("float", "tdpa: cap of the slave's adaptive damper, N s/m "
                                  "(at most 2 Mt/Ts keeps it stable).", minimum=0.0,
                                  exclusive_minimum=True),
    "damper_force_max_N": Field("float", "tdpa: cap of the damper's force, N.", minimum=0.0,
                                exclusive_minimum=True),
    "damper_force_rate_N_per_s": Field("float", "tdpa: how fast the damper's force may grow, "
                                       "N/s.", minimum=0.0, exclusive_minimum=True),
    "credit_max_J": Field("float", "tdpa: the most energy a side may hold to spend later, J.",
                          minimum=0.0),
    "master_keep_J": Field("float", "tdpa: energy of its own input the master keeps to return "
                           "itself, J (0: all goes to the slave).", minimum=0.0),
    "slave_keep_J": Field("float", "tdpa: the same on the slave, J.", minimum=0.0),
    "drift_stiffness_N_per_m": Field("float", "tdpa: stiffness of the drift correction pulling "
                                     "the tool to Ah1 yh, N/m (0: off).", minimum=0.0),
    "drift_force_max_N": Field("float", "tdpa: cap of the drift correction's force, N.",
                               minimum=0.0),
    "master_drift_rate_per_s": Field(
        "float", "tdpa: the master's drift correction, the share of the gap to the tool "
        "(Ah1^-1 yt) its handle command closes per second, 1/s (0: off).", minimum=0.0),
    "master_drift_speed_max_m_per_s": Field(
        "float", "tdpa: the most speed of that correction, m/s.", minimum=0.0),
    "slave_drift_rate_per_s": Field(
        "float", "tdpa: the slave's drift correction, the share of the gap to the handle "
        "(Ah1 yh) the tool closes per second where the environment's force allows it (free), "
        "else paid from the account, 1/s (0: off).", minimum=0.0),
    "slave_drift_speed_max_m_per_s": Field(
        "float", "tdpa: the most speed of that correction, m/s.", minimum=0.0),
    "paper_drift_stiffness_N_per_m": Field(
        "float", "paper: stiffness kp of the slow drift coupling vt += kp wc/(s + wc) (Ah1 yh - "
        "yt) at the slave, N/m (0: off, the paper's scheme exactly; haptic-analyze includes "
        "it).", minimum=0.0),
    "paper_drift_bandwidth_rad_s": Field(
        "float", "paper: its low-pass bandwidth wc, rad/s.", minimum=0.0,
        exclusive_minimum=True),
}


def drift_coupling(config: dict[str, Any], period_s: float) -> DriftCoupling | None:
    """The paper mode's drift coupling, or None when it is off (or in ``tdpa`` mode)."""
    section = config["control"]
    if section["mode"] != "paper" or section["paper_drift_stiffness_N_per_m"] == 0.0:
        return None
    return DriftCoupling(float(section["paper_drift_stiffness_N_per_m"]),
                         float(section["paper_drift_bandwidth_rad_s"]), float(period_s))


def drift_parameters(config: dict[str, Any]) -> tuple[float, float] | None:
    """(kp N/m, wc rad/s) of the paper mode's drift coupling for the analysis, or None."""
    section = config["control"]
    if section["mode"] != "paper" or section["paper_drift_stiffness_N_per_m"] == 0.0:
        return None
    return (float(section["paper_drift_stiffness_N_per_m"]),
            float(section["paper_drift_bandwidth_rad_s"]))


def control_mode(config: dict[str, Any]) -> str:
    """The validated configuration's control mode (one of :data:`CONTROL_MODES`)."""
    return str(config["control"]["mode"])


def lane_law(config: dict[str, Any]) -> str | None:
    """The lane law the configuration runs (one of ``LANE_CONTROLS``), or None for the paper's
    scheme and its passivity layer."""
    mode = str(config["control"]["mode"])
    return mode if mode in LANE_CONTROLS else None


def law_settings(config: dict[str, Any]) -> LawSettings:
    """A lane law's settings: the model's period (s), the wave variables' and the TDPA's (for
    ``four-channel-tdpa``) from ``[control]``."""
    section = config["control"]
    return LawSettings(period_s=float(config["model"]["sample_period_s"]),
                       wave_impedance_N_s_per_m=float(section["wave_impedance_N_s_per_m"]),
                       wave_filter_bandwidth_rad_s=float(
                           section["wave_filter_bandwidth_rad_s"]),
                       wave_drift_gain_per_s=float(section["wave_drift_gain_per_s"]),
                       passivity=standby_passivity_settings(config))


def passivity_settings(config: dict[str, Any]) -> PassivitySettings | None:
    """The passivity layer's settings in ``tdpa`` mode; None in ``paper`` mode."""
    if config["control"]["mode"] != "tdpa":
        return None
    return standby_passivity_settings(config)


def standby_passivity_settings(config: dict[str, Any]) -> PassivitySettings:
    """The passivity layer's settings whatever the mode: in ``paper`` mode the layer is built
    switched off for the margin governor's run-time switch (``[governor] action = "tdpa"``)."""
    section = config["control"]
    names = PassivitySettings.__dataclass_fields__
    return PassivitySettings(**{name: float(section[name]) for name in names})


def check_lane_law(config: dict[str, Any], record_path: object = None) -> None:
    """What a lane-law mode needs of the rest of the configuration (raises ConfigError naming
    the key): the laws exchange the tool's and the handle's coordinates one to one
    (``model.position_ratio_ah1`` the identity); the margin governor, the ROS 2 bridge and
    the MCAP recording (``--record``) belong to the paper's scheme and its passivity layer."""
    mode = config["control"]["mode"]
    ratio = config["model"]["position_ratio_ah1"]
    if [list(map(float, row)) for row in ratio] != [[1.0, 0.0], [0.0, 1.0]]:
        raise ConfigError("model.position_ratio_ah1", f"must be the identity with [control] "
                          f"mode = \"{mode}\" (the lane laws scale no positions)")
    if config["governor"]["enabled"]:
        raise ConfigError("governor.enabled", f"the margin governor runs in the paper and "
                          f"tdpa modes only, not with [control] mode = \"{mode}\"")
    if config["ros2"]["enabled"]:
        raise ConfigError("ros2.enabled", f"the ROS 2 bridge runs in the paper and tdpa modes "
                          f"only, not with [control] mode = \"{mode}\"")
    if record_path:
        raise ConfigError("--record", f"the MCAP recording runs in the paper and tdpa modes "
                          f"only, not with [control] mode = \"{mode}\"")
