"""The TDPA layer (common/model/passivity.py): the observer's accounting, the controllers
dissipating exactly the excess, and each pitfall of issue 16 (velocity floor and damper cap,
credit spent in bursts, bursts out of the controller)."""

from __future__ import annotations

import numpy as np
import pytest

from haptic.common.model.passivity import PassivityPort, PassivitySettings

TS = 0.00054


def port(lanes: int = 1, keep_J: float = 0.0, **changes: float) -> PassivityPort:
    return PassivityPort.create(PassivitySettings(**changes), TS, lanes, keep_J)


def test_received_energy_is_monotone_so_loss_and_reordering_only_delay_it() -> None:
    p = port(3)
    p.receive(np.array([0.1, 0.2, np.nan]))
    p.receive(np.array([0.05, np.nan, 0.3]))  # an older message and a lane without one
    assert p.peer_sent_J.tolist() == [0.1, 0.2, 0.3]
    assert p.tank_J.tolist() == pytest.approx([0.1, 0.2, 0.3])
    p.receive(np.array([0.1, 0.2, 0.3]))  # the same value again adds nothing
    assert p.tank_J.tolist() == pytest.approx([0.1, 0.2, 0.3])


def test_the_account_conserves_energy_and_hands_over_what_it_does_not_keep() -> None:
    p = port(2, keep_J=0.01, credit_max_J=10.0)
    rng = np.random.default_rng(1)
    for _ in range(200):
        p.observe(rng.normal(0.001, 0.002, 2))
        p.receive(p.peer_sent_J + rng.random(2) * 1e-3)
    # tank = received + in - out - handed over - forgotten, exactly.
    balance = (p.peer_sent_J + p.input_energy_J - p.output_energy_J - p.sent_J
               - p.forgotten_energy_J)
    assert p.tank_J == pytest.approx(balance, abs=1e-12)
    assert np.all(p.sent_J > 0.0)  # own input beyond keep_J went to the peer
    assert np.all(p.sent_J <= p.input_energy_J)  # and never more than the own input
    q = port(1, keep_J=0.01)
    q.observe(np.array([0.03]))
    assert q.tank_J[0] == pytest.approx(0.01) and q.sent_J[0] == pytest.approx(0.02)


def test_the_damper_dissipates_exactly_the_excess() -> None:
    p = port(1, damper_force_rate_N_per_s=1e9)  # the rise limit is pinned on its own
    p.receive(np.array([0.0004]))
    velocity = np.array([[0.3, -0.4]])  # 0.5 m/s
    tool_force = np.array([[6.0, -8.0]])  # ft . v = 5 W: 2.7 mJ this step
    actuator = np.array([[1.0, 2.0]])
    out = p.damp(actuator, velocity, tool_force)
    excess = 5.0 * TS - 0.0004
    alpha = excess / (TS * 0.25)
    assert out == pytest.approx(actuator - alpha * velocity)
    assert p.dissipated_energy_J[0] == pytest.approx(excess)


def test_no_action_below_the_velocity_floor_and_the_deficit_waits() -> None:
    p = port(1, velocity_floor_m_per_s=1e-3)
    velocity = np.array([[1e-9, 0.0]])  # |v|^2 = 1e-18: alpha would be astronomic
    out = p.damp(np.array([[1.0, 0.0]]), velocity, np.array([[5.0, 0.0]]))
    assert out.tolist() == [[1.0, 0.0]]
    p.observe(np.array([-1e-6]))  # the step's output happened anyway
    assert p.tank_J[0] < 0.0  # the observer keeps the deficit for the next steps
    out = p.damp(np.array([[1.0, 0.0]]), np.array([[0.01, 0.0]]), np.array([[0.0, 0.0]]))
    assert out[0, 0] < 1.0  # paid back as soon as the tool moves


