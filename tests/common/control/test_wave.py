"""Wave variables (common/control/wave.py and its Warp kernel): the transformation's power
identity, the passivity of a delayed, lossy channel, the energy credit and its bound, the
drift correction under loss, and the kernel equal to the numpy reference on random inputs,
non-finite ones included."""

from __future__ import annotations

import numpy as np
import pytest

from haptic.common.control.wave import (
    MASTER_SIGN,
    SLAVE_SIGN,
    WavePortState,
    WaveSettings,
    port_from_waves,
    wave_pair,
    wave_port_step_reference,
)
from haptic.common.control.wave_kernel import WavePortKernel

PERIOD_S = 0.001


def test_the_transformation_carries_the_port_power_and_inverts() -> None:
    rng = np.random.default_rng(0)
    force = rng.normal(0.0, 5.0, 1000)
    velocity = rng.normal(0.0, 0.2, 1000)
    for b in (0.5, 20.0, 400.0):
        u, w = wave_pair(force, velocity, b)
        np.testing.assert_allclose(force * velocity, (u * u - w * w) / 2.0, rtol=1e-12,
                                   atol=1e-12)
        back_force, back_velocity = port_from_waves(u, w, b)
        np.testing.assert_allclose(back_force, force, atol=1e-12)
        np.testing.assert_allclose(back_velocity, velocity, atol=1e-12)


def test_each_side_solves_its_port_from_the_received_wave() -> None:
    """The master's (velocity, force) make the received wave its outgoing one and the sent
    wave its incoming one; the slave's the other way round (admittance causality)."""
    settings = WaveSettings(period_s=PERIOD_S, filter_bandwidth_rad_s=0.0, drift_gain_per_s=0.0)
    b = settings.impedance_N_s_per_m
    force = np.array([[3.0, -1.5]])
    received = np.array([[0.7, -0.2]])
    fresh = np.array([True])
    for sign in (MASTER_SIGN, SLAVE_SIGN):
        energy = received * received * PERIOD_S / 2.0  # the peer's one wave's energy
        velocity, sent, _, _ = wave_port_step_reference(
            settings, WavePortState.create(1), sign, force, received, np.zeros((1, 2)), energy,
            fresh)
        u, w = wave_pair(force, velocity, b)
        into, out_of = (sent, received) if sign == MASTER_SIGN else (received, sent)
        np.testing.assert_allclose(u, into, atol=1e-12)
        np.testing.assert_allclose(w, out_of, atol=1e-12)


def _delayed_loop(settings: WaveSettings, loss: float, delay_steps: int, seconds: float,
                  seed: int, tremor_N: float = 0.0) -> tuple[np.ndarray, np.ndarray, float]:
    """An operator (a 200 N/m spring to a moving target, then a fixed one for the last
    4 s, plus a random force of ``tremor_N`` rms) on the master, a 5 N s/m damper on the
    slave, a constant delay each way, independent loss: (the channel's stored energy per step
    J, the positions' gap per step m, the final |x_m - x_s| m). The stored energy is the
    master port's work in minus the slave port's work out, from the ports' forces and
    velocities."""
    rng = np.random.default_rng(seed)
    master, slave = WavePortState.create(1), WavePortState.create(1)
    nothing = (np.zeros((1, 2)), np.zeros((1, 2)), np.zeros((1, 2)), np.array([True]))
    to_slave = [nothing] * delay_steps
    to_master = [nothing] * delay_steps
    x_m, x_s = np.zeros((1, 2)), np.zeros((1, 2))
    v_m, v_s = np.zeros((1, 2)), np.zeros((1, 2))
    ts = settings.period_s
    steps = int(round(seconds / ts))
    stored = np.empty(steps)
    gap = np.empty(steps)
    energy = 0.0
    for k in range(steps):
        t = k * ts
        if t < seconds - 4.0:
            target = np.array([[0.03 * np.sin(1.3 * t), 0.02 * np.sin(0.7 * t)]])
        else:
            target = np.array([[0.01, -0.01]])
        f_m = 200.0 * (target - x_m) - 5.0 * v_m + rng.normal(0.0, tremor_N, (1, 2))
        f_s = 5.0 * v_s
        v_m, *to_slave_message = wave_port_step_reference(settings, master, MASTER_SIGN, f_m,
                                                          *to_master.pop(0))
        v_s, *to_master_message = wave_port_step_reference(settings, slave, SLAVE_SIGN, f_s,
                                                           *to_slave.pop(0))
        to_slave.append((*to_slave_message, np.array([rng.random() >= loss])))
        to_master.append((*to_master_message, np.array([rng.random() >= loss])))
        energy += ts * float(np.sum(f_m * v_m) - np.sum(f_s * v_s))
        stored[k] = energy
        x_m = x_m + v_m * ts
        x_s = x_s + v_s * ts
        gap[k] = float(np.linalg.norm(x_m - x_s))
    return stored, gap, gap[-1]


