"""``four-channel-tdpa``'s side on Warp (common/control/four_channel_tdpa_kernel.py: the
four-channel kernel, then the master's TDPA kernel) against its numpy reference
(common/control/four_channel_passivity.py), both sides, on random inputs with non-finite
ones; and the comparison's pair carrying each side's handed-over energy in its messages."""

from __future__ import annotations

import numpy as np
import pytest

from haptic.common.control.four_channel import FourChannelGains, Impedance, side_laws
from haptic.common.control.four_channel_passivity import (
    MASTER_PORT_SIGN,
    SLAVE_PORT_SIGN,
    PassiveSideState,
    passive_side_step_reference,
)
from haptic.common.control.four_channel_tdpa_kernel import PassiveFourChannelSideKernel
from haptic.common.control.law_pairs import (
    FourChannelPair,
    PassiveFourChannelPair,
    passivity_port,
)
from haptic.common.model.passivity import PassivitySettings

MANIPULATOR = Impedance(mass_kg=0.1, damping_N_s_per_m=1.0)
LOCAL = Impedance(damping_N_s_per_m=50.0, stiffness_N_per_m=500.0)
ACCOUNTS = ("tank_J", "sent_J", "peer_sent_J", "input_energy_J", "output_energy_J",
            "forgotten_energy_J", "dissipated_energy_J", "active_steps", "previous_position_m")


def test_the_kernel_equals_the_reference_on_random_inputs() -> None:
    """A small account (the credit cap and keep_J act often), random forces that make the
    ports active, the peer's energy now and then, lost messages and non-finite fields."""
    gains = FourChannelGains.transparent(MANIPULATOR, MANIPULATOR, LOCAL, LOCAL, c5=-1.0,
                                         c6=0.3)
    settings = PassivitySettings(credit_max_J=0.002, master_keep_J=0.0005)
    lanes = 6
    rng = np.random.default_rng(5)
    laws = side_laws(gains, 0.001, force_limit_N=10.0, speed_limit_m_per_s=0.5,
                     position_limit_m=0.2)
    for law, sign in zip(laws, (MASTER_PORT_SIGN, SLAVE_PORT_SIGN), strict=True):
        start = rng.normal(0.0, 0.01, (lanes, 2))
        reference = PassiveSideState.create(law, settings, settings.master_keep_J, start)
        kernel = PassiveFourChannelSideKernel(law, settings, settings.master_keep_J, sign, start)
        peer_energy = np.zeros(lanes)
        for step in range(1500):
            own = rng.normal(0.0, 6.0, (lanes, 2))
            position = rng.normal(0.0, 0.05, (lanes, 2))
            velocity = rng.normal(0.0, 0.3, (lanes, 2))
            force = rng.normal(0.0, 6.0, (lanes, 2))
            fresh = rng.random(lanes) > 0.2
            if step % 5 == 0:
                peer_energy = peer_energy + rng.random(lanes) * 2e-4
            energy = peer_energy.copy()
            if step % 40 == 3:
                own[0, 0], own[5, 1] = np.nan, -np.inf
                energy[1] = np.nan
                position[1, 1] = np.inf
            expected = passive_side_step_reference(law, reference, sign, own, position,
                                                   velocity, force, energy, fresh)
            got = kernel.step(own, position, velocity, force, energy, fresh)
            for a, b in zip(got, expected, strict=True):
                assert np.all(np.isfinite(a))
                np.testing.assert_allclose(a, b, rtol=0.0, atol=1e-12)
        assert reference.port.active_steps.sum() > 1000  # the controller did act
        for name in ACCOUNTS:
            np.testing.assert_allclose(getattr(kernel.port, name), getattr(reference.port, name),
                                       rtol=1e-9, atol=1e-12, err_msg=name)
        for name in reference.side.names:
            np.testing.assert_allclose(getattr(kernel.state, name),
                                       getattr(reference.side, name), rtol=0.0, atol=1e-12,
                                       err_msg=name)


def test_the_pair_carries_each_sides_handed_over_energy() -> None:
    """The operator pushes the handle: the master's input goes out in its message's energy
    channel, the slave credits it from there, and a stale message credits nothing."""
    lanes = 2
    pair = PassiveFourChannelPair(lanes)
    handle_message, tool_message = pair.initial_messages(lanes)
    fresh = np.ones(lanes, bool)
    push = np.array([[2.0, 0.0], [0.0, 0.0]])
    for _ in range(200):
        pair.master(push, tool_message, fresh, handle_message)
    sent = handle_message[:, 6].copy()
    assert sent[0] > 0.0 and sent[1] == 0.0
    np.testing.assert_array_equal(sent, pair.master_side.port.sent_J)
    zero = np.zeros((lanes, 2))
    pair.slave(zero, zero, zero, handle_message, np.array([True, False]), tool_message)
    np.testing.assert_array_equal(pair.slave_side.port.peer_sent_J, [sent[0], 0.0])


def test_each_side_reports_its_own_port() -> None:
    """The programs' summaries: each side's passivity port, the one its messages' energy comes
    from; a law without the layer has none."""
    lanes = 2
    pair = PassiveFourChannelPair(lanes)
    handle_message, tool_message = pair.initial_messages(lanes)
    fresh = np.ones(lanes, bool)
    push = np.array([[0.0, 0.0], [2.0, 0.0]])
    zero = np.zeros((lanes, 2))
    for _ in range(200):
        pair.master(push, tool_message, fresh, handle_message)
        pair.slave(zero, zero, zero, handle_message, fresh, tool_message)
    master, slave = passivity_port(pair, "master"), passivity_port(pair, "slave")
    assert master is pair.master_side.port and slave is pair.slave_side.port
    np.testing.assert_array_equal(master.sent_J, handle_message[:, 6])
    assert master.sent_J[1] > 0.0 and master.sent_J[0] == 0.0
    np.testing.assert_array_equal(slave.peer_sent_J, master.sent_J)
    assert passivity_port(FourChannelPair(lanes), "slave") is None
    with pytest.raises(ValueError, match="master or slave"):
        passivity_port(pair, "tool")