def test_the_damper_is_capped_and_its_force_rises_gradually() -> None:
    settings = dict(damper_max_N_s_per_m=500.0, damper_force_max_N=10.0,
                    damper_force_rate_N_per_s=4000.0)
    p = port(1, **settings)
    velocity = np.array([[0.05, 0.0]])
    forces = []
    for _ in range(20):  # a large deficit: the whole clay force with an empty account
        out = p.damp(np.zeros((1, 2)), velocity, np.array([[1000.0, 0.0]]))
        forces.append(-out[0, 0])
    forces = np.array(forces)
    assert np.all(forces / 0.05 <= 500.0 + 1e-9)  # alpha capped
    assert np.all(forces <= 10.0 + 1e-12)  # damper force capped
    assert np.all(np.diff(np.r_[0.0, forces]) <= 4000.0 * TS + 1e-12)  # no kick
    assert forces[-1] == pytest.approx(min(500.0 * 0.05, 10.0))


def test_credit_is_capped_so_it_cannot_pay_for_a_burst_later() -> None:
    p = port(1, credit_max_J=0.05)
    p.receive(np.array([10.0]))  # a long passive stretch on the other side
    assert p.reserve_J()[0] == pytest.approx(0.05)
    assert p.forgotten_energy_J[0] == pytest.approx(9.95)
    # A burst worth 0.2 J in one step is not paid from the forgotten credit: the damper acts.
    velocity = np.array([[1.0, 0.0]])
    out = p.damp(np.zeros((1, 2)), velocity, np.array([[0.2 / TS, 0.0]]))
    assert out[0, 0] < 0.0


def test_the_master_yields_along_the_push_by_exactly_the_excess() -> None:
    p = port(1)
    force = np.array([[3.0, 4.0]])  # 5 N
    step = np.array([[-0.0003, -0.0004]])  # against the push: 2.5 mJ out
    correction = p.yield_command(force, step)
    excess = 2.5e-3
    assert np.einsum("ij,ij->i", force, correction)[0] == pytest.approx(
        min(excess, 0.05 * 25.0 * TS, 0.2 * TS * 5.0, 200.0 * TS * TS * 5.0))
    cross = force[0, 0] * correction[0, 1] - force[0, 1] * correction[0, 0]
    assert cross == pytest.approx(0.0, abs=1e-15)
    assert correction[0, 0] > 0.0


def test_the_master_controller_stays_off_below_the_force_floor() -> None:
    p = port(1, force_floor_N=0.05)
    correction = p.yield_command(np.array([[1e-12, 0.0]]), np.array([[-1.0, 0.0]]))
    assert correction.tolist() == [[0.0, 0.0]]


def test_drift_correction_adds_no_energy() -> None:
    p = port(2)  # empty account
    gap = np.array([[0.01, 0.0], [0.01, 0.0]])  # the tool should move +x
    velocity = np.array([[-0.1, 0.0], [0.1, 0.0]])  # lane 0 moves away: braking dissipates
    force = p.drift_force(gap, velocity, np.zeros((2, 2)))
    assert force[0, 0] > 0.0  # applied where it dissipates
    assert force[1, 0] == 0.0  # withheld where it would drive the tool with no energy
    p.receive(np.array([1.0, 1.0]))
    paid = p.drift_force(gap, velocity, np.zeros((2, 2)))
    assert paid[1, 0] > 0.0  # applied when the account pays for it


def test_the_master_drifts_to_the_tool_for_free_without_an_operator_force() -> None:
    """With no operator force the command's step costs nothing at the port (fh . dcmd = 0):
    it moves the gap times rate Ts towards the target, capped at the speed limit, from an
    empty account; no target (NaN) or a zero rate, no step."""
    p = port(3, master_drift_rate_per_s=2.0, master_drift_speed_max_m_per_s=0.005)
    command = np.zeros((3, 2))
    target = np.array([[0.001, -0.002], [0.5, 0.0], [np.nan, 0.0]])
    step = p.drift_command(np.zeros((3, 2)), command, target)
    np.testing.assert_allclose(step[0], target[0] * 2.0 * TS, rtol=1e-12)
    np.testing.assert_allclose(step[1], [0.005 * TS, 0.0], rtol=1e-12)  # capped
    assert step[2].tolist() == [0.0, 0.0]
    off = port(1, master_drift_rate_per_s=0.0)
    assert off.drift_command(np.zeros((1, 2)), command[:1], target[:1]).tolist() == [[0.0, 0.0]]


