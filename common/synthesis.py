"""Synthesis of the compensators Ct1, Ch2, Ct2 from Ch1 and the model (paper eqs 21-23).

With ``U11 = Gh Ch1 + Sh`` and the ratios ``Ah1`` (positions) and ``Ah2`` (forces)::

    Ct1 = U11 / (Gh Ah2)                     (eq 21)
    Ch2 = -Ah1 U11 / Gt                      (eq 22)
    Ct2 = (-Ah1 Ah2^-1 U11 - St) / Gt        (eq 23)

which make ``yt = Ah1 yh`` (eq 12) and ``ft = Ah2 fh^e`` (eq 20) hold. Common factors are
cancelled exactly where they are common (root matching with a relative tolerance), so the
results are minimal. A design is refused with :class:`SynthesisError` when a compensator is
improper (more zeros than poles: it would need future inputs) or not realisable as a stable
block (a pole in the open right half-plane: Gt or, with Sh != 0, Gh non-minimum phase, or an
unstable Ch1).
"""

from __future__ import annotations

from dataclasses import dataclass

import control
import numpy as np

from haptic.common.model import AxisModel, TeleopModel, polynomial_degree, tf, tf_coefficients

#: Relative distance under which a pole and a zero are taken as the same root and cancelled.
CANCELLATION_TOLERANCE = 1e-6
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


def cancel_common_roots(
    num: np.ndarray, den: np.ndarray, tolerance: float = CANCELLATION_TOLERANCE
) -> tuple[np.ndarray, np.ndarray]:
    """Cancel roots shared by numerator and denominator (relative ``tolerance``).

    Returns (num, den) scaled so that the denominator is monic.
    """
    num, den = _strip(np.asarray(num, float)), _strip(np.asarray(den, float))
    if polynomial_degree(num) < 0:
        return np.array([0.0]), np.array([1.0])
    zeros, poles = list(np.roots(num)), list(np.roots(den))
    kept_zeros = []
    for zero in zeros:
        distances = [abs(zero - pole) for pole in poles]
        if distances:
            best = int(np.argmin(distances))
            if distances[best] <= tolerance * max(1.0, abs(zero)):
                poles.pop(best)
                continue
        kept_zeros.append(zero)
    gain = num[0] / den[0]
    new_num = (gain * np.real_if_close(np.poly(kept_zeros), tol=1e6) if kept_zeros
               else np.array([gain]))
    new_den = np.real_if_close(np.poly(poles), tol=1e6) if poles else np.array([1.0])
    return np.real(np.atleast_1d(new_num)), np.real(np.atleast_1d(new_den))


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
    u11 = minimal_tf(gh * ch1 + axis.handle_compliance_sh)
    compensators = {
        "Ct1": minimal_tf(u11 / (gh * ah2)),
        "Ch2": minimal_tf(-ah1 * u11 / gt),
        "Ct2": minimal_tf((-(ah1 / ah2) * u11 - axis.tool_compliance_st) / gt),
    }
    origin = {
        "Ct1": "Ct1 = (Gh Ch1 + Sh)/(Gh Ah2) divides by Gh",
        "Ch2": "Ch2 = -Ah1 (Gh Ch1 + Sh)/Gt divides by Gt",
        "Ct2": "Ct2 = (-Ah1 Ah2^-1 (Gh Ch1 + Sh) - St)/Gt divides by Gt",
    }
    for name, system in compensators.items():
        num, den = tf_coefficients(system)
        num_degree, den_degree = polynomial_degree(num), polynomial_degree(den)
        if num_degree > den_degree:
            raise SynthesisError(
                f"{label}: {name} is improper (numerator degree {num_degree} > denominator "
                f"degree {den_degree}): {origin[name]}, so Gh Ch1 + Sh must roll off at least "
                f"as fast as Gt; give Ch1 more poles"
            )
        _refuse_unstable(f"{label}: {name}", system, f"{origin[name]}, which has that zero")
    return AxisCompensators(
        axis=axis.name, ch1=minimal_tf(ch1), ct1=compensators["Ct1"], ch2=compensators["Ch2"],
        ct2=compensators["Ct2"],
    )


def synthesize(model: TeleopModel) -> tuple[AxisCompensators, ...]:
    """Compensators for every axis of ``model``, in the model's axis order."""
    return tuple(synthesize_axis(axis, model.ch1) for axis in model.axes)
