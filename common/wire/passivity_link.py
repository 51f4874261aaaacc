"""The passivity layer on the wire: what a program does with ``energy_J`` and the
TDPA flag of the messages, in a few calls from its tick (master/program.py,
slave_sim/program.py).

A side in ``tdpa`` mode sends its port's cumulative handed-over energy with :attr:`Flags.TDPA`
set, takes the peer's from every fresh message (a new peer epoch restarts the count), and
refuses a peer in the other mode with a one-line :class:`LinkOpenError` (exit status 4), so
that two programs never run half a passivity layer.
"""

from __future__ import annotations

from typing import Any

from haptic.common.model.passivity import PassivityPort
from haptic.common.wire.errors import LinkOpenError
from haptic.common.wire.messages import Flags, control_mismatch


class PassivityLink:
    """One program's side of the energy exchange; ``tdpa``: this side runs the layer."""

    def __init__(self, tdpa: bool) -> None:
        self.mode = "tdpa" if tdpa else "paper"
        self.flags = Flags.TDPA if tdpa else Flags(0)
        self._peer_epoch: int | None = None
        self._checked_epoch: int | None = None

    def check(self, message: Any) -> None:
        """Raise :class:`LinkOpenError` when the first message of a peer's run (epoch) shows
        the other mode; later messages of that run are not checked again (a stopping peer's
        last safe-state message carries no mode)."""
        if message.epoch == self._checked_epoch:
            return
        why = control_mismatch(self.mode, message)
        if why is not None:
            raise LinkOpenError(why)
        self._checked_epoch = message.epoch

    def peer_energy(self, port: PassivityPort, message: Any) -> float:
        """The peer's cumulative handed-over energy in ``message``, J; a new epoch (the peer
        restarted) first makes ``port`` count the peer's energy from zero again. The ticks
        give it to their node (master/tick.py ``control``, slave_sim/tick.py
        ``receive_peer_energy``)."""
        if message.epoch != self._peer_epoch:
            if self._peer_epoch is not None:
                port.peer_restarted()
            self._peer_epoch = message.epoch
        return float(message.energy_J)

    @staticmethod
    def sent_J(state: Any) -> float:
        """The energy to put in this side's message: the port's cumulative handed-over energy
        (0 in ``paper`` mode or before the node has a state)."""
        port = getattr(state, "passivity", None)
        return 0.0 if port is None else float(port.sent_J[0])
