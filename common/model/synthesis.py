"""Synthesis of the compensators Ct1, Ch2, Ct2 from Ch1 and the model (paper eqs 21-23).

With ``U11 = Gh Ch1 + Sh`` and the ratios ``Ah1`` (positions) and ``Ah2`` (forces)::

    Ct1 = U11 / (Gh Ah2)                     (eq 21)
    Ch2 = -Ah1 U11 / Gt                      (eq 22)
    Ct2 = (-Ah1 Ah2^-1 U11 - St) / Gt        (eq 23)

which make ``yt = Ah1 yh`` (eq 12) and ``ft = Ah2 fh^e`` (eq 20) hold. The structural
cancellations (Gh in Ct1 when Sh = 0; Ch1's integrator against a tool without spring) are
done exactly, in polynomial arithmetic; nothing is cancelled by numerical root matching.
A design is refused with :class:`SynthesisError` when a compensator is
improper (more zeros than poles: it would need future inputs) or not realisable as a stable
block (a pole in the open right half-plane: Gt or, with Sh != 0, Gh non-minimum phase, or an
unstable Ch1).
"""

from __future__ import annotations

from dataclasses import dataclass

import control
import numpy as np

from haptic.common.model.axes import AxisModel, TeleopModel
from haptic.common.model.transfer import polynomial_degree, tf, tf_coefficients

#: Real part (1/s) above which a pole counts as in the open right half-plane.
RHP_TOLERANCE = 1e-9


class SynthesisError(ValueError):
    """The configured design gives a compensator that is improper or not realisable."""


@dataclass(frozen=True)
class AxisCompensators:
    """The four compensators of one axis, continuous time (transfer functions in s).

    ``ch1``: handle force (N) -> handle command (m); ``ct1``: tool force (N) -> handle
    command (m); ``ch2``: handle force (N) -> tool actuator force (N); ``ct2``: tool force (N)
    -> tool actuator force (N).
    """

    axis: str
    ch1: control.TransferFunction
    ct1: control.TransferFunction
    ch2: control.TransferFunction
    ct2: control.TransferFunction

    def as_dict(self) -> dict[str, control.TransferFunction]:
        """The compensators by name."""
        return {"Ch1": self.ch1, "Ct1": self.ct1, "Ch2": self.ch2, "Ct2": self.ct2}


def _strip(coefficients: np.ndarray) -> np.ndarray:
    nonzero = np.flatnonzero(coefficients != 0.0)
    return np.array([0.0]) if nonzero.size == 0 else coefficients[nonzero[0]:]


