"""The TDPA on the four-channel scheme (common/control/four_channel_passivity.py): on a delayed,
lossy channel where the plain law is active it keeps the two-port's output within its input,
where the plain law runs away it stays bounded, and where no account runs short it changes
nothing (transparency at zero delay unchanged)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from haptic.common.control.four_channel import (
    FourChannelGains,
    Impedance,
    SideState,
    side_laws,
    side_step_reference,
)
from haptic.common.control.four_channel_passivity import (
    MASTER_PORT_SIGN,
    SLAVE_PORT_SIGN,
    PassiveSideState,
    passive_side_step_reference,
)
from haptic.common.model.passivity import PassivitySettings

PERIOD_S = 0.001
MANIPULATOR = Impedance(mass_kg=0.1, damping_N_s_per_m=1.0)


def _gains(local_damping_N_s_per_m: float) -> FourChannelGains:
    """Lawrence's transparent channels without the masses around 500 N/m local controllers
    (the comparison's with 50 N s/m)."""
    local = Impedance(damping_N_s_per_m=local_damping_N_s_per_m, stiffness_N_per_m=500.0)
    return FourChannelGains.transparent(MANIPULATOR, MANIPULATOR, local, local,
                                        channel_masses=False)


@dataclass
class LoopRecord:
    """What a loop did: the two-port's cumulative work in (J) after each period, the handle's
    position (m) and both sides' speeds (m/s) per period, and the sides (their ports)."""

    work_J: np.ndarray
    handle_m: np.ndarray
    speed_m_per_s: np.ndarray
    master: object
    slave: object


def _loop(gains: FourChannelGains, tdpa: bool, delay_periods: int, loss: float,
          operator: tuple[float, float, float, float], environment: Impedance,
          seconds: float = 4.0, seed: int = 1) -> LoopRecord:
    """Both sides over one lane with ideal devices (each at its last command), the messages
    ``delay_periods`` late each way (at least one), each lost with probability ``loss``. The
    operator: a spring and damper (``operator`` = N/m, N s/m) to a sine (m, Hz) on the handle;
    the environment a spring and damper on the tool. The two-port's work in per period:
    ``fh . dxm - fe . dxs`` on the sides' command steps (the ports the layer observes)."""
    stiffness, damping, amplitude, frequency = operator
    master_law, slave_law = side_laws(gains, PERIOD_S)
    settings, zero = PassivitySettings(), np.zeros((1, 2))
    if tdpa:
        master = PassiveSideState.create(master_law, settings, settings.master_keep_J, zero)
        slave = PassiveSideState.create(slave_law, settings, settings.slave_keep_J, zero)
    else:
        master, slave = SideState.create(zero), SideState.create(zero)
    handle_state = master.side if tdpa else master
    tool_state = slave.side if tdpa else slave
    rng = np.random.default_rng(seed)
    silent = (zero, zero, zero, np.zeros(1), np.array([False]))
    to_slave, to_master = [silent] * delay_periods, [silent] * delay_periods
    steps = int(round(seconds / PERIOD_S))
    work, handle, speed = np.empty(steps), np.empty(steps), np.empty(steps)
    total, last_handle, last_tool = 0.0, zero, zero
    for k in range(steps):
        target = np.array([[amplitude * np.sin(2.0 * np.pi * frequency * k * PERIOD_S), 0.0]])
        fh = stiffness * (target - handle_state.position_m) - damping * (
            handle_state.velocity_m_per_s)
        fe = (environment.stiffness_N_per_m * tool_state.position_m
              + environment.damping_N_s_per_m * tool_state.velocity_m_per_s)
        slot = k % delay_periods
        if tdpa:
            xm, vm = passive_side_step_reference(master_law, master, MASTER_PORT_SIGN, fh,
                                                 *to_master[slot])
            xs, vs = passive_side_step_reference(slave_law, slave, SLAVE_PORT_SIGN, fe,
                                                 *to_slave[slot])
            energy = (master.port.sent_J.copy(), slave.port.sent_J.copy())
        else:
            xm, vm = side_step_reference(master_law, master, fh, *to_master[slot][:3],
                                         to_master[slot][4])
            xs, vs = side_step_reference(slave_law, slave, fe, *to_slave[slot][:3],
                                         to_slave[slot][4])
            energy = (np.zeros(1), np.zeros(1))
        total += float(fh[0] @ (xm[0] - last_handle[0]) - fe[0] @ (xs[0] - last_tool[0]))
        last_handle, last_tool = xm, xs
        work[k], handle[k] = total, xm[0, 0]
        speed[k] = max(np.abs(vm).max(), np.abs(vs).max())
        to_slave[slot] = (xm, vm, fh, energy[0], rng.random(1) >= loss)
        to_master[slot] = (xs, vs, fe, energy[1], rng.random(1) >= loss)
    return LoopRecord(work, handle, speed, master, slave)


STIFF_OPERATOR = (2000.0, 20.0, 0.01, 1.0)
STIFF_ENVIRONMENT = Impedance(stiffness_N_per_m=2000.0)


@pytest.mark.parametrize("delay_periods", [10, 50])
def test_the_layer_keeps_the_output_within_the_input_where_the_plain_law_is_active(
        delay_periods: int) -> None:
    """The comparison's gains, 10 or 50 ms each way, 20 % loss, a stiff operator and a stiff
    environment: the plain two-port gives out more than it took in (0.1 to 0.25 J); with the
    layer its work in never goes below zero."""
    gains = _gains(50.0)
    plain = _loop(gains, False, delay_periods, 0.2, STIFF_OPERATOR, STIFF_ENVIRONMENT)
    passive = _loop(gains, True, delay_periods, 0.2, STIFF_OPERATOR, STIFF_ENVIRONMENT)
    assert plain.work_J.min() < -0.05
    assert passive.work_J.min() >= -1e-9
    assert np.isfinite(passive.handle_m).all()


def test_the_layer_bounds_what_the_plain_law_runs_away_with() -> None:
    """Lightly damped local controllers (5 N s/m), 50 ms each way, 20 % loss: the plain law
    runs away to the speed limit, creating joules; with the layer the sides stay slow and the
    energy it could not dissipate in time (the controller's caps) is what its accounts show
    short, a fraction of that."""
    gains = _gains(5.0)
    plain = _loop(gains, False, 50, 0.2, STIFF_OPERATOR, STIFF_ENVIRONMENT)
    passive = _loop(gains, True, 50, 0.2, STIFF_OPERATOR, STIFF_ENVIRONMENT)
    assert plain.speed_m_per_s.max() == pytest.approx(1.0)  # pinned at the speed limit
    assert plain.work_J.min() < -1.0
    assert passive.speed_m_per_s.max() < 0.5
    assert passive.work_J.min() > -0.3
    deficit = float(passive.master.port.tank_J[0] + passive.slave.port.tank_J[0])
    assert passive.work_J[-1] >= deficit - 1e-9  # in flight and forgotten are never negative


def test_without_a_deficit_the_layer_changes_nothing() -> None:
    """Free motion, one period each way, no loss, a stiff operator on a 5 mm sine: what the
    master gives back (the manipulators' kinetic energy) stays within what it keeps of its own
    input (``keep_J``), so no account runs short, the controllers never act, and the handle
    moves exactly as without the layer: the zero-delay transparency is the plain law's."""
    gains = _gains(50.0)
    operator = (2000.0, 20.0, 0.005, 1.0)
    plain = _loop(gains, False, 1, 0.0, operator, Impedance())
    passive = _loop(gains, True, 1, 0.0, operator, Impedance())
    assert passive.master.port.active_steps[0] == 0
    assert passive.slave.port.active_steps[0] == 0
    assert passive.master.port.input_energy_J[0] > 1e-3  # energy did flow through the account
    np.testing.assert_array_equal(passive.handle_m, plain.handle_m)
    np.testing.assert_array_equal(passive.work_J, plain.work_J)


def test_a_spring_that_gives_back_more_than_is_kept_makes_the_master_yield() -> None:
    """The same loop against a 500 N/m, 5 N s/m environment: the spring gives back up to
    6 mJ a period before the slave's account of it reaches the master, which keeps 2 mJ, so
    the master runs short and yields (the handle ends up to about a tenth of the sine's
    amplitude off the plain law's path): the layer's cost in transparency at zero delay on a
    contact, which the comparison's wall and clay cells measure."""
    gains = _gains(50.0)
    operator = (2000.0, 20.0, 0.005, 1.0)
    environment = Impedance(damping_N_s_per_m=5.0, stiffness_N_per_m=500.0)
    plain = _loop(gains, False, 1, 0.0, operator, environment)
    passive = _loop(gains, True, 1, 0.0, operator, environment)
    assert passive.master.port.active_steps[0] > 0
    assert passive.work_J.min() >= -1e-9
    assert 0.0 < np.abs(passive.handle_m - plain.handle_m).max() < 0.2 * operator[2]
