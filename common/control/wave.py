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
- the energy guard that keeps it all passive: every message also carries the sender's wave
  energy ``E = sum(sent^2) Ts / 2``; a fresh message credits the reserve (J, per axis) with
  what ``E`` gained since the last credit, so the energy of a wave lost on the way arrives with
  the next message, and a used wave spends ``used^2 Ts / 2`` of it: the wave energy a side uses
  never exceeds the wave energy its peer sent. A credit is at most what the sender could have
  sent in the periods since the last one (``wave_limit^2 Ts / 2`` each), so a peer reporting
  more energy than it sent gains nothing beyond an honest one; the reserve is capped at
  ``reserve_max_J`` (what the cap drops is lost, never spent in a later burst).

A stale or lost message (``fresh`` false) and a non-finite wave leave the last received wave in
place (held), paid from the reserve like any used wave. The filtered wave may spend the whole
reserve; the drift correction only what lies above a floor that grows with the recent share of
stale periods (``reserve_floor_J`` once it reaches ``loss_floor_fraction``, over a memory of
``loss_memory_s``; zero on a clean link): a lossy link keeps a standing reserve for the held
waves of the next gap, whose energy is credited only after it, instead of spending it at once
on the correction. A non-finite integral or energy keeps the last one; a non-finite force counts
as 0 N; forces are clamped to ``force_limit_N`` and received waves to the wave of
``speed_limit_m_per_s`` and that force. Arrays are (lanes, 2): x and y.

