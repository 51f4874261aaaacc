"""The Time Domain Passivity Approach (TDPA) for the two-port teleoperator, vectorised over lanes.

The teleoperator (master compensator, network, slave compensator and virtual tool) is a
two-port between the operator's handle and the tool's environment (docs/control.md). Each side
observes the energy flowing through its own port (Hannaford and Ryu 2002; Ryu, Artigas and
Preusche 2010; Artigas, Ryu, Preusche and Hirzinger 2011, the "time delay power network"):

- master port: work into the network ``W_m = fh . dcmd`` per step (the operator's measured
  force times the step of the handle's position command; the handle's position servo and
  the operator's arm terminate the port);
- slave port: work into the network ``W_s = -ft . dyt`` per step (the force the tool applies
  to its environment times the tool's displacement; the virtual tool, whose damping the
  compensators cancel, is inside the network, the clay terminates it).

Each side keeps an energy account (the observer, ``tank_J``): its port's work in, minus its
work out, plus the energy the peer handed over; its own input, as far as it holds more than
``keep_J``, it hands to the peer, and every message carries the cumulative handed-over energy
``sent_J``. That sum only grows, so a lost or late message merely delays the peer's view: the
newest value received is the largest (:meth:`PassivityPort.receive`). With ``keep_J = 0`` this
is Artigas' TDPN (the slave may give out what the master took in, and back); a small ``keep_J``
lets each side return the energy its own local dynamics stored a moment ago (the energy packets
of Franken, Stramigioli et al. 2011) without any energy being counted twice: energy in flight
belongs to neither side, so the sum of the two ports' output never exceeds the sum of their
input.

Both ports are in admittance causality (force in, motion out: the master commands the
handle's position from fh, the virtual tool moves and the clay answers with ft), so the
passivity controller is a series conductance that changes the motion by what the observer
lacks: whenever this step's work out would exceed the account, the motion is corrected along
the port's force by ``d = excess f / |f|^2`` (``f . d`` = the excess, dissipated exactly):

- master: the handle command yields along fh (the operator's push meets less resistance);
- slave: the tool's step shrinks along ft (it pushes less far into the clay).

Pitfalls and what this module does about them (each pinned by a test in
tests/common/model/test_passivity.py):

- division by ``|f|^2`` near zero (the velocity floor of an impedance-type damper): below
  ``force_floor_N`` the controller does not act and the deficit waits for the next step;
  the conductance is capped (``conductance_max_m_per_N_s``), and on the slave the correction
  never reverses the step (it at most stops the motion along ft);
- energy credit spent later in a burst: the account is capped at ``credit_max_J``; what it
  would hold beyond is forgotten (``forgotten_energy_J``), so a long passive stretch cannot
  pay for a long active one later;
- bursts out of the controller: the correction's speed is capped at
  ``correction_speed_max_m_per_s`` and may grow by at most
  ``correction_accel_max_m_per_s2`` per second; a deficit the caps leave is carried to the
  next steps (the observer still holds it), so the bound on the energy is kept over a few
  steps instead of in one kick.

Everything is numpy over lanes (arrays (lanes,) and (lanes, 2)); a port holds its state and
settings, and the node calls it with a few lines.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

#: The control modes a run may select with ``[control] mode``.
MODES = ("paper", "tdpa")


@dataclass(frozen=True)
class PassivitySettings:
    """The passivity layer's limits (SI units in the names)."""

    force_floor_N: float = 0.002
    conductance_max_m_per_N_s: float = 0.05
    correction_speed_max_m_per_s: float = 0.2
    correction_accel_max_m_per_s2: float = 200.0
    credit_max_J: float = 0.5
    master_keep_J: float = 0.002
    slave_keep_J: float = 0.002
    velocity_floor_m_per_s: float = 1e-5
    damper_max_N_s_per_m: float = 2000.0
    damper_force_max_N: float = 40.0
    damper_force_rate_N_per_s: float = 4000.0
    drift_stiffness_N_per_m: float = 200.0
    drift_force_max_N: float = 2.0
    master_drift_rate_per_s: float = 2.0
    master_drift_speed_max_m_per_s: float = 0.01
    slave_drift_rate_per_s: float = 2.0
    slave_drift_speed_max_m_per_s: float = 0.01


