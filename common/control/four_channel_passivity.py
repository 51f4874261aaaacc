"""The time-domain passivity layer (TDPA, :mod:`haptic.common.model.passivity`) on Lawrence's
four-channel scheme (:mod:`haptic.common.control.four_channel`): one side's numpy reference.

Both sides of the four-channel law command a position (admittance causality: force in,
position out), as the paper's master does, so each side runs the TDPA exactly as the paper's
master runs it (:func:`haptic.common.model.passivity.master_step_reference`): after the law's
step, the observer credits the energy the peer handed over (the cumulative ``sent_J`` its
messages carry), the adaptive conductance moves the position command along the port's force
by what the account lacks for this step's work, and the step's work is observed; the side's
own input beyond ``keep_J`` is handed to the peer. The correction is written into the virtual
manipulator's position, so it persists (the law's position channels see the yielded
position, and the peer receives it).

The ports (work into the network per period, J):

- master: ``fh . dxm``, the operator's force (N) on the step of the handle's position command;
- slave: ``-fe . dxs``, the environment's force on the tool (``-fe``, N, where ``fe`` is the
  force the tool applies) on the step of the tool's position command.

Each side's position servo and device terminate its port, as the handle's servo terminates
the paper's master port: energy made between a command and its device (a servo's lag
against a stiff wall) is outside the observed two-port, and the layer does not see it.

The port force is ``port_sign`` times the force the side's law measures: +1 on the master
(:data:`MASTER_PORT_SIGN`), -1 on the slave (:data:`SLAVE_PORT_SIGN`). With a passive operator
and a passive environment the two-port then gives out no more than it took in, whatever the
delay and loss (docs/control.md, docs/architectures.md). Where the account never runs short,
the conductance never acts and the positions are the plain four-channel law's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from haptic.common.control.four_channel import SideLaw, SideState, side_step_reference
from haptic.common.model.passivity import PassivityPort, PassivitySettings, master_step_reference

#: The master's port force is the operator's force on the handle.
MASTER_PORT_SIGN = 1.0
#: The slave's port force is the environment's force on the tool: minus what the tool applies.
SLAVE_PORT_SIGN = -1.0


@dataclass(eq=False)
class PassiveSideState:
    """One side over lanes: the four-channel law's state (``side``), the TDPA port
    (``port``), and the command's last value and offset (``last_command_m``, ``origin_m``,
    (lanes, 2), m) that the TDPA step re-bases as the paper's master does (kept for the
    arithmetic's sake; the four-channel law reads neither)."""

    side: SideState
    port: PassivityPort
    last_command_m: np.ndarray
    origin_m: np.ndarray

    @classmethod
    def create(cls, law: SideLaw, settings: PassivitySettings, keep_J: float,
               start_m: np.ndarray) -> PassiveSideState:
        """At rest at ``start_m`` (lanes, 2), m, with an empty account that keeps ``keep_J``
        (J) of its own input to return itself."""
        side = SideState.create(start_m)
        lanes = side.position_m.shape[0]
        port = PassivityPort.create(settings, law.period_s, lanes, keep_J)
        port.previous_position_m[...] = side.position_m
        return cls(side, port, side.position_m.copy(), np.zeros_like(side.position_m))


def passive_side_step_reference(law: SideLaw, state: PassiveSideState, port_sign: float,
                                own_force_N: np.ndarray, peer_position_m: np.ndarray,
                                peer_velocity_m_per_s: np.ndarray, peer_force_N: np.ndarray,
                                peer_energy_J: np.ndarray, fresh: np.ndarray
                                ) -> tuple[np.ndarray, np.ndarray]:
    """One period of one side with the TDPA over lanes: (position command m, velocity m/s),
    each (lanes, 2); ``state`` advances in place. ``peer_energy_J`` (lanes,) is the peer's
    cumulative handed-over energy in its message, taken where ``fresh``; the energy this side
    hands over is ``state.port.sent_J`` after the call."""
    _, velocity = side_step_reference(law, state.side, own_force_N, peer_position_m,
                                      peer_velocity_m_per_s, peer_force_N, fresh)
    state.port.receive(np.where(np.asarray(fresh, bool), peer_energy_J, np.nan))
    lanes = state.side.position_m.shape[0]
    limit = np.full(2, law.position_limit_m)
    master_step_reference(state.port, port_sign * np.asarray(own_force_N, float),
                          state.side.position_m, state.last_command_m, state.origin_m,
                          np.zeros(lanes, bool), law.force_limit_N, -limit, limit)
    return state.side.position_m.copy(), velocity


__all__ = ["MASTER_PORT_SIGN", "SLAVE_PORT_SIGN", "PassiveSideState",
           "passive_side_step_reference"]
