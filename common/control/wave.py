"""Wave variables (Niemeyer and Slotine, IJRR 2004): each side turns its port's force and
velocity into waves, the network carries only waves, and a channel with any constant delay
stores energy but never creates it.

With wave impedance ``b`` (N s/m), at a port of force ``F`` (N) and velocity ``v`` (m/s)::

    u = (b v + F) / sqrt(2 b)      the wave travelling into the channel at the master,
    w = (b v - F) / sqrt(2 b)      the wave travelling out of it,     F v = (u^2 - w^2) / 2

(waves in sqrt(W)). Both of this project's ports are in admittance causality (force in,
motion out: the master commands the handle from the operator's force, the slave commands the
tool's velocity against the environment's force), so each side solves for its velocity from the
force it measures and the wave it received, ``r``::

    master (sign +1, F = operator force on the handle):   v = (sqrt(2 b) r + F) / b,
                                                           sent = r + sqrt(2 / b) F
    slave  (sign -1, F = force the tool applies to its environment):
                                                           v = (sqrt(2 b) r - F) / b,
                                                           sent = r - sqrt(2 / b) F

On the received wave, before it is used, each side applies

- the wave filter: a first-order low-pass ``y += a (r - y)``, ``a = Ts wc / (1 + Ts wc)``
  (backward Euler at ``wc`` rad/s; off at ``wc = 0``), which damps wave reflections. Since
  ``y_k^2 <= (1 - a) y_{k-1}^2 + a r_k^2`` it never outputs more wave energy than came in,
  over any prefix;
- the drift correction of Niemeyer and Slotine 2004: every message also carries the sender's
  wave integral ``U = sum(sent) Ts``; the receiver adds ``gain (U_recv - U_used)`` so the
  integral of what it uses follows what was sent. A lost or filtered wave changes the
  relation between the positions; with the integrals matched, ``x_m - x_s = ((U_m - U_s) +
  (W_m - W_s)) / sqrt(2 b)`` closes at rest;
- the energy guard that keeps it all passive: a reserve (J, per axis) gains
  ``(r^2 - used^2) Ts / 2`` each step and the used wave is clamped to
  ``|used| <= sqrt(r^2 + 2 reserve / Ts)``, so the wave energy used never exceeds the wave
  energy received. The reserve is capped at ``reserve_max_J`` (what the cap drops is lost,
  never spent in a later burst).

A stale or lost message (``fresh`` false) and a non-finite wave count as a zero wave (the
passive choice: a held wave would be spent twice); a non-finite integral keeps the last one;
a non-finite force counts as 0 N; forces are clamped to ``force_limit_N`` and received waves
to the wave of ``speed_limit_m_per_s`` and that force. Arrays are (lanes, 2): x and y.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

MASTER_SIGN = 1.0
SLAVE_SIGN = -1.0


@dataclass(frozen=True)
class WaveSettings:
    """The wave transformation's impedance, the filter, the drift correction and the bounds
    (SI units in the names)."""

    period_s: float
    impedance_N_s_per_m: float = 20.0
    filter_bandwidth_rad_s: float = 60.0
    drift_gain_per_s: float = 2.0
    reserve_max_J: float = 0.05
    force_limit_N: float = 40.0
    speed_limit_m_per_s: float = 1.0

    def __post_init__(self) -> None:
        for name in ("period_s", "impedance_N_s_per_m", "force_limit_N", "speed_limit_m_per_s"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        for name in ("filter_bandwidth_rad_s", "drift_gain_per_s", "reserve_max_J"):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")

    @property
    def filter_weight(self) -> float:
        """The low-pass's ``a`` (1: the filter is off)."""
        if self.filter_bandwidth_rad_s == 0.0:
            return 1.0
        wt = self.period_s * self.filter_bandwidth_rad_s
        return wt / (1.0 + wt)

    @property
    def wave_limit(self) -> float:
        """The largest wave a side accepts, sqrt(W): that of the speed and force limits."""
        b = self.impedance_N_s_per_m
        return (b * self.speed_limit_m_per_s + self.force_limit_N) / math.sqrt(2.0 * b)