def _random_ports(settings: WaveSettings, loss: float, delay_steps: int, seconds: float,
                  seed: int) -> np.ndarray:
    """Random forces at both ports (each side's law makes its velocity), a constant delay
    each way, independent loss: per step, the channel's stored energy (the master port's
    work in minus the slave port's work out, from forces and velocities) less the wave energy
    sent but not yet credited at the far side (in flight, or lost and not yet reported by a
    later message), J. Passivity: never negative (what the ports took out never exceeds what
    was credited, which never exceeds what was sent)."""
    rng = np.random.default_rng(seed)
    master, slave = WavePortState.create(1), WavePortState.create(1)
    nothing = (np.zeros((1, 2)), np.zeros((1, 2)), np.zeros((1, 2)), np.array([True]))
    to_slave = [nothing] * delay_steps
    to_master = [nothing] * delay_steps
    ts = settings.period_s
    steps = int(round(seconds / ts))
    margin = np.empty(steps)
    stored = 0.0
    for k in range(steps):
        f_m = rng.normal(0.0, 5.0, (1, 2))
        f_s = rng.normal(0.0, 5.0, (1, 2))
        v_m, *to_slave_message = wave_port_step_reference(settings, master, MASTER_SIGN, f_m,
                                                          *to_master.pop(0))
        v_s, *to_master_message = wave_port_step_reference(settings, slave, SLAVE_SIGN, f_s,
                                                           *to_slave.pop(0))
        to_slave.append((*to_slave_message, np.array([rng.random() >= loss])))
        to_master.append((*to_master_message, np.array([rng.random() >= loss])))
        stored += ts * float(np.sum(f_m * v_m) - np.sum(f_s * v_s))
        uncredited = float(np.sum(master.sent_energy_J - slave.credited_energy_J)
                           + np.sum(slave.sent_energy_J - master.credited_energy_J))
        margin[k] = stored - uncredited
    return margin


@pytest.mark.parametrize("loss", [0.0, 0.3])
@pytest.mark.parametrize("bandwidth_rad_s", [0.0, 60.0])
def test_the_delayed_channel_never_gives_out_more_energy_than_it_took_in(
        loss: float, bandwidth_rad_s: float) -> None:
    """50 ms each way, with and without loss and the filter, a strong drift correction: the
    channel holds at least the energy sent but not yet credited at every step (so its stored
    energy is never negative). The margin is the reserves, so a correction or a held wave
    spending energy that was not credited shows here."""
    settings = WaveSettings(period_s=PERIOD_S, drift_gain_per_s=20.0,
                            filter_bandwidth_rad_s=bandwidth_rad_s)
    margin = _random_ports(settings, loss, delay_steps=50, seconds=2.0, seed=3)
    assert margin.min() >= -1e-12


def test_the_drift_correction_never_uses_more_wave_energy_than_was_sent() -> None:
    """A strong correction towards an integral unrelated to the waves, half the messages
    lost: the used wave's energy stays within the energy the peer sent up to its newest
    received message over every prefix, and the correction still acts within that budget."""
    settings = WaveSettings(period_s=PERIOD_S, drift_gain_per_s=50.0, filter_bandwidth_rad_s=0.0)
    state = WavePortState.create(1)
    rng = np.random.default_rng(4)
    sent_energy = np.zeros((1, 2))
    credited_bound = used_energy = 0.0
    integral = np.zeros((1, 2))
    for _ in range(3000):
        wave = rng.normal(0.0, 0.5, (1, 2))
        sent_energy = sent_energy + wave * wave * PERIOD_S / 2.0
        fresh = np.array([rng.random() > 0.5])
        integral = integral + rng.normal(0.0, 0.01, (1, 2))  # an integral unrelated to waves
        velocity, _, _, _ = wave_port_step_reference(settings, state, SLAVE_SIGN,
                                                     np.zeros((1, 2)), wave, integral,
                                                     sent_energy, fresh)
        used = velocity * settings.impedance_N_s_per_m / np.sqrt(2 * settings.impedance_N_s_per_m)
        if fresh[0]:
            credited_bound = float(np.sum(sent_energy))
        used_energy += float(np.sum(used * used)) * PERIOD_S / 2.0
        assert used_energy <= credited_bound + 1e-12
    assert used_energy > 0.5 * credited_bound  # the correction did act within its budget


