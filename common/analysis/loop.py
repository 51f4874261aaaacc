"""The closed loop of one axis as a characteristic function of the round-trip delay.

Eliminating the positions from the model (docs/model.md, section 3) leaves::

    Delta(s, tau) = A(s) + B(s) e^(-s tau)
    A = (1 + Ph Ch1)(1 - Pt Ct2),   B = Ph Ct1 Pt Ch2,
    Ph = Th Gh / (1 + Th Sh),       Pt = Tt Gt / (1 - Tt St),

where tau is the round-trip delay (handle force to the slave plus tool force back). The
closed loop is stable iff Delta has no zero in the closed right half-plane. With the
synthesized compensators and tau = 0, Delta equals the paper's eq 29.

The sampled-data variant describes the loop the runtime executes at Ts: Tustin
compensators, zero-order-hold plants, the master's command applied one sample late (a CiA 402
drive in cyclic synchronous position mode applies a target at the next SYNC), and the slave's
environment force computed at the end of its step from the held actuator force.
"""

from __future__ import annotations

from dataclasses import dataclass

import control
import numpy as np

from haptic.common.model.plants import (
    causal_plants,
)
from haptic.common.model.synthesis import AxisCompensators, minimal_tf
from haptic.common.model.teleop import AxisModel, evaluate_tf, tf, tf_coefficients

#: Real part (1/s) of the line s = sigma + j w the argument principle walks along; keeps the
#: integrators of Ch1 and Gt (poles at s = 0) outside the counted region.
CONTOUR_SHIFT_1_PER_S = 1e-5


def feedthrough(system: control.TransferFunction) -> float:
    """The direct feedthrough D = lim G at infinity of a proper transfer function."""
    num, den = tf_coefficients(system)
    num, den = np.trim_zeros(num, "f"), np.trim_zeros(den, "f")
    return float(num[0] / den[0]) if len(num) == len(den) else 0.0


def sample(system: control.TransferFunction, sample_period_s: float,
           method: str) -> control.TransferFunction:
    """``system`` discretised at ``sample_period_s`` (s) by ``method`` ("zoh" or "tustin").
    A zero system (Pt with no environment, Tt = 0) stays zero: discretising it is exact,
    while SciPy's conversion would strip its all-zero numerator and warn that the result
    may be meaningless."""
    num, _ = tf_coefficients(system)
    if not np.any(num):
        return control.tf([0.0], [1.0], sample_period_s)
    return control.sample_system(system, sample_period_s, method=method)


@dataclass(frozen=True)
class LoopTerms:
    """Responses of the loop's parts at the points ``s`` (continuous) or ``z`` (sampled)."""

    a: np.ndarray  # A(lambda), dimensionless
    b: np.ndarray  # B(lambda), dimensionless
    s: np.ndarray  # the continuous frequency points s = sigma + j w, 1/s

    def characteristic(self, round_trip_delay_s: float) -> np.ndarray:
        """Delta = A + B e^(-s tau) at the points."""
        return self.a + self.b * np.exp(-self.s * round_trip_delay_s)


class AxisLoop:
    """Evaluates A and B of one axis, continuous or sampled at ``sample_period_s``."""

    def __init__(
        self,
        axis: AxisModel,
        compensators: AxisCompensators,
        sample_period_s: float | None = None,
        drift: tuple[float, float] | None = None,
    ) -> None:
        """``drift``: the paper mode's drift coupling (kp N/m, wc rad/s) at the slave,
        ``vt += kp wc/(s + wc) (Ah1 yh_recv - yt)`` (common/model/drift.py); None: the paper's
        loop exactly."""
        self.axis = axis
        self.drift = drift
        self.compensators = compensators
        self.sample_period_s = sample_period_s
        ph, pt = causal_plants(axis)
        comps = compensators
        if sample_period_s is None:
            self._parts = {"ph": ph, "pt": pt, "ch1": comps.ch1, "ct1": comps.ct1,
                           "ch2": comps.ch2, "ct2": comps.ct2}
            self._pt_feedthrough = 0.0
        else:
            ts = sample_period_s
            pt_zoh = sample(pt, ts, "zoh")
            self._pt_feedthrough = feedthrough(pt_zoh)
            self._parts = {
                "ph": sample(ph, ts, "zoh"),
                "pt": pt_zoh,
                **{name: sample(system, ts, "tustin")
                   for name, system in (("ch1", comps.ch1), ("ct1", comps.ct1),
                                        ("ch2", comps.ch2), ("ct2", comps.ct2))},
            }
        if drift is not None:
            # The coupling's parts: Cp, the tool seen by its force Gt' = Gt/(1 - Tt St) and
            # the handle seen by its command Gh' = Gh/(1 + Th Sh) (docs/control.md).
            kp, wc = drift
            th = tf(axis.operator_impedance_th_N_per_m, [1.0])
            tt = tf(axis.environment_impedance_tt_N_per_m, axis.environment_impedance_den)
            gt = axis.tool_actuator_gt / (1 - tt * axis.tool_compliance_st)
            gh = axis.handle_actuator_gh / (1 + th * axis.handle_compliance_sh)
            extra = {"cp": tf([kp * wc], [1.0, wc]), "gt_": minimal_tf(gt),
                     "gh_": minimal_tf(gh)}
            if sample_period_s is not None:
                extra = {"cp": sample(extra["cp"], sample_period_s, "tustin"),
                         "gt_": sample(extra["gt_"], sample_period_s, "zoh"),
                         "gh_": sample(extra["gh_"], sample_period_s, "zoh")}
            self._parts.update(extra)

    @property
    def sampled(self) -> bool:
        """True for the sampled-data loop."""
        return self.sample_period_s is not None

    @property
    def max_frequency_rad_s(self) -> float | None:
        """The Nyquist frequency pi/Ts of the sampled loop; None when continuous."""
        return None if self.sample_period_s is None else np.pi / self.sample_period_s

    def terms_at(self, s: np.ndarray) -> LoopTerms:
        """A and B at the continuous points ``s`` (for the sampled loop, at z = e^(s Ts))."""
        s = np.asarray(s, complex)
        if self.sample_period_s is None:
            point = s
        else:
            point = np.exp(s * self.sample_period_s)
        value = {name: evaluate_tf(system, point) for name, system in self._parts.items()}
        ph, pt = value["ph"], value["pt"]
        if self.sample_period_s is not None:
            ph = ph / point  # the master's command is applied one sample late
            pt = pt - self._pt_feedthrough + self._pt_feedthrough / point
        a = (1.0 + ph * value["ch1"]) * (1.0 - pt * value["ct2"])
        b = ph * value["ct1"] * pt * value["ch2"]
        if self.drift is not None:  # the slow coupling of Ah1 yh_recv - yt at the slave
            gh = value["gh_"] if self.sample_period_s is None else value["gh_"] / point
            a = a + (1.0 + ph * value["ch1"]) * value["gt_"] * value["cp"]
            b = b + gh * value["ct1"] * pt * value["cp"] * self.axis.position_ratio_ah1
        return LoopTerms(a=a, b=b, s=s)

    def terms(self, omega_rad_s: np.ndarray, shift_1_per_s: float = 0.0) -> LoopTerms:
        """A and B on the line s = shift + j w."""
        return self.terms_at(shift_1_per_s + 1j * np.asarray(omega_rad_s, float))
