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

from dataclasses import dataclass, field, replace
from typing import Any

import control
import numpy as np

from haptic.common.model.errors import ConfigError

AXES = ("x", "y")


#: Coefficients smaller than this fraction of a polynomial's largest are rounding noise.
NEGLIGIBLE_COEFFICIENT = 1e-14


def clean_polynomial(coefficients: list[float] | np.ndarray) -> np.ndarray:
    """Coefficients (highest power first) with negligible ones set to zero and leading
    zeros dropped; the zero polynomial is [0.0]."""
    values = np.atleast_1d(np.asarray(coefficients, float)).copy()
    scale = float(np.max(np.abs(values))) if values.size else 0.0
    values[np.abs(values) < NEGLIGIBLE_COEFFICIENT * scale] = 0.0
    nonzero = np.flatnonzero(values)
    return np.array([0.0]) if nonzero.size == 0 else values[nonzero[0]:]


def tf(num: list[float] | np.ndarray, den: list[float] | np.ndarray) -> control.TransferFunction:
    """A SISO continuous-time transfer function from coefficient lists (highest power first)."""
    return control.tf(clean_polynomial(num), clean_polynomial(den))


def polynomial_degree(coefficients: np.ndarray) -> int:
    """Degree of a polynomial given highest power first; -1 for the zero polynomial."""
    nonzero = np.flatnonzero(np.asarray(coefficients) != 0.0)
    return -1 if nonzero.size == 0 else len(coefficients) - 1 - int(nonzero[0])


def tf_coefficients(system: control.TransferFunction) -> tuple[np.ndarray, np.ndarray]:
    """Numerator and denominator of a SISO transfer function, highest power first."""
    return (
        np.atleast_1d(np.asarray(system.num[0][0], float)),
        np.atleast_1d(np.asarray(system.den[0][0], float)),
    )


def relative_degree(system: control.TransferFunction) -> int | None:
    """deg(den) - deg(num); ``None`` for the zero transfer function."""
    num, den = tf_coefficients(system)
    num_degree = polynomial_degree(num)
    return None if num_degree < 0 else polynomial_degree(den) - num_degree


def evaluate_tf(system: control.TransferFunction, points: np.ndarray) -> np.ndarray:
    """Evaluate a SISO transfer function at complex points (s or z)."""
    num, den = tf_coefficients(system)
    return np.polyval(num, points) / np.polyval(den, points)


@dataclass(frozen=True)
class AxisModel:
    """One axis of the handle-operator-tool-environment model (units in the field names)."""

    name: str
    handle_actuator_gh: control.TransferFunction  # position command (m) -> position (m)
    handle_compliance_sh: control.TransferFunction  # m/N
    tool_compliance_st: control.TransferFunction  # m/N
    operator_impedance_th_N_per_m: np.ndarray  # polynomial in s
    environment_impedance_tt_N_per_m: np.ndarray  # polynomial in s
    tool_mass_kg: float
    tool_damping_N_s_per_m: float
    tool_stiffness_N_per_m: float
    position_ratio_ah1: float  # yt = Ah1 yh, dimensionless
    force_ratio_ah2: float  # ft = Ah2 fh^e, dimensionless
    #: Denominator of a rational Tt (polynomial in s; [1]: Tt is the polynomial above), e.g.
    #: the clay's contact linearised about steady cutting (common/model/clay_contact.py).
    environment_impedance_den: np.ndarray = field(default_factory=lambda: np.ones(1))

    @property
    def tool_actuator_gt(self) -> control.TransferFunction:
        """Gt = 1/(Mt s^2 + Bt s + Kt), actuator force (N) -> tool position (m) (eq 5)."""
        return tf([1.0], [self.tool_mass_kg, self.tool_damping_N_s_per_m,
                          self.tool_stiffness_N_per_m])

    def with_environment(self, impedance_N_per_m: np.ndarray,
                         denominator: np.ndarray | None = None) -> AxisModel:
        """A copy with another environment impedance Tt (e.g. the clay as B s): the
        polynomial ``impedance_N_per_m`` over ``denominator`` (default 1)."""
        return replace(self, environment_impedance_tt_N_per_m=np.asarray(impedance_N_per_m, float),
                       environment_impedance_den=np.ones(1) if denominator is None
                       else np.asarray(denominator, float))


@dataclass(frozen=True)
class TeleopModel:
    """The whole model: the sampling period, the master compensator Ch1 and both axes."""

    sample_period_s: float
    ch1_gain_k: float
    ch1_num: np.ndarray
    ch1_den: np.ndarray
    axes: tuple[AxisModel, ...]

    @property
    def ch1(self) -> control.TransferFunction:
        """Ch1 = k num/den: handle force (N) -> handle position command (m), m/N."""
        return tf(self.ch1_gain_k * self.ch1_num, self.ch1_den)

    def with_gain(self, gain_k: float) -> TeleopModel:
        """A copy with another Ch1 gain k."""
        if not gain_k > 0.0 or not np.isfinite(gain_k):
            raise ConfigError("model.ch1.gain_k", f"must be a finite number > 0 (got {gain_k})")
        return replace(self, ch1_gain_k=float(gain_k))

    def axis(self, name: str) -> AxisModel:
        """The axis called ``name`` ("x" or "y")."""
        for axis in self.axes:
            if axis.name == name:
                return axis
        raise KeyError(name)


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
    from haptic.common.model.plants import causal_plants
    from haptic.common.model.synthesis import SynthesisError, synthesize_axis

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