@dataclass(eq=False)
class PassivityPort:
    """One side's passivity observer and controller over ``lanes`` lanes.

    The observer is an energy account (``tank_J``, lanes): the work that flowed into the
    network at this port, plus the energy the peer handed over, minus the work that flowed
    out and what was handed to the peer. ``sent_J`` (lanes,), monotone, is the cumulative
    energy handed to the peer: every message carries it. ``peer_sent_J`` is the newest
    (largest) value received. ``forgotten_energy_J`` the credit dropped by the cap,
    ``dissipated_energy_J`` what the controller dissipated, ``correction_m`` (lanes,) the
    size of the controller's last correction, ``active_steps`` how often it acted;
    ``input_energy_J``/``output_energy_J`` the port's positive and negative work (the
    observer's two sums, for reports).

    ``active`` (lanes,) bool: the lanes whose layer runs. In ``tdpa`` mode every lane always
    does; in ``paper`` mode with the margin governor's ``tdpa`` action the port is built
    switched off (a standby) and :meth:`switch` turns it on and off at run time. A switched-off
    lane observes nothing, corrects nothing and hands nothing over; it still takes the peer's
    cumulative energy (``peer_sent_J``), so the counters on both sides stay monotone over the
    whole run and energy is never counted twice. Switching on starts the account empty.
    """

    settings: PassivitySettings
    period_s: float
    keep_J: float
    tank_J: np.ndarray
    sent_J: np.ndarray
    peer_sent_J: np.ndarray
    input_energy_J: np.ndarray
    output_energy_J: np.ndarray
    forgotten_energy_J: np.ndarray
    dissipated_energy_J: np.ndarray
    correction_m: np.ndarray
    damper_force_N: np.ndarray
    active_steps: np.ndarray
    previous_position_m: np.ndarray
    active: np.ndarray

    @classmethod
    def create(cls, settings: PassivitySettings, period_s: float, lanes: int,
               keep_J: float = 0.0, zeros: Any = np.zeros, active: bool = True
               ) -> PassivityPort:
        """A port with nothing observed yet; ``keep_J``: the energy of its own input the port
        keeps to return itself (0: everything goes to the peer, Artigas' TDPN). ``zeros``
        ``(shape, dtype) -> array`` makes the arrays (the master: views of Warp buffers); the
        port only ever changes them in place. ``active``: the layer runs from the start
        (``tdpa`` mode), else it waits switched off for :meth:`switch`."""
        floats = [zeros((lanes,), np.float64) for _ in range(9)]
        port = cls(settings, float(period_s), float(keep_J), *floats,
                   zeros((lanes,), np.int64), zeros((lanes, 2), np.float64),
                   zeros((lanes,), np.bool_))
        port.active[...] = active
        return port

    def switch(self, lanes: np.ndarray, on: bool) -> np.ndarray:
        """Switch the layer on (``on``) or off in ``lanes`` ((lanes,) bool mask); returns the
        lanes whose state changed. Switching on starts their account empty (safe: nothing may
        be given out that was not taken in since) with no correction or damper force under
        way; the monotone counters (``sent_J``, ``peer_sent_J``) carry on."""
        mask = np.asarray(lanes, bool)
        changed = mask & (self.active != on)
        if on:
            self.tank_J[changed] = 0.0
            self.correction_m[changed] = 0.0
            self.damper_force_N[changed] = 0.0
        self.active[changed] = on
        return changed

    def receive(self, peer_sent_J: np.ndarray) -> None:
        """Take the peer's cumulative handed-over energy from a message (lanes,), J. A lane
        without a message (non-finite) and an older (smaller) value change nothing, so loss
        and reordering only delay energy, never create it. A switched-off lane notes the value
        without crediting it."""
        value = np.asarray(peer_sent_J, float)
        newest = np.fmax(self.peer_sent_J, np.where(np.isfinite(value), value, -np.inf))
        self.tank_J += np.where(self.active, newest - self.peer_sent_J, 0.0)
        self.peer_sent_J[...] = newest
        self._cap_credit()

    def continue_from(self, previous: PassivityPort | None) -> None:
        """Carry the monotone counters over from the port this one replaces (a node state
        made afresh after a resync): the peer keeps seeing ``sent_J`` grow, and what the peer
        sent is not counted twice; a lane switched on stays on. The account itself starts
        empty (which is safe)."""
        if previous is not None:
            self.sent_J[...] = previous.sent_J
            self.peer_sent_J[...] = previous.peer_sent_J
            self.active[...] = previous.active

    def peer_restarted(self) -> None:
        """The peer's counter started again (a new run, a new epoch): count from zero."""
        self.peer_sent_J[...] = 0.0

    def reserve_J(self) -> np.ndarray:
        """The observer: energy the port may still give out, J (lanes,); negative when the
        network has been active at this port beyond what the controller could dissipate."""
        return self.tank_J

    def _cap_credit(self) -> None:
        """Forget the reserve beyond ``credit_max_J`` (the credit-burst pitfall)."""
        excess = np.maximum(self.tank_J - self.settings.credit_max_J, 0.0)
        self.forgotten_energy_J += excess
        self.tank_J -= excess

    def observe(self, work_in_J: np.ndarray) -> None:
        """Account one step's work into the network at this port (lanes,), J; hand the step's
        input, as far as the port holds more than ``keep_J``, to the peer (``sent_J``)."""
        work = np.where(self.active, np.nan_to_num(np.asarray(work_in_J, float)), 0.0)
        self.input_energy_J += np.maximum(work, 0.0)
        self.output_energy_J += np.maximum(-work, 0.0)
        self.tank_J += work
        # Only this step's own input is handed over (energy received stays until spent or
        # capped, so it does not bounce between the sides), and only beyond keep_J.
        give = np.clip(self.tank_J - self.keep_J, 0.0, np.maximum(work, 0.0))
        self.sent_J += give
        self.tank_J -= give
        self._cap_credit()

    def _correction(self, force_N: np.ndarray, work_out_J: np.ndarray) -> np.ndarray:
        """The conductance's correction (lanes, 2), m, along ``force_N``: ``f . d`` equals
        what this step's work out ``work_out_J`` lacks in the account, within the floor,
        the caps and the rise limit."""
        s, ts = self.settings, self.period_s
        force2 = np.einsum("ij,ij->i", force_N, force_N)
        excess = np.maximum(work_out_J - self.reserve_J(), 0.0)
        usable = force2 >= s.force_floor_N ** 2
        size = np.where(usable, excess / np.sqrt(np.maximum(force2, 1e-300)), 0.0)
        size = np.minimum(size, s.conductance_max_m_per_N_s * np.sqrt(force2) * ts)
        rise = s.correction_accel_max_m_per_s2 * ts * ts
        size = np.minimum(size, np.minimum(s.correction_speed_max_m_per_s * ts,
                                           self.correction_m + rise))
        size = np.where(self.active, size, 0.0)  # a switched-off lane corrects nothing
        self.correction_m[...] = size
        self.active_steps += size > 0.0
        self.dissipated_energy_J += size * np.sqrt(force2)
        return size[:, None] * force_N / np.sqrt(np.maximum(force2, 1e-300))[:, None]

    def yield_command(self, force_N: np.ndarray, handle_step_m: np.ndarray) -> np.ndarray:
        """Master side: the correction (lanes, 2), m, to add to this step's handle command
        for the operator's force (lanes, 2), N, and the command's step (lanes, 2), m, whose
        work is ``fh . dcmd``. It moves along fh: the handle yields to the push by what the
        account lacks."""
        work_out = -np.einsum("ij,ij->i", force_N, handle_step_m)
        return self._correction(force_N, work_out)

    def drift_command(self, force_N: np.ndarray, command_m: np.ndarray,
                      target_m: np.ndarray) -> np.ndarray:
        """Master side, drift compensation: the step (lanes, 2), m, that moves this step's
        handle command ``command_m`` (after the yield) towards ``target_m``, the tool's
        received position in handle coordinates (Ah1^-1 yt_recv; NaN: none): the gap times
        ``master_drift_rate_per_s`` Ts, at most ``master_drift_speed_max_m_per_s`` Ts long.
        Its work at the port ``fh . d`` is the operator's input where positive (free); where
        negative it is paid from what the account holds after this step's other work
        ``fh . (command - previous)``, else scaled down. With no operator force it costs
        nothing: the port's work is ``fh . dcmd``."""
        s = self.settings
        step = self._drift_step(np.asarray(target_m, float) - command_m,
                                s.master_drift_rate_per_s, s.master_drift_speed_max_m_per_s)
        work = np.einsum("ij,ij->i", force_N, step)
        other = np.einsum("ij,ij->i", force_N, command_m - self.previous_position_m)
        return self._paid(step, work, np.maximum(self.reserve_J() + other, 0.0))

    def drift_shift(self, gap_m: np.ndarray, port_force_N: np.ndarray) -> np.ndarray:
        """Slave side, drift compensation: the step (lanes, 2), m, that moves the tool
        towards ``Ah1 yh`` (``gap_m`` = Ah1 yh - yt; NaN: none), the gap times
        ``slave_drift_rate_per_s`` Ts, at most ``slave_drift_speed_max_m_per_s`` Ts long, as
        the master's command moves towards the tool. Its work at the port, the
        environment's ``-ft . d``, is the environment's own release where positive (free:
        it moves the tool where the environment pushes it, and the observer counts it in);
        where negative it is paid from the account, else scaled down. In free space (no
        environment force) it costs nothing."""
        s = self.settings
        step = self._drift_step(np.asarray(gap_m, float), s.slave_drift_rate_per_s,
                                s.slave_drift_speed_max_m_per_s)
        work = -np.einsum("ij,ij->i", np.nan_to_num(port_force_N), step)
        return self._paid(step, work, np.maximum(self.reserve_J(), 0.0))

    def _drift_step(self, gap_m: np.ndarray, rate_per_s: float,
                    speed_max_m_per_s: float) -> np.ndarray:
        """Either side's drift step (lanes, 2), m: ``gap_m`` (lanes, 2; NaN: no step) times
        ``rate_per_s`` Ts, at most ``speed_max_m_per_s`` Ts long."""
        ts = self.period_s
        known = np.all(np.isfinite(gap_m), axis=1) & (rate_per_s > 0.0)
        step = np.where(known[:, None], np.nan_to_num(gap_m) * (rate_per_s * ts), 0.0)
        length = np.sqrt(np.einsum("ij,ij->i", step, step))
        most = speed_max_m_per_s * ts
        step *= np.minimum(1.0, most / np.maximum(length, 1e-300))[:, None]
        return step

    def _paid(self, step: np.ndarray, work_J: np.ndarray, budget_J: np.ndarray) -> np.ndarray:
        """``step`` (lanes, 2) as far as it is paid: whole where the work it gives out at the
        port, ``-work_J``, is within ``budget_J`` (>= 0, so an input, ``work_J`` >= 0, always
        is), else scaled to the budget; none on lanes switched off."""
        paid = -work_J <= budget_J
        step *= np.where(paid & self.active, 1.0,
                         np.where(self.active, budget_J / np.maximum(-work_J, 1e-300),
                                  0.0))[:, None]
        return step

    def damp(self, force_N: np.ndarray, velocity_m_per_s: np.ndarray,
             port_force_N: np.ndarray) -> np.ndarray:
        """Slave side: the actuator force (lanes, 2), N, after the adaptive damper on the
        virtual tool, for the desired actuator force ``force_N``, the tool's velocity
        (lanes, 2), m/s, and the force it applies to its environment (lanes, 2), N, which
        estimates this step's work ``ft . v Ts``. The damper ``alpha v`` dissipates
        ``alpha |v|^2 Ts``, what the account lacks; below the velocity floor it does not act
        and ``alpha`` is capped, so is its force (magnitude and rise)."""
        s, ts = self.settings, self.period_s
        speed2 = np.einsum("ij,ij->i", velocity_m_per_s, velocity_m_per_s)
        work_out = np.einsum("ij,ij->i", port_force_N, velocity_m_per_s) * ts
        excess = np.maximum(work_out - self.reserve_J(), 0.0)
        moving = speed2 >= s.velocity_floor_m_per_s ** 2
        alpha = np.where(moving, excess / (ts * np.maximum(speed2, 1e-300)), 0.0)
        alpha = np.where(self.active, np.minimum(alpha, s.damper_max_N_s_per_m), 0.0)
        speed = np.sqrt(speed2)
        rise = s.damper_force_rate_N_per_s * ts
        magnitude = np.minimum(alpha * speed, np.minimum(s.damper_force_max_N,
                                                         self.damper_force_N + rise))
        self.damper_force_N[...] = magnitude
        alpha = np.where(moving, magnitude / np.maximum(speed, 1e-300), 0.0)
        self.active_steps += alpha > 0.0
        self.dissipated_energy_J += alpha * speed2 * ts
        return force_N - alpha[:, None] * velocity_m_per_s

    def drift_force(self, gap_m: np.ndarray, velocity_m_per_s: np.ndarray,
                    port_force_N: np.ndarray) -> np.ndarray:
        """Slave side, drift compensation: a spring force (lanes, 2), N, pulling the tool
        towards ``Ah1 yh`` (``gap_m`` = Ah1 yh - yt), at most ``drift_force_max_N``, applied
        only where it does not add energy: its work this step ``F . v Ts`` must be paid from
        what the account holds beyond this step's own work ``ft . v Ts``, else it is scaled
        down (to zero when the account is empty and the spring would drive the tool)."""
        s, ts = self.settings, self.period_s
        force = s.drift_stiffness_N_per_m * np.nan_to_num(gap_m)
        norm = np.linalg.norm(force, axis=1)
        force *= np.minimum(1.0, s.drift_force_max_N / np.maximum(norm, 1e-300))[:, None]
        work = np.einsum("ij,ij->i", force, velocity_m_per_s) * ts
        own = np.maximum(np.einsum("ij,ij->i", port_force_N, velocity_m_per_s) * ts, 0.0)
        budget = np.maximum(self.reserve_J() - own, 0.0)
        scale = np.where(work <= budget, 1.0, budget / np.maximum(work, 1e-300))
        return force * np.where(self.active, scale, 0.0)[:, None]


