"""The clay's contact law as numbers both sides of the project share (docs/clay.md).

The slave renders the clay through a proxy joined to the tool by a spring-damper
(``COUPLING_STIFFNESS_N_PER_M``, ``COUPLING_DAMPING_N_S_PER_M``); the clay advances the proxy
by its viscous yield law f = B dp/dt. Linearised about steady cutting (the proxy moving with
the tool, the clay pushing back), the environment impedance is the clay's damper in series
with the coupling::

    Tt(s) = B s (K + b s) / (K + (B + b) s)          N/m

which tends to ``B s`` at low frequency (the paper's viscous clay, f = B v) and whose damping
at the loop's oscillation frequency is lower than B. The analysis (``haptic-analyze
--environment clay``) and the latency sweep's clay mode use it; the slave's clay
(``haptic.slave_sim.clay.sim``) uses the same constants.
"""

from __future__ import annotations

import numpy as np

#: Coupling spring between the tool and its proxy in the clay, N/m.
COUPLING_STIFFNESS_N_PER_M = 2000.0
#: Coupling damper in parallel with the spring, N s/m.
COUPLING_DAMPING_N_S_PER_M = 50.0


def clay_impedance(damping_N_s_per_m: float,
                   stiffness_N_per_m: float = COUPLING_STIFFNESS_N_PER_M,
                   coupling_damping_N_s_per_m: float = COUPLING_DAMPING_N_S_PER_M
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Numerator and denominator (polynomials in s, N/m) of the clay's Tt linearised about
    steady cutting in a block of damping ``damping_N_s_per_m``."""
    b, k, c = coupling_damping_N_s_per_m, stiffness_N_per_m, damping_N_s_per_m
    if c == 0.0:  # no clay: no force
        return np.zeros(1), np.ones(1)
    return np.array([c * b, c * k, 0.0]), np.array([c + b, k])


def passivity_margin_N_s_per_m(device_damping_N_s_per_m: float, sample_period_s: float,
                               stiffness_N_per_m: float = COUPLING_STIFFNESS_N_PER_M,
                               coupling_damping_N_s_per_m: float = COUPLING_DAMPING_N_S_PER_M
                               ) -> float:
    """Colgate and Brown's passivity bound for a virtual spring-damper rendered at period Ts
    on a device of physical damping Bt: ``Bt - (K Ts / 2 + b)``, N s/m; > 0 is passive."""
    return float(device_damping_N_s_per_m
                 - (0.5 * stiffness_N_per_m * sample_period_s + coupling_damping_N_s_per_m))


__all__ = ["COUPLING_DAMPING_N_S_PER_M", "COUPLING_STIFFNESS_N_PER_M", "clay_impedance",
           "passivity_margin_N_s_per_m"]
