"""Lawrence's four-channel teleoperation scheme (Lawrence 1993; Hashtrudi-Zaad and Salcudean
2001) as a discrete law per side, the numpy reference of
:mod:`haptic.common.control.four_channel_kernel`.

Each side renders a virtual manipulator (the master's ``Zm``, the slave's ``Zs``: mass and
damping, N s/m) under its local controller (``Cm``, ``Cs``: damping and stiffness on its own
motion) and the four channels::

    Zm vh = fh + tau_m,   tau_m = -Cm vh - C4 ve + C6 fh - C2 fe      (master)
    Zs ve = tau_s - fe,   tau_s = -Cs ve + C1 vh + C3 fh - C5 fe      (slave)

with ``C1``, ``C4`` impedances (``M s + B + K / s``: the peer's acceleration, velocity and
position) and ``C2, C3, C5, C6`` dimensionless force gains; ``fh`` is the operator's force on
the handle, ``fe`` the force the tool applies to its environment (both N). The scheme is
transparent (the operator feels exactly the environment, ``Zt = Ze``) at zero delay when::

    C1 = Zs + Cs,   C4 = -(Zm + Cm),   C2 = 1 + C6,   C3 = 1 + C5

(Lawrence's choice ``C5 = C6 = 0`` gives ``C2 = C3 = 1``, ``C2 C3 = 1``; ``C5 = -1`` drops
the ``C3`` channel with local force feedback on the slave). The hybrid matrix and Llewellyn's
absolute stability test are in :mod:`haptic.common.control.two_port`.

Both of this project's ports command motion (admittance causality), so each side integrates
its virtual manipulator (implicit Euler in its own damping and stiffness, which keeps that part
passive at any period) and outputs the position and velocity its servo follows. A side's
general step, with ``f_own`` the force it measures and ``f_peer`` the one it receives::

    M a = (s + g_own) f_own + P(peer motion) + g_peer f_peer - B v - K x
    master: s = +1, g_own = C6, P = -C4, g_peer = -C2;  slave: s = -1, g_own = -C5, P = C1,
    g_peer = C3;  B = Z.damping + C.damping, K = C.stiffness

with the peer's acceleration the difference of its received velocity over the period (0 when
no fresh message came). A stale message or one with any non-finite field leaves the last
received peer values in place; a non-finite own force counts as 0 N; forces are clamped to
``force_limit_N``, velocities to ``speed_limit_m_per_s``, positions to ``position_limit_m``.
Arrays are (lanes, 2): x and y.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np


@dataclass(frozen=True)
class Impedance:
    """``Z(s) = mass_kg s + damping_N_s_per_m + stiffness_N_per_m / s`` (force over
    velocity)."""

    mass_kg: float = 0.0
    damping_N_s_per_m: float = 0.0
    stiffness_N_per_m: float = 0.0

    def at(self, s: np.ndarray) -> np.ndarray:
        """Its value at the complex frequencies ``s`` (rad/s, non-zero)."""
        return self.mass_kg * s + self.damping_N_s_per_m + self.stiffness_N_per_m / s

    def __add__(self, other: Impedance) -> Impedance:
        return Impedance(self.mass_kg + other.mass_kg,
                         self.damping_N_s_per_m + other.damping_N_s_per_m,
                         self.stiffness_N_per_m + other.stiffness_N_per_m)

    def __neg__(self) -> Impedance:
        return Impedance(-self.mass_kg, -self.damping_N_s_per_m, -self.stiffness_N_per_m)


@dataclass(frozen=True)
class FourChannelGains:
    """The manipulators ``master`` (Zm) and ``slave`` (Zs), the local controllers
    ``master_local`` (Cm) and ``slave_local`` (Cs), and the channels C1..C6."""

    master: Impedance
    slave: Impedance
    master_local: Impedance
    slave_local: Impedance
    c1: Impedance
    c2: float
    c3: float
    c4: Impedance
    c5: float = 0.0
    c6: float = 0.0

    @classmethod
    def transparent(cls, master: Impedance, slave: Impedance, master_local: Impedance,
                    slave_local: Impedance, c5: float = 0.0, c6: float = 0.0,
                    channel_masses: bool = True) -> FourChannelGains:
        """The transparency-optimal channels for these manipulators and local controllers:
        ``C1 = Zs + Cs``, ``C4 = -(Zm + Cm)``, ``C2 = 1 + C6``, ``C3 = 1 + C5``.

        ``channel_masses=False`` leaves the manipulators' masses out of ``C1`` and ``C4``:
        a sampled loop feeds the peer's acceleration forward one exchange late, which makes
        the common motion of the two sides grow without bound; without it the scheme stays
        stable and transparent up to the masses' ``M w^2`` (docs/architectures.md)."""
        c1, c4 = slave + slave_local, -(master + master_local)
        if not channel_masses:
            c1 = Impedance(0.0, c1.damping_N_s_per_m, c1.stiffness_N_per_m)
            c4 = Impedance(0.0, c4.damping_N_s_per_m, c4.stiffness_N_per_m)
        return cls(master, slave, master_local, slave_local, c1=c1, c2=1.0 + c6, c3=1.0 + c5,
                   c4=c4, c5=c5, c6=c6)

    @classmethod
    def position_position(cls, master: Impedance, slave: Impedance, master_local: Impedance,
                          slave_local: Impedance) -> FourChannelGains:
        """The two-channel position-error scheme in four-channel form: ``C1 = Cs``,
        ``C4 = -Cm``, no force channel (a spring and damper between the two manipulators
        when ``Cm = Cs``)."""
        return cls(master, slave, master_local, slave_local, c1=slave_local, c2=0.0, c3=0.0,
                   c4=-master_local)