def test_the_master_drift_against_the_operator_is_paid_from_the_account() -> None:
    """Along the operator's push the drift takes the operator's input (always); against it,
    the work the port gives out (-fh . d) is at most what the account holds: none from an
    empty one, all of it once the account pays."""
    p = port(2, master_drift_rate_per_s=2.0)
    force = np.array([[1.0, 0.0], [-1.0, 0.0]])  # lane 0 pushes towards +x, lane 1 against
    command = np.zeros((2, 2))
    target = np.array([[0.002, 0.0], [0.002, 0.0]])
    step = p.drift_command(force, command, target)
    assert step[0, 0] == pytest.approx(0.002 * 2.0 * TS)
    assert step[1, 0] == 0.0
    p.receive(np.array([1e-9, 1e-9]))  # a little energy: pays part of the step
    part = p.drift_command(force, command, target)
    assert -np.dot(force[1], part[1]) == pytest.approx(1e-9)
    p.receive(np.array([1.0, 1.0]))
    paid = p.drift_command(force, command, target)
    assert paid[1, 0] == pytest.approx(0.002 * 2.0 * TS)


def test_the_slave_drifts_to_the_handle_for_free_in_free_space() -> None:
    """With no environment force the tool's step costs nothing at the port (-ft . d = 0): it
    moves the gap (Ah1 yh - yt) times rate Ts, capped at the speed limit, from an empty
    account; no handle position (NaN), a zero rate or a port switched off, no step."""
    p = port(3, slave_drift_rate_per_s=2.0, slave_drift_speed_max_m_per_s=0.005)
    gap = np.array([[0.001, -0.002], [0.5, 0.0], [np.nan, 0.0]])
    step = p.drift_shift(gap, np.zeros((3, 2)))
    np.testing.assert_allclose(step[0], gap[0] * 2.0 * TS, rtol=1e-12)
    np.testing.assert_allclose(step[1], [0.005 * TS, 0.0], rtol=1e-12)  # capped
    assert step[2].tolist() == [0.0, 0.0]
    off = port(1, slave_drift_rate_per_s=0.0)
    assert off.drift_shift(gap[:1], np.zeros((1, 2))).tolist() == [[0.0, 0.0]]
    standby = port(1)
    standby.active[:] = False
    assert standby.drift_shift(gap[:1], np.zeros((1, 2))).tolist() == [[0.0, 0.0]]


def test_the_slave_drift_against_the_environment_is_paid_from_the_account() -> None:
    """Where the environment pushes the tool (ft, the force on the environment, points the
    other way) the step is the environment's release and always taken; against the
    environment its work on it (ft . d) is at most what the account holds: none from an empty
    one, all of it once the account pays."""
    p = port(2, slave_drift_rate_per_s=2.0)
    gap = np.array([[-0.002, 0.0], [0.002, 0.0]])  # both tools should move by the gap
    force = np.array([[1.0, 0.0], [1.0, 0.0]])  # a spring at +x: it pushes the tools to -x
    step = p.drift_shift(gap, force)
    assert step[0, 0] == pytest.approx(-0.002 * 2.0 * TS)  # with the environment: free
    assert step[1, 0] == 0.0  # into the spring with nothing to pay
    p.receive(np.array([1e-9, 1e-9]))
    part = p.drift_shift(gap, force)
    assert np.dot(force[1], part[1]) == pytest.approx(1e-9)
    p.receive(np.array([1.0, 1.0]))
    assert p.drift_shift(gap, force)[1, 0] == pytest.approx(0.002 * 2.0 * TS)


