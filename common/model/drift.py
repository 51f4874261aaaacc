"""Position-drift coupling for the paper's scheme (``[control] mode = "paper"``).

The paper's scheme has no position feedback between the sides (docs/model.md section 6):
every difference between what the two sides integrate stays as an offset. This coupling adds,
at the slave, a slow spring on the received position gap, through a first-order low-pass::

    vt += Cp (Ah1 yh_recv - yt),   Cp(s) = kp wc / (s + wc)

(``kp`` N/m, ``wc`` rad/s; Tustin at Ts like the compensators). It is outside the paper's
design, so the stability analysis includes it (common/analysis/loop.py: the A and B terms gain
``(1 + Ph Ch1) Gt' Cp`` and ``Gh' Ct1 Pt Cp Ah1``, docs/control.md), and it is off by default
(``paper_drift_stiffness_N_per_m = 0``), when the slave runs no code of it at all.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class DriftCoupling:
    """The coupling's gain ``stiffness_N_per_m`` (kp) and ``bandwidth_rad_s`` (wc) at the
    period ``period_s``."""

    stiffness_N_per_m: float
    bandwidth_rad_s: float
    period_s: float

    def initial_state(self, lanes: int) -> np.ndarray:
        """The filter's state (lanes, 4): the last output (x, y) and the last input (x, y)."""
        return np.zeros((lanes, 4))

    def coefficients(self) -> tuple[float, float]:
        """The Tustin low-pass's (a, b): y = a y' + b (x + x') (also the slave's kernel's)."""
        wt = self.bandwidth_rad_s * self.period_s
        return (2.0 - wt) / (2.0 + wt), wt / (2.0 + wt)

    def force(self, state: np.ndarray, gap_m: np.ndarray) -> np.ndarray:
        """The spring force (lanes, 2), N, for the gap ``Ah1 yh_recv - yt`` (lanes, 2), m;
        advances ``state`` in place (Tustin: y = a y' + b (x + x'))."""
        a, b = self.coefficients()
        gap = np.nan_to_num(gap_m)
        filtered = a * state[:, 0:2] + b * (gap + state[:, 2:4])
        state[:, 0:2] = filtered
        state[:, 2:4] = gap
        return self.stiffness_N_per_m * filtered
