"""The paper's two-port model of handle, operator, virtual tool and environment, per axis.

Sign convention (docs/model.md derives it): positions and forces are positive along +x/+y;
``fh`` is the force the operator applies to the handle's force sensor, ``ft`` the force the
tool applies to its environment (the clay), so the environment pushes back with ``-ft``::

    fh = uh - Th yh            yh = Gh vh + Sh fh
    ft = Tt yt - ut            yt = Gt vt + St ft
    vh = Ch1 fh - Ct1 ft       vt = -Ch2 fh + Ct2 ft

All transfer functions are in s with SI units: Gh m/m, Sh and St m/N, Gt m/N, Ch1 m/N;
Th and Tt are impedance polynomials in N/m.
"""

from __future__ import annotations

from typing import Any

import numpy as np

# The model's types and transfer-function helpers live in axes.py and transfer.py, which the
# synthesis and the plants import without this module; they are re-exported here, where
# the programs have always taken them from.
from haptic.common.model.axes import AXES, AxisModel, TeleopModel
from haptic.common.model.errors import ConfigError
from haptic.common.model.plants import causal_plants
from haptic.common.model.synthesis import SynthesisError, synthesize_axis
from haptic.common.model.transfer import (
    NEGLIGIBLE_COEFFICIENT,
    clean_polynomial,
    evaluate_tf,
    polynomial_degree,
    relative_degree,
    tf,
    tf_coefficients,
)

__all__ = ["AXES", "NEGLIGIBLE_COEFFICIENT", "AxisModel", "TeleopModel", "clean_polynomial",
           "evaluate_tf", "model_from_config", "polynomial_degree", "relative_degree", "tf",
           "tf_coefficients"]


def _check_proper(key: str, num: list[float], den: list[float]) -> None:
    num_degree = polynomial_degree(np.asarray(num))
    den_degree = polynomial_degree(np.asarray(den))
    if num_degree > den_degree:
        raise ConfigError(
            key,
            f"improper transfer function (numerator degree {num_degree} > denominator "
            f"degree {den_degree}); it cannot be realised",
        )


def model_from_config(config: dict[str, Any]) -> TeleopModel:
    """Build the :class:`TeleopModel` from a validated configuration (``config["model"]``).

    Raises :class:`ConfigError` naming the key for an improper Ch1, Gh, Sh or St, or a tool
    with no mass, damping nor stiffness.
    """
    section = config["model"]
    ch1 = section["ch1"]
    _check_proper("model.ch1.num", ch1["num"], ch1["den"])
    if not any(ch1["num"]):
        raise ConfigError("model.ch1.num", "must not be zero (Ch1 = 0 never moves the handle)")
    axes = []
    for index, name in enumerate(AXES):
        raw = section[name]
        prefix = f"model.{name}"
        _check_proper(f"{prefix}.handle_actuator_gh_num", raw["handle_actuator_gh_num"],
                      raw["handle_actuator_gh_den"])
        _check_proper(f"{prefix}.handle_compliance_sh_num", raw["handle_compliance_sh_num"],
                      raw["handle_compliance_sh_den"])
        _check_proper(f"{prefix}.tool_compliance_st_num", raw["tool_compliance_st_num"],
                      raw["tool_compliance_st_den"])
        if polynomial_degree(np.asarray(raw["handle_actuator_gh_num"])) < 0:
            raise ConfigError(f"{prefix}.handle_actuator_gh_num", "must not be zero")
        if raw["tool_mass_kg"] == 0 and raw["tool_damping_N_s_per_m"] == 0 and (
            raw["tool_stiffness_N_per_m"] == 0
        ):
            raise ConfigError(f"{prefix}.tool_mass_kg", "Gt = 1/(Mt s^2 + Bt s + Kt) is undefined "
                              "with Mt, Bt and Kt all zero")
        axes.append(
            AxisModel(
                name=name,
                handle_actuator_gh=tf(raw["handle_actuator_gh_num"], raw["handle_actuator_gh_den"]),
                handle_compliance_sh=tf(raw["handle_compliance_sh_num"],
                                        raw["handle_compliance_sh_den"]),
                tool_compliance_st=tf(raw["tool_compliance_st_num"], raw["tool_compliance_st_den"]),
                operator_impedance_th_N_per_m=np.asarray(raw["operator_impedance_th"], float),
                environment_impedance_tt_N_per_m=np.asarray(raw["environment_impedance_tt"], float),
                tool_mass_kg=raw["tool_mass_kg"],
                tool_damping_N_s_per_m=raw["tool_damping_N_s_per_m"],
                tool_stiffness_N_per_m=raw["tool_stiffness_N_per_m"],
                position_ratio_ah1=section["position_ratio_ah1"][index][index],
                force_ratio_ah2=section["force_ratio_ah2"][index][index],
            )
        )
    model = TeleopModel(
        sample_period_s=section["sample_period_s"],
        ch1_gain_k=ch1["gain_k"],
        ch1_num=np.asarray(ch1["num"], float),
        ch1_den=np.asarray(ch1["den"], float),
        axes=tuple(axes),
    )
    _check_realisable(model)
    return model


def _check_realisable(model: TeleopModel) -> None:
    """What every program's start computes from the model, checked here so that a model that
    cannot run is a :class:`ConfigError` naming its axis table: each axis's compensators
    synthesise (eqs 21-23) and its plants Ph and Pt are proper (a zero tool mass with an St
    that does not roll off, extreme coefficients)."""
    for axis in model.axes:
        key = f"model.{axis.name}"
        try:
            synthesize_axis(axis, model.ch1)
            for name, system in zip(("Ph", "Pt"), causal_plants(axis), strict=True):
                if not all(np.all(np.isfinite(c)) for c in tf_coefficients(system)):
                    raise SynthesisError(f"axis {axis.name}: {name} has coefficients beyond "
                                         "the float range")
        except (SynthesisError, ValueError, ArithmeticError, np.linalg.LinAlgError) as error:
            if "Pt" in str(error) and axis.tool_mass_kg == 0.0:
                key += ".tool_mass_kg"  # a massless tool: Gt of first order
            raise ConfigError(key, str(error)) from None