def _add(first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """``first + second`` (highest power first) with the coefficients that cancel set to
    exactly zero: a sum below a few ulps of its terms' magnitudes is rounding, judged per
    coefficient (scale-free, unlike a threshold relative to the largest coefficient, which
    drops a legitimate leading 1 next to trailing coefficients of 1e14)."""
    size = max(len(first), len(second))
    a = np.concatenate([np.zeros(size - len(first)), np.asarray(first, float)])
    b = np.concatenate([np.zeros(size - len(second)), np.asarray(second, float)])
    total = a + b
    total[np.abs(total) <= 64.0 * np.finfo(float).eps * (np.abs(a) + np.abs(b))] = 0.0
    return total


def _exact_tf(num: np.ndarray, den: np.ndarray) -> control.TransferFunction:
    """A transfer function of coefficients already free of rounding (no relative cleaning:
    see :func:`_add`)."""
    return control.tf(_strip(np.asarray(num, float)), _strip(np.asarray(den, float)))


def _trailing_zeros(polynomial: np.ndarray) -> int:
    nonzero = np.flatnonzero(polynomial)
    return 0 if nonzero.size == 0 else len(polynomial) - 1 - int(nonzero[-1])


def cancel_common_roots(num: np.ndarray, den: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cancel the roots at s = 0 that numerator and denominator share (exact trailing zeros,
    such as Ch1's integrator against a tool without spring); returns (num, den) with a monic
    denominator.

    Other cancellations are structural and done symbolically by the synthesis; a pole-zero
    pair that merely coincides numerically is left in place: it costs a stable state (an
    unstable one is refused), never accuracy, which root matching with a tolerance would.
    """
    num, den = _strip(np.asarray(num, float)), _strip(np.asarray(den, float))
    if polynomial_degree(num) < 0:
        return np.array([0.0]), np.array([1.0])
    common = min(_trailing_zeros(num), _trailing_zeros(den))
    if common:
        num, den = num[:-common], den[:-common]
    return num / den[0], den / den[0]


def minimal_tf(system: control.TransferFunction) -> control.TransferFunction:
    """``system`` with its common pole-zero factors cancelled."""
    num, den = tf_coefficients(system)
    return tf(*cancel_common_roots(num, den))


def _rhp_poles(system: control.TransferFunction) -> np.ndarray:
    _, den = tf_coefficients(system)
    if polynomial_degree(den) < 1:
        return np.array([])
    poles = np.roots(_strip(den))
    return poles[poles.real > RHP_TOLERANCE]


def _refuse_unstable(label: str, system: control.TransferFunction, why: str) -> None:
    poles = _rhp_poles(system)
    if poles.size:
        listed = ", ".join(f"{p:.4g}" for p in poles)
        raise SynthesisError(f"{label} is not realisable: unstable pole(s) at {listed} ({why})")


def synthesize_axis(axis: AxisModel, ch1: control.TransferFunction) -> AxisCompensators:
    """Compensators of one axis for the master compensator ``ch1`` (eqs 21-23)."""
    gh = axis.handle_actuator_gh
    gt = axis.tool_actuator_gt
    ah1, ah2 = axis.position_ratio_ah1, axis.force_ratio_ah2
    label = f"axis {axis.name}"
    for name, system in (("Ch1", ch1), ("Gh", gh), ("Sh", axis.handle_compliance_sh),
                         ("St", axis.tool_compliance_st), ("Gt", gt)):
        _refuse_unstable(f"{label}: {name}", system,
                         "the analysis assumes stable or marginal parts")
    # Polynomial arithmetic that keeps the structural cancellations exact: Gh's denominator
    # never enters Ct1, and a zero compliance drops its factors.
    gh_num, gh_den = tf_coefficients(gh)
    ch1_num, ch1_den = tf_coefficients(ch1)
    sh_num, sh_den = tf_coefficients(axis.handle_compliance_sh)
    st_num, st_den = tf_coefficients(axis.tool_compliance_st)
    _, gt_inverse = tf_coefficients(gt)  # Gt = 1/(Mt s^2 + Bt s + Kt)
    mul = np.polymul
    ratio = ah1 / ah2
    if polynomial_degree(sh_num) < 0:  # Sh = 0: U11 = Gh Ch1, Ct1 = Ch1 / Ah2
        u11_num, u11_den = mul(gh_num, ch1_num), mul(gh_den, ch1_den)
        ct1 = (ch1_num, ah2 * ch1_den)
    else:  # U11 = Gh Ch1 + Sh = u11_num / (gh_den ch1_den sh_den)
        u11_num = _add(mul(mul(gh_num, ch1_num), sh_den), mul(mul(sh_num, gh_den), ch1_den))
        u11_den = mul(mul(gh_den, ch1_den), sh_den)
        ct1 = (u11_num, ah2 * mul(mul(ch1_den, sh_den), gh_num))
    if polynomial_degree(st_num) < 0:  # St = 0: Ct2 = -Ah1 Ah2^-1 U11 / Gt
        ct2 = (-ratio * mul(u11_num, gt_inverse), u11_den)
    else:
        ct2_num = _add(-ratio * mul(u11_num, st_den), -1.0 * mul(st_num, u11_den))
        ct2 = (mul(ct2_num, gt_inverse), mul(u11_den, st_den))
    compensators = {
        "Ct1": _exact_tf(*cancel_common_roots(*ct1)),
        "Ch2": _exact_tf(*cancel_common_roots(-ah1 * mul(u11_num, gt_inverse), u11_den)),
        "Ct2": _exact_tf(*cancel_common_roots(*ct2)),
    }
    origin = {
        "Ct1": "Ct1 = (Gh Ch1 + Sh)/(Gh Ah2) divides by Gh",
        "Ch2": "Ch2 = -Ah1 (Gh Ch1 + Sh)/Gt divides by Gt",
        "Ct2": "Ct2 = (-Ah1 Ah2^-1 (Gh Ch1 + Sh) - St)/Gt divides by Gt",
    }
    remedy = {
        "Ct1": "Sh must roll off at least as fast as Gh",
        "Ch2": "Gh Ch1 + Sh must roll off at least as fast as Gt; give Ch1 more poles",
        "Ct2": "Gh Ch1 + Sh and St must roll off at least as fast as Gt; give Ch1 more poles",
    }
    for name, system in compensators.items():
        num, den = tf_coefficients(system)
        num_degree, den_degree = polynomial_degree(num), polynomial_degree(den)
        if num_degree > den_degree:
            raise SynthesisError(
                f"{label}: {name} is improper (numerator degree {num_degree} > denominator "
                f"degree {den_degree}): {origin[name]}, so {remedy[name]}"
            )
        _refuse_unstable(f"{label}: {name}", system, f"{origin[name]}, which has that zero")
    return AxisCompensators(
        axis=axis.name, ch1=minimal_tf(ch1), ct1=compensators["Ct1"], ch2=compensators["Ch2"],
        ct2=compensators["Ct2"],
    )


def synthesize(model: TeleopModel) -> tuple[AxisCompensators, ...]:
    """Compensators for every axis of ``model``, in the model's axis order."""
    return tuple(synthesize_axis(axis, model.ch1) for axis in model.axes)
