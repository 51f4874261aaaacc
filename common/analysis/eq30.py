"""The paper's sufficient (small-gain) stability condition, eq 30, on a frequency grid::

    |Gh Ch1 (j w)| < |Sh + (Ah1 Ah2^-1 Tt + Th)^-1 (j w)|   for all w >= 0.

It comes from eq 29 at zero delay; it says nothing about delay.
"""

from __future__ import annotations

from dataclasses import dataclass

import control
import numpy as np

from haptic.common.model.teleop import AxisModel, evaluate_tf


@dataclass(frozen=True)
class Eq30Result:
    """Eq 30 for one axis: the worst ratio lhs/rhs (dimensionless) and where (rad/s)."""

    satisfied: bool
    worst_ratio: float
    worst_frequency_rad_s: float
    unbounded_at_low_frequency: bool  # Gh Ch1 integrates: no gain can satisfy eq 30


def eq30_ratio(
    axis: AxisModel, ch1: control.TransferFunction, omega_rad_s: np.ndarray
) -> np.ndarray:
    """|Gh Ch1| / |Sh + (Ah1 Ah2^-1 Tt + Th)^-1| at each frequency."""
    s = 1j * np.asarray(omega_rad_s, float)
    ratio = axis.position_ratio_ah1 / axis.force_ratio_ah2
    tt = (np.polyval(axis.environment_impedance_tt_N_per_m, s)
          / np.polyval(axis.environment_impedance_den, s))
    impedance = ratio * tt + np.polyval(axis.operator_impedance_th_N_per_m, s)
    lhs = np.abs(evaluate_tf(axis.handle_actuator_gh, s) * evaluate_tf(ch1, s))
    rhs = np.abs(evaluate_tf(axis.handle_compliance_sh, s) + 1.0 / impedance)
    return lhs / rhs


def check_eq30(
    axis: AxisModel, ch1: control.TransferFunction, omega_rad_s: np.ndarray
) -> Eq30Result:
    """Evaluate eq 30 on ``omega_rad_s``."""
    ratio = eq30_ratio(axis, ch1, omega_rad_s)
    worst = int(np.argmax(ratio))
    integrating = bool(np.any(np.abs(control.poles(axis.handle_actuator_gh * ch1)) < 1e-9))
    compliant = bool(np.any(axis.handle_compliance_sh.num[0][0] != 0))
    return Eq30Result(
        satisfied=bool(ratio[worst] < 1.0),
        worst_ratio=float(ratio[worst]),
        worst_frequency_rad_s=float(omega_rad_s[worst]),
        unbounded_at_low_frequency=integrating and not compliant,
    )
