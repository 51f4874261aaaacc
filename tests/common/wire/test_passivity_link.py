"""The passivity layer on the wire (common/wire/passivity_link.py): the peer's ``energy_J`` and
its restarts, the modes' flags and the refusal of a peer in the other mode."""

from __future__ import annotations

import pytest

from haptic.common.model.passivity import PassivityPort, PassivitySettings
from haptic.common.wire.errors import LinkOpenError
from haptic.common.wire.messages import Flags, HandleState
from haptic.common.wire.passivity_link import PassivityLink


def _message(energy_J: float, epoch: int = 1, flags: Flags = Flags.TDPA) -> HandleState:
    return HandleState(epoch, 0, 0, flags, (0.0, 0.0), (0.0, 0.0), energy_J=energy_J)


def test_the_peers_energy_is_read_and_a_new_epoch_restarts_its_count() -> None:
    """The ticks give the value to their node (tests/slave_sim/test_tick_peer_energy.py)."""
    port = PassivityPort.create(PassivitySettings(), 0.00054, 1)
    link = PassivityLink(True)
    port.peer_sent_J[:] = 0.003
    assert link.peer_energy(port, _message(0.003)) == 0.003
    assert port.peer_sent_J[0] == 0.003  # the same run: the count stands
    assert link.peer_energy(port, _message(0.0005, epoch=2)) == 0.0005
    assert port.peer_sent_J[0] == 0.0  # the peer restarted: counts from zero


def test_a_peer_configured_in_the_other_mode_is_refused_a_switched_one_is_not() -> None:
    with pytest.raises(LinkOpenError, match='mode = "tdpa"'):
        PassivityLink(False).check(_message(0.0))
    PassivityLink(False).check(_message(0.0, flags=Flags.TDPA_SWITCHED | Flags.FORCES_ENABLED))


def test_each_mode_sets_its_flag_and_sends_its_ports_energy() -> None:
    """A ``tdpa`` side flags every message TDPA and sends its port's cumulative handed-over
    energy (J); a ``paper`` side flags nothing and sends 0 J, as does a side whose node has
    no port yet."""
    from types import SimpleNamespace

    assert (PassivityLink(True).mode, PassivityLink(True).flags) == ("tdpa", Flags.TDPA)
    assert (PassivityLink(False).mode, PassivityLink(False).flags) == ("paper", Flags(0))
    assert int(PassivityLink(False).flags) == 0
    port = PassivityPort.create(PassivitySettings(), 0.00054, 2)
    port.sent_J[:] = (0.25, 0.75)
    assert PassivityLink.sent_J(SimpleNamespace(passivity=port)) == 0.25  # lane 0: the program's
    assert PassivityLink.sent_J(SimpleNamespace(passivity=None)) == 0.0
    assert PassivityLink.sent_J(object()) == 0.0
