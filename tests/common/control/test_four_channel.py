"""Lawrence's four-channel scheme (common/control/four_channel.py, its kernel) and its
two-port analysis (common/control/two_port.py): transparency at zero delay in the analysis and
in the sampled loop, Llewellyn's verdict on known cases, the kernel equal to the reference."""

from __future__ import annotations

import numpy as np
import pytest

from haptic.common.control.four_channel import (
    FourChannelGains,
    Impedance,
    SideState,
    side_laws,
    side_step_reference,
)
from haptic.common.control.four_channel_kernel import FourChannelSideKernel
from haptic.common.control.two_port import (
    absolute_stability,
    hybrid_matrix,
    llewellyn,
    transmitted_impedance,
)

PERIOD_S = 0.001
HANDLE = Impedance(mass_kg=0.1, damping_N_s_per_m=1.0)
TOOL = Impedance(mass_kg=0.1, damping_N_s_per_m=1.0)
LOCAL = Impedance(damping_N_s_per_m=50.0, stiffness_N_per_m=500.0)
BAND_RAD_S = np.logspace(-1, 3, 300)


@pytest.mark.parametrize("environment", [Impedance(0.0, 5.0, 2000.0), Impedance(0.0, 40.0),
                                         Impedance(2.0, 0.0, 0.0), Impedance(0.3, 3.0, 300.0)])
@pytest.mark.parametrize("c5", [0.0, -1.0])
def test_the_transparent_gains_give_the_operator_the_environment_at_zero_delay(
        environment: Impedance, c5: float) -> None:
    gains = FourChannelGains.transparent(HANDLE, TOOL, LOCAL, LOCAL, c5=c5)
    h = hybrid_matrix(gains, BAND_RAD_S)
    np.testing.assert_allclose(h[:, 0, 0], 0.0, atol=1e-9)
    np.testing.assert_allclose(h[:, 1, 1], 0.0, atol=1e-9)
    np.testing.assert_allclose(h[:, 0, 1] * h[:, 1, 0], -1.0, atol=1e-9)
    ze = environment.at(1j * BAND_RAD_S)
    np.testing.assert_allclose(transmitted_impedance(h, ze), ze, rtol=1e-9)


def test_position_position_is_not_transparent() -> None:
    """The two-channel scheme adds its coupling's compliance: a stiff wall feels softer."""
    gains = FourChannelGains.position_position(HANDLE, TOOL, LOCAL, LOCAL)
    w = np.array([1.0])
    wall = Impedance(0.0, 5.0, 20000.0).at(1j * w)
    felt = transmitted_impedance(hybrid_matrix(gains, w), wall)
    assert abs(felt[0]) < 0.1 * abs(wall[0])


def _sampled_loop(gains: FourChannelGains, environment: Impedance, frequency_hz: float,
                  seconds: float = 6.0) -> tuple[complex, float]:
    """Both sides' discrete laws, each message one period late, an operator as a stiff
    spring (2000 N/m, 20 N s/m) to a 5 mm sine on the handle, a spring and damper environment
    (explicit: from the tool's last state): (fh / vh at the sine's frequency over the last
    whole periods of the second half, the largest handle speed m/s)."""
    master_law, slave_law = side_laws(gains, PERIOD_S)
    master = SideState.create(np.zeros((1, 2)))
    slave = SideState.create(np.zeros((1, 2)))
    zeros = np.zeros((1, 2))
    to_master = (zeros, zeros, zeros)
    to_slave = (zeros, zeros, zeros)
    fresh = np.array([True])
    steps = int(round(seconds / PERIOD_S))
    force = np.empty(steps)
    speed = np.empty(steps)
    for k in range(steps):
        target = np.array([[0.005 * np.sin(2.0 * np.pi * frequency_hz * k * PERIOD_S), 0.0]])
        fh = 2000.0 * (target - master.position_m) - 20.0 * master.velocity_m_per_s
        fe = (environment.stiffness_N_per_m * slave.position_m
              + environment.damping_N_s_per_m * slave.velocity_m_per_s)
        xm, vm = side_step_reference(master_law, master, fh, *to_master, fresh)
        xs, vs = side_step_reference(slave_law, slave, fe, *to_slave, fresh)
        to_slave, to_master = (xm, vm, fh), (xs, vs, fe)
        force[k], speed[k] = fh[0, 0], vm[0, 0]
    t = np.arange(steps) * PERIOD_S
    window = np.floor(seconds / 2.0 * frequency_hz) / frequency_hz
    keep = t >= seconds - window
    phasor = np.exp(-2j * np.pi * frequency_hz * t[keep])
    return complex(np.sum(force[keep] * phasor) / np.sum(speed[keep] * phasor)), float(
        np.abs(speed).max())


