"""The configuration schema: every key a program accepts, with its unit and bounds.

One table per part of the system; :mod:`haptic.common.config` holds the rules that apply it.
"""

from __future__ import annotations

from typing import Any

from haptic.common.config.control_schema import CONTROL_SCHEMA
from haptic.common.config.fields import Field, Schema
from haptic.common.config.governor_schema import GOVERNOR_SCHEMA
from haptic.common.config.link_schema import LINK_SCHEMA
from haptic.common.config.lockstep_schema import LOCKSTEP_SCHEMA
from haptic.common.config.master_schema import MASTER_SCHEMA
from haptic.common.config.ros2_schema import ROS2_SCHEMA
from haptic.common.config.runner_schema import RUNNER_SCHEMA
from haptic.common.config.slave_schema import SLAVE_SCHEMA
from haptic.common.model.errors import ConfigError


def _leading_nonzero(coefficients: list[float]) -> str | None:
    if coefficients[0] == 0.0 and any(c != 0.0 for c in coefficients):
        return "leading coefficient (highest power of s first) must be non-zero"
    return None


def _nonzero_polynomial(coefficients: list[float]) -> str | None:
    if all(c == 0.0 for c in coefficients):
        return "must not be the zero polynomial"
    return _leading_nonzero(coefficients)


def _diagonal_nonsingular(matrix: Any) -> str | None:
    if matrix[0][1] != 0.0 or matrix[1][0] != 0.0:
        return "must be diagonal (the x and y axes are independent)"
    if matrix[0][0] == 0.0 or matrix[1][1] == 0.0:
        return "is singular (a zero diagonal element); it must be invertible"
    return None


#: Smallest non-zero tool parameter accepted (in its own SI unit): below it the value is
#: rounding noise that would make Gt's response overflow.
SMALLEST_NONZERO_PARAMETER = 1e-9


def _zero_or_meaningful(value: float) -> str | None:
    if 0.0 < value < SMALLEST_NONZERO_PARAMETER:
        return f"must be 0 or at least {SMALLEST_NONZERO_PARAMETER:g} (got {value:g})"
    return None


def _polynomial(doc: str, together: tuple[str, ...] = ()) -> Field:
    return Field("float_list", doc, check=_leading_nonzero, together=together)


def _denominator(doc: str, together: tuple[str, ...] = ()) -> Field:
    return Field("float_list", doc, check=_nonzero_polynomial, together=together)


AXIS_SCHEMA: Schema = {
    "handle_actuator_gh_num": _polynomial(
        "Gh numerator in s: handle actuator with operator, position command (m) to handle "
        "position (m), dimensionless (paper eqs 31, 32).",
        together=("handle_actuator_gh_den",)),
    "handle_actuator_gh_den": _denominator("Gh denominator in s.",
        together=("handle_actuator_gh_num",)),
    "operator_impedance_th": _polynomial(
        "Th, operator arm impedance polynomial in s, N/m: [kg, N s/m, N/m] (eq 33)."
    ),
    "environment_impedance_tt": _polynomial(
        "Tt, environment impedance polynomial in s, N/m (eq 33)."
    ),
    "handle_compliance_sh_num": _polynomial("Sh numerator, handle compliance, m/N.",
        together=("handle_compliance_sh_den",)),
    "handle_compliance_sh_den": _denominator("Sh denominator.",
        together=("handle_compliance_sh_num",)),
    "tool_compliance_st_num": _polynomial("St numerator, tool compliance, m/N.",
        together=("tool_compliance_st_den",)),
    "tool_compliance_st_den": _denominator("St denominator.",
        together=("tool_compliance_st_num",)),
    "tool_mass_kg": Field("float", "Mt, virtual tool mass, kg (eq 5).", minimum=0.0,
                          check=_zero_or_meaningful),
    "tool_damping_N_s_per_m": Field(
        "float", "Bt, viscous damping of tool actuator and clay, N s/m (eq 5).", minimum=0.0,
        check=_zero_or_meaningful,
    ),
    "tool_stiffness_N_per_m": Field("float", "Kt, tool spring stiffness, N/m (eq 5).", minimum=0.0,
                                    check=_zero_or_meaningful),
}

MODEL_SCHEMA: Schema = {
    "sample_period_s": Field(
        "float", "Ts, the control period of both sides, s (10 us to 0.1 s).", minimum=1e-5,
        maximum=0.1,
    ),
    "position_ratio_ah1": Field(
        "matrix2", "Ah1, diagonal position ratio, yt = Ah1 yh, dimensionless.",
        check=_diagonal_nonsingular,
    ),
    "force_ratio_ah2": Field(
        "matrix2", "Ah2, diagonal force ratio, ft = Ah2 fh^e, dimensionless.",
        check=_diagonal_nonsingular,
    ),
    "ch1": {
        "gain_k": Field("float", "k in Ch1 = k num/den, m/N per unit of num/den.", minimum=0.0,
                        exclusive_minimum=True),
        "num": _polynomial("Ch1 numerator in s (before the gain k).", together=("den",)),
        "den": _denominator("Ch1 denominator in s.", together=("num",)),
    },
    "x": AXIS_SCHEMA,
    "y": AXIS_SCHEMA,
}

ANALYSIS_SCHEMA: Schema = {
    "round_trip_delay_s": Field(
        "float", "Round-trip network delay tau analysed by default, s (at most 10 s).",
        minimum=0.0, maximum=10.0,
    ),
    "max_frequency_rad_s": Field(
        "float", "Upper end of the frequency grid, rad/s (1 to 1e7).", minimum=1.0,
        maximum=1e7,
    ),
    "max_delay_s": Field(
        "float", "Largest round-trip delay searched for margins and maps, s.", minimum=0.0,
        exclusive_minimum=True,
    ),
    "max_gain_k": Field(
        "float", "Largest Ch1 gain k searched for k_max, m/N.", minimum=0.0,
        exclusive_minimum=True,
    ),
}

#: [supervision]: no silent inert sessions (common/runtime/inert.py).
SUPERVISION_SCHEMA: Schema = {
    "inert_after_s": Field(
        "float", "A side whose peer is present but whose forces are off this long says so "
        "(status line, summary, session report), s.", minimum=0.0, exclusive_minimum=True,
        maximum=3600.0),
}


SCHEMA: Schema = {
    "model": MODEL_SCHEMA,
    "analysis": ANALYSIS_SCHEMA,
    "slave": SLAVE_SCHEMA,
    "master": MASTER_SCHEMA,
    "link": LINK_SCHEMA,
    "lockstep": LOCKSTEP_SCHEMA,
    "runner": RUNNER_SCHEMA,
    "supervision": SUPERVISION_SCHEMA,
    "governor": GOVERNOR_SCHEMA,
    "control": CONTROL_SCHEMA,
    "ros2": ROS2_SCHEMA,
}


def check_across_keys(config: dict[str, Any]) -> None:
    """The rules that tie keys of different places together, checked whenever a file or a flag
    sets a key (raises :class:`ConfigError` naming one of them); rules that need a program's
    own objects stay with them (``[slave.safety]``'s in ``InputGuardSettings.from_config``)."""
    governor = config.get("governor", {})
    if "urgent_factor" in governor and "safety_factor" in governor and not (
            governor["urgent_factor"] >= governor["safety_factor"]):
        raise ConfigError("governor.urgent_factor",
                          f"must be >= governor.safety_factor ({governor['safety_factor']:g}; "
                          f"got {governor['urgent_factor']:g})")
