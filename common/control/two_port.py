"""The four-channel teleoperator as a two-port (hybrid form) and Llewellyn's absolute
stability criterion (Llewellyn 1952; Hashtrudi-Zaad and Salcudean 2001, section 3).

The hybrid matrix maps the handle's velocity and the environment's force to the operator's
force and the tool's velocity::

    [fh; -ve] = H(s) [vh; fe]

from the two equations of :mod:`haptic.common.control.four_channel`, with every channel that
crosses the network delayed one way (``C1, C3`` master to slave, ``C2, C4`` slave to master,
each times ``exp(-s T)``). The operator feels ``Zt = (h11 + (h11 h22 - h12 h21) Ze) /
(1 + h22 Ze)`` against an environment ``Ze``: transparency is ``h11 = h22 = 0``,
``h12 h21 = -1``.

Llewellyn: a two-port is absolutely stable (stable against every passive operator and
environment) iff ``h11`` and ``h22`` have no poles in the right half plane and, at every
frequency, ``Re h11 >= 0``, ``Re h22 >= 0`` and
``eta = 2 Re h11 Re h22 - Re(h12 h21) - |h12 h21| >= 0``. :func:`llewellyn` checks the three
inequalities over a frequency grid; :func:`absolute_stability` adds the pole condition where
``H`` is rational (no delay): the poles of ``h11`` and ``h22`` are among the zeros of
``s D(s)``, ``D = (1 + C6) Zcs - C3 C4``, and of ``s Zcs(s)``, both quadratics. With delay the
denominators are quasi-polynomials and the poles are not checked (``rhp_poles`` None).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from haptic.common.control.four_channel import FourChannelGains, Impedance


def hybrid_matrix(gains: FourChannelGains, frequencies_rad_s: np.ndarray,
                  one_way_delay_s: float = 0.0) -> np.ndarray:
    """H(j w) (n, 2, 2) complex at the frequencies ``frequencies_rad_s`` (n,), > 0."""
    s = 1j * np.asarray(frequencies_rad_s, dtype=float)
    delay = np.exp(-s * one_way_delay_s)
    zcm = (gains.master + gains.master_local).at(s)
    zcs = (gains.slave + gains.slave_local).at(s)
    c1 = gains.c1.at(s) * delay
    c3 = gains.c3 * delay
    c2 = gains.c2 * delay
    c4 = gains.c4.at(s) * delay
    # unknowns (fh, ve) from  (1 + C6) fh - C4 ve = Zcm vh + C2 fe
    #                          C3 fh - Zcs ve = -C1 vh + (1 + C5) fe
    lhs = np.empty((s.size, 2, 2), complex)
    lhs[:, 0, 0] = 1.0 + gains.c6
    lhs[:, 0, 1] = -c4
    lhs[:, 1, 0] = c3
    lhs[:, 1, 1] = -zcs
    rhs = np.empty((s.size, 2, 2), complex)
    rhs[:, 0, 0] = zcm
    rhs[:, 0, 1] = c2
    rhs[:, 1, 0] = -c1
    rhs[:, 1, 1] = 1.0 + gains.c5
    solved = np.linalg.solve(lhs, rhs)  # [fh; ve] = solved [vh; fe]
    solved[:, 1, :] = -solved[:, 1, :]
    return solved


def transmitted_impedance(h: np.ndarray, environment: np.ndarray) -> np.ndarray:
    """What the operator feels, ``fh / vh`` (N s/m), against ``environment`` ``Ze`` (n,)."""
    h11, h12, h21, h22 = h[:, 0, 0], h[:, 0, 1], h[:, 1, 0], h[:, 1, 1]
    return (h11 + (h11 * h22 - h12 * h21) * environment) / (1.0 + h22 * environment)


@dataclass(frozen=True)
class LlewellynVerdict:
    """The criterion over the grid: ``absolutely_stable``, and the worst values found (the
    least ``Re h11``, ``Re h22`` and ``eta``, and the frequency of the least ``eta``,
    rad/s); ``rhp_poles``: whether ``h11`` or ``h22`` has a right-half-plane pole (None: not
    checked)."""

    absolutely_stable: bool
    min_re_h11: float
    min_re_h22: float
    min_eta: float
    worst_frequency_rad_s: float
    rhp_poles: bool | None = None


def llewellyn(h: np.ndarray, frequencies_rad_s: np.ndarray, tolerance: float = 1e-9
              ) -> LlewellynVerdict:
    """Llewellyn's three inequalities on ``h`` (n, 2, 2) at ``frequencies_rad_s`` (n,), each
    allowed to miss by ``tolerance`` relative to the size of the terms (a lossless two-port,
    the transparent one, sits exactly on the boundary)."""
    re11 = h[:, 0, 0].real
    re22 = h[:, 1, 1].real
    product = h[:, 0, 1] * h[:, 1, 0]
    eta = 2.0 * re11 * re22 - product.real - np.abs(product)
    scale = np.maximum(np.abs(product) + np.abs(2.0 * re11 * re22), 1.0)
    worst = int(np.argmin(eta / scale))
    stable = bool(np.all(re11 >= -tolerance * np.maximum(np.abs(h[:, 0, 0]), 1.0))
                  and np.all(re22 >= -tolerance * np.maximum(np.abs(h[:, 1, 1]), 1.0))
                  and np.all(eta >= -tolerance * scale))
    return LlewellynVerdict(stable, float(re11.min()), float(re22.min()), float(eta.min()),
                            float(np.asarray(frequencies_rad_s)[worst]))


def _times_s(impedance: Impedance) -> np.ndarray:
    """``s Z(s)`` as polynomial coefficients, highest power first."""
    return np.array([impedance.mass_kg, impedance.damping_N_s_per_m,
                     impedance.stiffness_N_per_m])


def has_rhp_poles(gains: FourChannelGains, tolerance: float = 1e-9) -> bool:
    """Whether ``h11`` or ``h22`` of the undelayed two-port may have a pole with a real part
    above ``tolerance`` (rad/s): a zero of ``s D(s)`` or ``s Zcs(s)`` there."""
    zcs = _times_s(gains.slave + gains.slave_local)
    denominator = (1.0 + gains.c6) * zcs - gains.c3 * _times_s(gains.c4)
    for polynomial in (denominator, zcs):
        trimmed = np.trim_zeros(polynomial, "f")
        if trimmed.size > 1 and np.any(np.roots(trimmed).real > tolerance):
            return True
    return False


def absolute_stability(gains: FourChannelGains, frequencies_rad_s: np.ndarray,
                       one_way_delay_s: float = 0.0) -> LlewellynVerdict:
    """Llewellyn's verdict on the four-channel two-port at ``one_way_delay_s``: the
    inequalities over ``frequencies_rad_s`` and, without delay, the pole condition."""
    verdict = llewellyn(hybrid_matrix(gains, frequencies_rad_s, one_way_delay_s),
                        frequencies_rad_s)
    if one_way_delay_s != 0.0:
        return verdict
    poles = has_rhp_poles(gains)
    return replace(verdict, absolutely_stable=verdict.absolutely_stable and not poles,
                   rhp_poles=poles)


__all__ = ["LlewellynVerdict", "absolute_stability", "has_rhp_poles", "hybrid_matrix",
           "llewellyn", "transmitted_impedance"]