@pytest.mark.parametrize("frequency_hz", [0.5, 1.0, 2.0])
def test_the_sampled_loop_is_transparent_up_to_the_masses(frequency_hz: float) -> None:
    """The discrete laws with the masses out of the channels, a message a period late each
    way: the operator feels the environment (500 N/m, 5 N s/m) within 6 %, as the two-port
    at one period's delay predicts within 3 %."""
    gains = FourChannelGains.transparent(HANDLE, TOOL, LOCAL, LOCAL, channel_masses=False)
    environment = Impedance(0.0, 5.0, 500.0)
    felt, _ = _sampled_loop(gains, environment, frequency_hz)
    w = np.array([2.0 * np.pi * frequency_hz])
    ze = environment.at(1j * w)[0]
    assert abs(felt / ze - 1.0) < 0.06
    predicted = transmitted_impedance(hybrid_matrix(gains, w, PERIOD_S), np.array([ze]))[0]
    assert abs(felt / predicted - 1.0) < 0.03


def test_feeding_the_masses_forward_a_period_late_runs_away() -> None:
    gains = FourChannelGains.transparent(HANDLE, TOOL, LOCAL, LOCAL)
    _, fastest = _sampled_loop(gains, Impedance(0.0, 5.0, 500.0), 1.0, seconds=2.0)
    assert fastest == pytest.approx(1.0)  # pinned at the speed limit


def test_llewellyn_on_known_cases() -> None:
    """Position-position coupling of passive manipulators at zero delay is absolutely
    stable; the transparent scheme at zero delay is lossless (on the boundary, accepted);
    with 5 ms each way the transparent scheme is not, while position-position still is."""
    pp = FourChannelGains.position_position(HANDLE, TOOL, LOCAL, LOCAL)
    transparent = FourChannelGains.transparent(HANDLE, TOOL, LOCAL, LOCAL)
    verdict = llewellyn(hybrid_matrix(pp, BAND_RAD_S), BAND_RAD_S)
    assert verdict.absolutely_stable and verdict.min_re_h11 > 0.0
    assert llewellyn(hybrid_matrix(transparent, BAND_RAD_S), BAND_RAD_S).absolutely_stable
    delayed = llewellyn(hybrid_matrix(transparent, BAND_RAD_S, 0.005), BAND_RAD_S)
    assert not delayed.absolutely_stable and delayed.min_eta < 0.0
    assert llewellyn(hybrid_matrix(pp, BAND_RAD_S, 0.005), BAND_RAD_S).absolutely_stable


def test_the_pole_condition_rejects_a_hidden_unstable_controller() -> None:
    """Transparent channels around a slave controller with negative damping cancel it out of
    H exactly (the inequalities hold, on the boundary), but D = Zcs + Zcm keeps its
    right-half-plane zeros: h11's poles. Only the pole check sees them."""
    unstable = Impedance(damping_N_s_per_m=-60.0, stiffness_N_per_m=500.0)
    gains = FourChannelGains.transparent(HANDLE, TOOL, LOCAL, unstable)
    assert llewellyn(hybrid_matrix(gains, BAND_RAD_S), BAND_RAD_S).absolutely_stable
    verdict = absolute_stability(gains, BAND_RAD_S)
    assert verdict.rhp_poles and not verdict.absolutely_stable
    healthy = absolute_stability(FourChannelGains.transparent(HANDLE, TOOL, LOCAL, LOCAL),
                                 BAND_RAD_S)
    assert healthy.absolutely_stable and healthy.rhp_poles is False
    assert absolute_stability(gains, BAND_RAD_S, 0.005).rhp_poles is None  # not checked


def test_the_kernel_equals_the_reference_on_random_inputs() -> None:
    gains = FourChannelGains.transparent(HANDLE, TOOL, LOCAL, LOCAL, c5=-1.0, c6=0.3)
    lanes = 6
    rng = np.random.default_rng(17)
    for law in side_laws(gains, PERIOD_S, force_limit_N=10.0, speed_limit_m_per_s=0.5,
                         position_limit_m=0.2):
        start = rng.normal(0.0, 0.01, (lanes, 2))
        reference = SideState.create(start)
        kernel = FourChannelSideKernel(law, start)
        for step in range(500):
            own = rng.normal(0.0, 6.0, (lanes, 2))
            position = rng.normal(0.0, 0.05, (lanes, 2))
            velocity = rng.normal(0.0, 0.3, (lanes, 2))
            force = rng.normal(0.0, 6.0, (lanes, 2))
            fresh = rng.random(lanes) > 0.2
            if step % 40 == 3:
                own[0, 0] = np.nan
                position[1, 1] = np.inf
                velocity[2, 0] = np.nan
                force[3, 1] = -np.inf
                position[4, 0] = 1e300  # finite, beyond the limit
            expected = side_step_reference(law, reference, own, position, velocity, force,
                                           fresh)
            got = kernel.step(own, position, velocity, force, fresh)
            for a, b in zip(got, expected, strict=True):
                assert np.all(np.isfinite(a))
                np.testing.assert_allclose(a, b, rtol=0.0, atol=1e-12)
        for name in reference.names:
            np.testing.assert_allclose(getattr(kernel.state, name), getattr(reference, name),
                                       rtol=0.0, atol=1e-12, err_msg=name)