def test_both_sides_close_a_gap_the_controllers_left_in_lockstep() -> None:
    """The sweep's worst tdpa cell of the last round (k = 19, 0.2 s round trip, 20 % loss in
    bursts): after the 1 N pulse the TDPA controllers leave the handle and the tool on either
    side of their start, at rest in force balance. The master's drift alone closes that only
    at the loop's slow pace, because the force loop pulls the handle back to the balance
    (this seed: 0.94 mm left after 8 s, 2.8 mm with neither drift); with the slave's drift as
    well both sides meet (0.012 mm)."""
    from haptic.common.config import load_config
    from haptic.common.config.scenario import load_scenario
    from haptic.common.model.teleop import model_from_config
    from haptic.lockstep.simulator import LockstepSimulator
    from haptic.lockstep.sweep import SweepSettings, sweep_injection
    from haptic.master.simulated_rig.operator import parse_operator_spec

    model = model_from_config(load_config(None))
    delay = int(round(0.2 / model.sample_period_s))
    injection = sweep_injection(SweepSettings(gains_k=(19.0,), delays_s=(0.2,),
                                                loss_probability=0.2, bursty=True))
    gaps = {}
    for name, rate in (("both", 2.0), ("master only", 0.0)):
        sim = LockstepSimulator(model, load_scenario("constant-rate"),
                                parse_operator_spec("constant:fx=0,fy=0"), np.array([19.0]),
                                "linear", device="cpu",
                                passivity=PassivitySettings(slave_drift_rate_per_s=rate))
        result = sim.run(8.0, delay, to_slave=injection, to_master=injection, seed=4,
                         excitation_N=np.full((20, 2), 1.0))
        assert np.isfinite(result.peak_handle_force_N).all()
        gaps[name] = float(np.linalg.norm(result.final_position_gap_m[0]))
    assert gaps["both"] <= 0.1e-3, gaps
    assert gaps["master only"] > 0.5e-3, gaps


def test_two_port_passivity_in_a_delayed_lockstep_run() -> None:
    """The linear loop at k = 13 and 0.1 s round trip grows in the paper's scheme and stays
    bounded with TDPA, and the sum of the ports' output never exceeds their input by more
    than the deficits the floors leave (a few millijoules)."""
    from haptic.common.config import load_config
    from haptic.common.config.scenario import load_scenario
    from haptic.common.model.teleop import model_from_config
    from haptic.lockstep.simulator import LockstepSimulator
    from haptic.master.simulated_rig.operator import parse_operator_spec

    model = model_from_config(load_config(None))
    delay = int(round(0.1 / model.sample_period_s))
    peaks = {}
    for control, settings in (("paper", None), ("tdpa", PassivitySettings())):
        sim = LockstepSimulator(model, load_scenario("constant-rate"),
                                parse_operator_spec("constant:fx=0,fy=0"), np.array([13.0]),
                                "linear", device="cpu", passivity=settings)
        result = sim.run(1.5, delay, excitation_N=np.full((20, 2), 1.0))
        peaks[control] = float(np.nan_to_num(result.peak_handle_force_N, nan=np.inf).max())
        if settings is not None:
            master, slave = sim.final_states[0].passivity, sim.final_states[1].passivity
            output = master.output_energy_J + slave.output_energy_J
            inputs = master.input_energy_J + slave.input_energy_J
            assert np.all(output <= inputs + 0.005)
            assert np.all(np.abs(result.final_position_gap_m) < 0.002)
    assert peaks["paper"] > 10.0
    assert peaks["tdpa"] <= 1.5


def test_the_shipped_limits_are_the_configurations_and_frozen() -> None:
    """The code's defaults and the shipped ``[control]`` limits are one set of values (a
    changed default would otherwise pass every test that builds its own settings)."""
    import dataclasses

    from haptic.common.config import load_config
    from haptic.common.config.control_schema import standby_passivity_settings

    shipped = PassivitySettings()
    assert standby_passivity_settings(load_config()) == shipped
    assert dataclasses.astuple(shipped) == (
        0.002, 0.05, 0.2, 200.0, 0.5, 0.002, 0.002, 1e-5, 2000.0, 40.0, 4000.0, 200.0, 2.0,
        2.0, 0.01, 2.0, 0.01)
    with pytest.raises(dataclasses.FrozenInstanceError):
        shipped.credit_max_J = 1e9  # type: ignore[misc]
