"""The ``[control]`` table: which control scheme runs (the paper's, or with the passivity
layer, TDPA), the passivity layer's limits and the paper mode's drift coupling."""

from __future__ import annotations

from typing import Any

from haptic.common.config.fields import Field, Schema
from haptic.common.model.drift import DriftCoupling
from haptic.common.model.passivity import MODES, PassivitySettings

CONTROL_SCHEMA: Schema = {
    "mode": Field("str", "\"paper\": the paper's scheme as published; \"tdpa\": with the "
                  "passivity layer (time domain passivity, docs/control.md). Both programs "
                  "must run the same mode.", choices=MODES),
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
    """The validated configuration's control mode, "paper" or "tdpa"."""
    return str(config["control"]["mode"])


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