A message is :data:`MESSAGE_CHANNELS` columns per lane: the wave, its integral and its
energy, each (x, y) (:func:`message_fields`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

MASTER_SIGN = 1.0
SLAVE_SIGN = -1.0
#: Columns of a wave message: the wave (x, y), its integral (x, y), its energy (x, y).
MESSAGE_CHANNELS = 6


def message_fields(message: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A (lanes, 6) message's (wave sqrt(W), integral sqrt(W) s, energy J) as (lanes, 2) views."""
    return message[:, 0:2], message[:, 2:4], message[:, 4:6]


@dataclass(frozen=True)
class WaveSettings:
    """The wave transformation's impedance, the filter, the drift correction and the bounds
    (SI units in the names)."""

    period_s: float
    impedance_N_s_per_m: float = 20.0
    filter_bandwidth_rad_s: float = 60.0
    drift_gain_per_s: float = 2.0
    reserve_max_J: float = 0.05
    reserve_floor_J: float = 0.01
    loss_floor_fraction: float = 0.05
    loss_memory_s: float = 1.0
    force_limit_N: float = 40.0
    speed_limit_m_per_s: float = 1.0

    def __post_init__(self) -> None:
        for name in ("period_s", "impedance_N_s_per_m", "force_limit_N", "speed_limit_m_per_s"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        for name in ("filter_bandwidth_rad_s", "drift_gain_per_s", "reserve_max_J",
                     "reserve_floor_J"):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")
        for name in ("loss_floor_fraction", "loss_memory_s"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")

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

    @property
    def stale_weight(self) -> float:
        """The stale-share average's weight per period, ``Ts / loss_memory_s`` (at most 1)."""
        return min(1.0, self.period_s / self.loss_memory_s)

    @property
    def credit_per_period_J(self) -> float:
        """The most wave energy a sender can send in one period, J: ``wave_limit^2 Ts / 2``."""
        return self.wave_limit ** 2 * self.period_s / 2.0


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
    reserve (J), the integral of the used wave, the newest received integral, the integral of
    the sent wave (sqrt(W) s), the held (last received) wave (sqrt(W)), the peer's energy
    credited so far and the energy sent (J), the periods since the last credit and the recent
    share of stale periods (0..1)."""

    filtered: np.ndarray
    reserve_J: np.ndarray
    used_integral: np.ndarray
    received_integral: np.ndarray
    sent_integral: np.ndarray
    held_wave: np.ndarray
    credited_energy_J: np.ndarray
    sent_energy_J: np.ndarray
    periods_uncredited: np.ndarray
    stale_share: np.ndarray

    @classmethod
    def create(cls, lanes: int) -> WavePortState:
        """A side at rest: everything zero."""
        return cls(*(np.zeros((lanes, 2)) for _ in range(10)))


def _credit(settings: WaveSettings, state: WavePortState, fresh2: np.ndarray,
            received_energy_J: np.ndarray) -> None:
    """A fresh message's energy counter credits the reserve with what it gained since the last
    credit, at most what the sender could have sent since (in place)."""
    state.periods_uncredited[...] = state.periods_uncredited + 1.0
    counted = fresh2 & np.isfinite(received_energy_J)
    gained = np.where(counted, received_energy_J - state.credited_energy_J, 0.0)
    credit = np.clip(gained, 0.0, state.periods_uncredited * settings.credit_per_period_J)
    state.credited_energy_J[...] = state.credited_energy_J + credit
    state.periods_uncredited[...] = np.where(counted, 0.0, state.periods_uncredited)
    state.reserve_J[...] = np.minimum(state.reserve_J + credit, settings.reserve_max_J)


def _spend(settings: WaveSettings, state: WavePortState,
           desired: np.ndarray) -> np.ndarray:
    """The used wave: the filtered wave within the whole reserve, the correction only within
    what lies above the loss floor; its energy leaves the reserve (in place)."""
    ts = settings.period_s
    floor = settings.reserve_floor_J * np.minimum(
        1.0, state.stale_share / settings.loss_floor_fraction)
    whole = np.sqrt(2.0 * state.reserve_J / ts)
    filtered = np.clip(state.filtered, -whole, whole)
    spare = np.sqrt(filtered * filtered + 2.0 * np.maximum(state.reserve_J - floor, 0.0) / ts)
    bound = np.minimum(spare, whole)
    used = np.clip(desired, -bound, bound)
    state.reserve_J[...] = np.maximum(state.reserve_J - used * used * (ts / 2.0), 0.0)
    return used


def wave_port_step_reference(settings: WaveSettings, state: WavePortState, sign: float,
                             force_N: np.ndarray, received_wave: np.ndarray,
                             received_integral: np.ndarray, received_energy_J: np.ndarray,
                             fresh: np.ndarray
                             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One period of one side (``sign``: :data:`MASTER_SIGN` or :data:`SLAVE_SIGN`), the numpy
    reference of :mod:`haptic.common.control.wave_kernel`: (velocity command m/s, wave to
    send, its integral, its energy J), each (lanes, 2); ``state`` advances in place."""
    b = settings.impedance_N_s_per_m
    ts = settings.period_s
    limit = settings.force_limit_N
    wave_limit = settings.wave_limit
    fresh2 = np.asarray(fresh, bool)[:, None]
    force = np.where(np.isfinite(force_N), force_N, 0.0)
    force = np.clip(force, -limit, limit)
    arrived = fresh2 & np.isfinite(received_wave)
    state.held_wave[...] = np.where(arrived, np.clip(received_wave, -wave_limit, wave_limit),
                                    state.held_wave)
    state.stale_share[...] = state.stale_share + settings.stale_weight * (
        np.where(arrived, 0.0, 1.0) - state.stale_share)
    held = fresh2 & np.isfinite(received_integral)
    state.received_integral[...] = np.where(held, received_integral, state.received_integral)
    _credit(settings, state, fresh2, received_energy_J)
    state.filtered[...] = state.filtered + settings.filter_weight * (
        state.held_wave - state.filtered)
    desired = state.filtered + settings.drift_gain_per_s * (
        state.received_integral - state.used_integral)
    used = _spend(settings, state, desired)
    state.used_integral[...] = state.used_integral + used * ts
    root = math.sqrt(2.0 * b)
    velocity = (root * used + sign * force) / b
    sent = used + sign * (2.0 * force / root)
    state.sent_integral[...] = state.sent_integral + sent * ts
    state.sent_energy_J[...] = state.sent_energy_J + sent * sent * (ts / 2.0)
    return velocity, sent, state.sent_integral.copy(), state.sent_energy_J.copy()


__all__ = ["MASTER_SIGN", "MESSAGE_CHANNELS", "SLAVE_SIGN", "WavePortState", "WaveSettings",
           "message_fields", "port_from_waves", "wave_pair", "wave_port_step_reference"]