@dataclass(frozen=True)
class SideLaw:
    """One side's step in the general form of the module's docstring (SI units)."""

    period_s: float
    mass_kg: float
    damping_N_s_per_m: float
    stiffness_N_per_m: float
    own_force_gain: float
    peer: Impedance
    peer_force_gain: float
    force_limit_N: float = 40.0
    speed_limit_m_per_s: float = 1.0
    position_limit_m: float = 1.0

    def __post_init__(self) -> None:
        if not (self.period_s > 0.0 and self.mass_kg > 0.0):
            raise ValueError("period_s and the manipulator's mass_kg must be > 0")
        if self.damping_N_s_per_m < 0.0 or self.stiffness_N_per_m < 0.0:
            raise ValueError("the local damping and stiffness must be >= 0")

    @property
    def implicit_mass_kg(self) -> float:
        """``M + Ts B + Ts^2 K``: the implicit Euler step's divisor, kg."""
        ts = self.period_s
        return self.mass_kg + ts * self.damping_N_s_per_m + ts * ts * self.stiffness_N_per_m


def side_laws(gains: FourChannelGains, period_s: float, force_limit_N: float = 40.0,
              speed_limit_m_per_s: float = 1.0, position_limit_m: float = 1.0
              ) -> tuple[SideLaw, SideLaw]:
    """(master's law, slave's law) of the four-channel gains at ``period_s``."""
    limits = (force_limit_N, speed_limit_m_per_s, position_limit_m)
    master = SideLaw(period_s, gains.master.mass_kg,
                     gains.master.damping_N_s_per_m + gains.master_local.damping_N_s_per_m,
                     gains.master.stiffness_N_per_m + gains.master_local.stiffness_N_per_m,
                     1.0 + gains.c6, -gains.c4, -gains.c2, *limits)
    slave = SideLaw(period_s, gains.slave.mass_kg,
                    gains.slave.damping_N_s_per_m + gains.slave_local.damping_N_s_per_m,
                    gains.slave.stiffness_N_per_m + gains.slave_local.stiffness_N_per_m,
                    -(1.0 + gains.c5), gains.c1, gains.c3, *limits)
    return master, slave


@dataclass(eq=False)
class SideState:
    """One side over lanes, each (lanes, 2): its virtual manipulator's position (m) and
    velocity (m/s), and the last received peer position, velocity and force."""

    position_m: np.ndarray
    velocity_m_per_s: np.ndarray
    peer_position_m: np.ndarray
    peer_velocity_m_per_s: np.ndarray
    peer_force_N: np.ndarray
    names: ClassVar[tuple[str, ...]] = ("position_m", "velocity_m_per_s", "peer_position_m",
                                        "peer_velocity_m_per_s", "peer_force_N")

    @classmethod
    def create(cls, start_m: np.ndarray) -> SideState:
        """At rest at ``start_m`` (lanes, 2), the peer at rest there too."""
        start = np.array(start_m, dtype=float)
        zeros = np.zeros_like(start)
        return cls(start.copy(), zeros.copy(), start.copy(), zeros.copy(), zeros.copy())


def side_step_reference(law: SideLaw, state: SideState, own_force_N: np.ndarray,
                        peer_position_m: np.ndarray, peer_velocity_m_per_s: np.ndarray,
                        peer_force_N: np.ndarray, fresh: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray]:
    """One period of one side over lanes: (position command m, velocity m/s), each
    (lanes, 2); ``state`` advances in place."""
    ts = law.period_s
    flim, vlim, xlim = law.force_limit_N, law.speed_limit_m_per_s, law.position_limit_m
    own = np.clip(np.where(np.isfinite(own_force_N), own_force_N, 0.0), -flim, flim)
    finite = (np.isfinite(peer_position_m) & np.isfinite(peer_velocity_m_per_s)
              & np.isfinite(peer_force_N)).all(axis=1)
    take = (np.asarray(fresh, bool) & finite)[:, None]
    new_velocity = np.clip(np.where(take, peer_velocity_m_per_s, 0.0), -vlim, vlim)
    accel = np.where(take, (new_velocity - state.peer_velocity_m_per_s) / ts, 0.0)
    state.peer_velocity_m_per_s[...] = np.where(take, new_velocity,
                                                state.peer_velocity_m_per_s)
    state.peer_position_m[...] = np.where(
        take, np.clip(np.where(take, peer_position_m, 0.0), -xlim, xlim), state.peer_position_m)
    state.peer_force_N[...] = np.where(
        take, np.clip(np.where(take, peer_force_N, 0.0), -flim, flim), state.peer_force_N)
    peer = law.peer
    drive = (law.own_force_gain * own + peer.mass_kg * accel
             + peer.damping_N_s_per_m * state.peer_velocity_m_per_s
             + peer.stiffness_N_per_m * state.peer_position_m
             + law.peer_force_gain * state.peer_force_N)
    x = state.position_m
    v = state.velocity_m_per_s
    velocity = (law.mass_kg * v + ts * (drive - law.stiffness_N_per_m * x)) / law.implicit_mass_kg
    velocity = np.clip(velocity, -vlim, vlim)
    state.velocity_m_per_s[...] = velocity
    state.position_m[...] = np.clip(x + ts * velocity, -xlim, xlim)
    return state.position_m.copy(), velocity.copy()


__all__ = ["FourChannelGains", "Impedance", "SideLaw", "SideState", "side_laws",
           "side_step_reference"]