def test_a_peer_reporting_more_energy_than_it_sent_gains_no_more_than_an_honest_one() -> None:
    """A counter that leaps by a joule a message is credited at most the largest wave's energy
    per period since the last credit, and the reserve never exceeds its cap; non-finite and
    falling counters credit nothing."""
    settings = WaveSettings(period_s=PERIOD_S, reserve_max_J=10.0)
    state = WavePortState.create(1)
    claimed = np.zeros((1, 2))
    zero = np.zeros((1, 2))
    for step in range(200):
        fresh = np.array([step % 4 == 0])
        claimed = claimed + 1.0
        before = state.credited_energy_J.copy()
        wave_port_step_reference(settings, state, MASTER_SIGN, zero, zero, zero, claimed, fresh)
        gained = state.credited_energy_J - before
        periods = 4.0 if fresh[0] and step > 0 else 1.0
        assert np.all(gained <= periods * settings.credit_per_period_J + 1e-15)
    assert np.all(state.credited_energy_J <= 200 * settings.credit_per_period_J + 1e-12)
    for bad in (np.full((1, 2), np.nan), np.full((1, 2), np.inf), np.full((1, 2), -5.0)):
        before = state.credited_energy_J.copy()
        wave_port_step_reference(settings, state, MASTER_SIGN, zero, zero, zero, bad,
                                 np.array([True]))
        np.testing.assert_array_equal(state.credited_energy_J, before)
    capped = WaveSettings(period_s=PERIOD_S, reserve_max_J=1e-4)
    small = WavePortState.create(1)
    for step in range(50):
        wave_port_step_reference(capped, small, MASTER_SIGN, zero, zero, zero,
                                 np.full((1, 2), 1e3 * (step + 1)), np.array([True]))
        assert np.all(small.reserve_J <= capped.reserve_max_J)


def test_a_lost_wave_is_held_and_paid_for_once_its_energy_is_reported() -> None:
    """A constant wave with every other message lost: the stale periods hold the last wave
    once the reserve has it, and the used integral follows the sent one (the energy of the lost
    waves arrives with the next message)."""
    settings = WaveSettings(period_s=PERIOD_S, filter_bandwidth_rad_s=0.0)
    state = WavePortState.create(1)
    wave = np.array([[0.4, -0.3]])
    zero = np.zeros((1, 2))
    for step in range(4000):
        fresh = np.array([step % 2 == 0])
        sent_integral = wave * PERIOD_S * (step + 1)
        sent_energy = wave * wave * PERIOD_S / 2.0 * (step + 1)
        velocity, _, _, _ = wave_port_step_reference(settings, state, SLAVE_SIGN, zero, wave,
                                                     sent_integral, sent_energy, fresh)
    np.testing.assert_allclose(state.held_wave, wave)
    np.testing.assert_allclose(state.used_integral, sent_integral, rtol=0.01)
    assert state.stale_share[0, 0] == pytest.approx(0.5, abs=0.05)


def test_the_drift_correction_closes_the_gap_that_loss_leaves() -> None:
    """30 % loss each way, 100 ms each way: holding the lost waves alone leaves the sides about
    a tenth of a millimetre apart at rest; with the correction they end within 10 um."""
    off = WaveSettings(period_s=PERIOD_S, drift_gain_per_s=0.0)
    on = WaveSettings(period_s=PERIOD_S, drift_gain_per_s=5.0)
    _, _, gap_off = _delayed_loop(off, 0.3, delay_steps=100, seconds=10.0, seed=2)
    _, _, gap_on = _delayed_loop(on, 0.3, delay_steps=100, seconds=10.0, seed=2)
    assert gap_off > 5e-5
    assert gap_on < 1e-5
    assert gap_on < gap_off / 20.0


def test_the_kernel_equals_the_reference_on_random_inputs() -> None:
    lanes = 7
    for sign in (MASTER_SIGN, SLAVE_SIGN):
        settings = WaveSettings(period_s=PERIOD_S, drift_gain_per_s=20.0, reserve_max_J=0.01,
                                force_limit_N=10.0)
        reference = WavePortState.create(lanes)
        kernel = WavePortKernel(settings, lanes, sign)
        rng = np.random.default_rng(11)
        integral = np.zeros((lanes, 2))
        energy = np.zeros((lanes, 2))
        for step in range(600):
            force = rng.normal(0.0, 8.0, (lanes, 2))
            wave = rng.normal(0.0, 4.0, (lanes, 2))
            integral = integral + rng.normal(0.0, 0.01, (lanes, 2))
            sent_integral = integral.copy()
            energy = energy + rng.random((lanes, 2)) * 2e-3
            sent_energy = energy.copy()
            fresh = rng.random(lanes) > 0.2
            if step % 50 == 7:
                force[0, 0] = np.nan
                force[1, 1] = np.inf
                wave[2, 0] = -np.inf
                wave[3, 1] = np.nan
                sent_integral[4, 0] = np.nan
                wave[5, 0] = 1e300  # finite but beyond the limit
                sent_energy[6, 0] = np.nan
                sent_energy[6, 1] = 1e300  # a counter's leap: credited within the bound
            expected = wave_port_step_reference(settings, reference, sign, force, wave,
                                                sent_integral, sent_energy, fresh)
            got = kernel.step(force, wave, sent_integral, sent_energy, fresh)
            for name, a, b in zip(("velocity", "sent", "integral", "energy"), got, expected,
                                  strict=True):
                assert np.all(np.isfinite(a)), name
                np.testing.assert_allclose(a, b, rtol=0.0, atol=1e-12, err_msg=name)
        for name in WavePortKernel.STATE_FIELDS:
            np.testing.assert_allclose(getattr(kernel.state, name), getattr(reference, name),
                                       rtol=1e-12, atol=1e-12, err_msg=name)
        assert np.any(kernel.state.reserve_J > 0.0)