def passivity_summary(port: PassivityPort | None, standby: bool, lane: int = 0
                      ) -> dict[str, Any]:
    """A program's summary keys of its passivity layer (one lane): ``tdpa_layer`` ("off": the
    paper's scheme without it; "tdpa": on all run; "standby": built for the governor's
    run-time switch), ``tdpa_active`` (on at the end), and its energies, J: what it handed
    to the peer and received, what flowed in and out at the port, what the controller
    dissipated and the credit cap forgot, what the account holds at the end (negative: a
    deficit the controller's caps left), and the steps it acted."""
    if port is None:
        return {"tdpa_layer": "standby" if standby else "off", "tdpa_active": False}
    return {"tdpa_layer": "standby" if standby else "tdpa",
            "tdpa_active": bool(port.active[lane]),
            "tdpa_sent_J": float(port.sent_J[lane]),
            "tdpa_received_J": float(port.peer_sent_J[lane]),
            "tdpa_input_energy_J": float(port.input_energy_J[lane]),
            "tdpa_output_energy_J": float(port.output_energy_J[lane]),
            "tdpa_dissipated_energy_J": float(port.dissipated_energy_J[lane]),
            "tdpa_forgotten_energy_J": float(port.forgotten_energy_J[lane]),
            "tdpa_reserve_J": float(port.tank_J[lane]),
            "tdpa_active_steps": int(port.active_steps[lane])}


