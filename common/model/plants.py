"""The two plants of the paper's loop, from an axis's model: the handle with the operator's
arm (Ph) and the tool with the environment (Pt), as transfer functions (SI units)."""

from __future__ import annotations

import control
import numpy as np

from haptic.common.model.axes import AxisModel
from haptic.common.model.synthesis import minimal_tf
from haptic.common.model.transfer import tf, tf_coefficients


def _polynomial_tf(coefficients: np.ndarray) -> control.TransferFunction:
    return tf(coefficients, [1.0])


def handle_with_operator(axis: AxisModel) -> control.TransferFunction:
    """Ph = Th Gh / (1 + Th Sh): handle command (m) -> force the operator's arm takes (N)."""
    th = _polynomial_tf(axis.operator_impedance_th_N_per_m)
    return minimal_tf(th * axis.handle_actuator_gh / (1 + th * axis.handle_compliance_sh))


def tool_with_environment(axis: AxisModel) -> control.TransferFunction:
    """Pt = Tt Gt / (1 - Tt St): tool actuator force (N) -> force on the environment (N); Tt
    may be rational (``environment_impedance_den``)."""
    tt = tf(axis.environment_impedance_tt_N_per_m, axis.environment_impedance_den)
    return minimal_tf(tt * axis.tool_actuator_gt / (1 - tt * axis.tool_compliance_st))


def causal_plants(axis: AxisModel) -> tuple[control.TransferFunction, control.TransferFunction]:
    """(Ph, Pt) of ``axis``; ``ValueError`` naming the axis and the plant when one is improper
    (the loop would not be causal)."""
    ph, pt = handle_with_operator(axis), tool_with_environment(axis)
    for name, system in (("Ph = Th Gh/(1 + Th Sh)", ph), ("Pt = Tt Gt/(1 - Tt St)", pt)):
        num, den = tf_coefficients(system)
        if len(np.trim_zeros(num, "f")) > len(np.trim_zeros(den, "f")):
            raise ValueError(f"axis {axis.name}: {name} is improper; the loop is not causal")
    return ph, pt