def wave_pair(force_N: np.ndarray, velocity_m_per_s: np.ndarray, impedance_N_s_per_m: float
              ) -> tuple[np.ndarray, np.ndarray]:
    """The (in, out) waves of a port: ``u = (b v + F)/sqrt(2b)``, ``w = (b v - F)/sqrt(2b)``;
    ``F v = (u^2 - w^2)/2``."""
    b = impedance_N_s_per_m
    scale = math.sqrt(2.0 * b)
    return (b * velocity_m_per_s + force_N) / scale, (b * velocity_m_per_s - force_N) / scale


def port_from_waves(u: np.ndarray, w: np.ndarray, impedance_N_s_per_m: float
                    ) -> tuple[np.ndarray, np.ndarray]:
    """The inverse of :func:`wave_pair`: (force N, velocity m/s)."""
    b = impedance_N_s_per_m
    scale = math.sqrt(2.0 * b)
    return (u - w) * scale / 2.0, (u + w) * scale / (2.0 * b)


@dataclass(eq=False)
class WavePortState:
    """One side's wave state over lanes, each (lanes, 2): the filter's output, the energy
    reserve (J), the integral of the used wave, the newest received integral and the integral
    of the sent wave (sqrt(W) s)."""

    filtered: np.ndarray
    reserve_J: np.ndarray
    used_integral: np.ndarray
    received_integral: np.ndarray
    sent_integral: np.ndarray

    @classmethod
    def create(cls, lanes: int) -> WavePortState:
        """A side at rest: everything zero."""
        return cls(*(np.zeros((lanes, 2)) for _ in range(5)))


def wave_port_step_reference(settings: WaveSettings, state: WavePortState, sign: float,
                             force_N: np.ndarray, received_wave: np.ndarray,
                             received_integral: np.ndarray, fresh: np.ndarray
                             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One period of one side (``sign``: :data:`MASTER_SIGN` or :data:`SLAVE_SIGN`), the numpy
    reference of :mod:`haptic.common.control.wave_kernel`: (velocity command m/s, wave to
    send, its integral), each (lanes, 2); ``state`` advances in place."""
    b = settings.impedance_N_s_per_m
    ts = settings.period_s
    limit = settings.force_limit_N
    wave_limit = settings.wave_limit
    fresh2 = np.asarray(fresh, bool)[:, None]
    force = np.where(np.isfinite(force_N), force_N, 0.0)
    force = np.clip(force, -limit, limit)
    ok = fresh2 & np.isfinite(received_wave)
    r = np.clip(np.where(ok, received_wave, 0.0), -wave_limit, wave_limit)
    held = fresh2 & np.isfinite(received_integral)
    state.received_integral[...] = np.where(held, received_integral, state.received_integral)
    state.filtered[...] = state.filtered + settings.filter_weight * (r - state.filtered)
    desired = state.filtered + settings.drift_gain_per_s * (
        state.received_integral - state.used_integral)
    bound = np.sqrt(r * r + 2.0 * state.reserve_J / ts)
    used = np.clip(desired, -bound, bound)
    reserve = np.maximum(state.reserve_J + (r * r - used * used) * (ts / 2.0), 0.0)
    state.reserve_J[...] = np.minimum(reserve, settings.reserve_max_J)
    state.used_integral[...] = state.used_integral + used * ts
    root = math.sqrt(2.0 * b)
    velocity = (root * used + sign * force) / b
    sent = used + sign * (2.0 * force / root)
    state.sent_integral[...] = state.sent_integral + sent * ts
    return velocity, sent, state.sent_integral.copy()


__all__ = ["MASTER_SIGN", "SLAVE_SIGN", "WavePortState", "WaveSettings", "port_from_waves",
           "wave_pair", "wave_port_step_reference"]