def master_step_reference(port: PassivityPort, inputs: np.ndarray, command_m: np.ndarray,
                          last_command_m: np.ndarray, origin_m: np.ndarray,
                          faulted: np.ndarray, force_limit_N: float,
                          workspace_min_m: np.ndarray, workspace_max_m: np.ndarray,
                          peer_target_m: np.ndarray | None = None,
                          enabled: np.ndarray | None = None) -> None:
    """The master's passivity step in numpy, in place, after the node's kernel wrote
    ``command_m`` (lanes, 2): the command yields along fh by what the account lacks for this
    step's work ``fh . dcmd``, then drifts towards ``peer_target_m`` (Ah1^-1 yt_recv, (lanes,
    2), m; NaN or None: no target) on ``enabled`` lanes (:meth:`PassivityPort.drift_command`),
    the offset is re-based like the kernel's own limits, then the work is observed. The
    reference of haptic.common.control.passivity_kernel (same arithmetic)."""
    raw = inputs[:, 0:2]
    force = np.clip(np.where(np.isfinite(raw), raw, 0.0), -force_limit_N, force_limit_N)
    correction = port.yield_command(force, command_m - port.previous_position_m)
    correction[faulted] = 0.0
    if peer_target_m is not None:
        lanes = np.ones(len(command_m), bool) if enabled is None else np.asarray(enabled, bool)
        drift = port.drift_command(force, command_m + correction, peer_target_m)
        drift[~lanes | np.asarray(faulted, bool)] = 0.0
        correction = correction + drift
    moved = np.clip(command_m + correction, workspace_min_m, workspace_max_m)
    command_m[...] = moved
    origin_m += moved - last_command_m
    last_command_m[...] = moved
    port.observe(np.einsum("ij,ij->i", force, moved - port.previous_position_m))
    port.previous_position_m[...] = moved
