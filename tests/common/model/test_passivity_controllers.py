"""The TDPA controllers' arithmetic at exact values (common/model/passivity.py): the master's
conductance (each of its limits binding in a lane of its own), the drift steps on both sides
and how they are paid, the slave's damper and drift spring, and the master's whole passivity
step (``master_step_reference``, the numpy reference of the master's kernel).

Each test puts one case per lane and states the expected value from the rule in the
docstrings, computed here in scalar Python; tests/common/model/test_passivity.py tests the physics
(exactly the excess dissipated, no energy created) over runs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from haptic.common.model.passivity import PassivityPort, PassivitySettings, master_step_reference

#: A binary period, s, so that ties below are exact in floating point.
TS = 2.0 ** -11


def port(lanes: int, **changes: float) -> PassivityPort:
    return PassivityPort.create(PassivitySettings(**changes), TS, lanes)


def exact(values: np.ndarray, expected: list) -> None:
    np.testing.assert_allclose(values, np.asarray(expected, float), rtol=1e-12, atol=0.0)


def test_the_conductance_takes_the_smallest_of_its_limits_lane_by_lane() -> None:
    """``|d|`` = min(excess / |f|, conductance |f| Ts, speed Ts, last |d| + accel Ts^2), 0
    below the force floor, on a switched-off lane or where the account covers the step."""
    s = PassivitySettings()
    p = port(11)
    rise = s.correction_accel_max_m_per_s2 * TS * TS
    force = np.array([[3.0, 4.0], [1.0, 0.0], [0.0, 10.0], [0.0, 10.0], [0.0015, 0.0],
                      [0.002, 0.0], [1.0, 0.0], [1.0, 0.0], [1.0, 0.0], [0.0, 0.0],
                      [0.3, 0.4]])
    work_out = np.array([1e-4, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 0.5, 0.25 + 2.0 ** -19, 1.0,
                         1e-6])
    p.correction_m[2] = 1.0  # the rise limit far off: the speed limit binds
    p.correction_m[3] = 1e-5  # the rise counts from the last correction
    p.active[6] = False
    p.tank_J[7] = 1.0  # the account covers the step
    p.tank_J[8] = 0.25  # it covers all but 2^-19 J
    # the step against the push whose work out is work_out: -f . step = work_out
    norm2 = np.einsum("ij,ij->i", force, force)
    step = -force * (work_out / np.maximum(norm2, 1e-300))[:, None]
    step[9] = [-1.0, 0.0]
    correction = p.yield_command(force, step)
    size = [min(1e-4 / 5.0, 0.05 * 5.0 * TS, rise),  # the excess binds
            0.05 * 1.0 * TS,  # the conductance binds
            0.2 * TS,  # the speed binds
            1e-5 + rise,  # the rise binds
            0.0,  # below the force floor
            0.05 * 0.002 * TS,  # at the floor exactly: it acts
            0.0, 0.0, 2.0 ** -19, 0.0,
            1e-6 / 0.5]  # the excess binds below 1 N
    assert size[0] == 1e-4 / 5.0
    exact(p.correction_m, size)
    direction = force / np.sqrt(np.maximum(norm2, 1e-300))[:, None]
    exact(correction, np.asarray(size)[:, None] * direction)
    assert np.isfinite(correction).all() and correction[9].tolist() == [0.0, 0.0]
    assert p.active_steps.tolist() == [1, 1, 1, 1, 0, 1, 0, 0, 1, 0, 1]
    exact(p.dissipated_energy_J, np.asarray(size) * np.sqrt(norm2))
    # the work of the correction at the port is what the account lacked (lane 0, 8)
    assert float(force[0] @ correction[0]) == pytest.approx(1e-4, rel=1e-12)
    assert float(force[8] @ correction[8]) == 2.0 ** -19
    p.correction_m[...] = 0.0
    along = p.yield_command(force[:1].repeat(11, 0), -step[:1].repeat(11, 0))
    assert not along.any()  # a step along the push gives nothing out


def test_the_drift_step_is_the_gap_times_rate_capped_at_the_speed() -> None:
    """``gap rate Ts``, shortened to ``speed Ts`` along the gap; a gap with any non-finite
    coordinate, none."""
    p = port(5, master_drift_rate_per_s=4.0, master_drift_speed_max_m_per_s=0.5)
    most = 0.5 * TS
    target = np.array([[3e-3, -4e-3], [30.0, 40.0], [np.nan, 1.0], [1.0, np.inf],
                       [0.0, 0.0]])
    step = p.drift_command(np.zeros((5, 2)), np.zeros((5, 2)), target)
    exact(step[0], [3e-3 * 4.0 * TS, -4e-3 * 4.0 * TS])
    exact(step[1], [0.6 * most, 0.8 * most])
    assert step[2:].tolist() == [[0.0, 0.0]] * 3
    assert p.correction_m.tolist() == [0.0] * 5  # drift is not the conductance
    slow = port(1, master_drift_rate_per_s=0.5)
    exact(slow.drift_command(np.zeros((1, 2)), np.zeros((1, 2)), np.array([[2e-3, 0.0]])),
          [[2e-3 * 0.5 * TS, 0.0]])  # any rate above 0 acts
    one = port(1, master_drift_rate_per_s=4.0, master_drift_speed_max_m_per_s=0.5)
    relative = one.drift_command(np.zeros((1, 2)), np.array([[1e-3, 2e-3]]),
                                 np.array([[2e-3, 1e-3]]))  # the gap from the command
    exact(relative[0], [1e-3 * 4.0 * TS, -1e-3 * 4.0 * TS])


def test_the_master_drift_is_paid_from_the_account_and_this_steps_other_work() -> None:
    """Against the push (``fh . d`` < 0) the step is paid from ``max(account + fh . (command -
    previous), 0)``: whole within it, scaled to it beyond, nothing from a debt; along the
    push it is free; a switched-off lane takes none."""
    p = port(7, master_drift_rate_per_s=4.0, master_drift_speed_max_m_per_s=1.0)
    force = np.array([[1.0, 0.0], [-1.0, 0.0], [-1.0, 0.0], [-1.0, 0.0], [-1.0, 0.0],
                      [-2.0, 0.0], [1.0, 0.0]])
    target = np.full((7, 2), 0.0)
    target[:, 0] = 2.0 ** -8
    full = 2.0 ** -8 * 4.0 * TS  # the whole step, m: its work against the push is -f full
    command = np.zeros((7, 2))
    p.tank_J[:] = [0.0, 0.0, full / 4, -1.0, full / 4, 0.0, 0.0]
    p.previous_position_m[3] = [0.0, 0.0]
    p.previous_position_m[4] = [full / 4, 0.0]  # this step's command went -full/4: paid in
    p.previous_position_m[5] = [-full / 2, 0.0]  # it went +full/2 against the push: a debt
    p.tank_J[5] = 2.0 * full  # which the account pays first: the rest pays the drift
    p.active[6] = False
    step = p.drift_command(force, command, target)
    expected = [full,  # along the push: free
                0.0,  # against it, nothing to pay with
                full / 4,  # a quarter of the work paid
                0.0,  # a debt pays nothing (and never reverses the step)
                full / 2,  # the account's quarter and the command's quarter
                full / 2,  # 2 full - 2 (full / 2) = full of budget for 2 full of work
                0.0]
    exact(step[:, 0], expected)
    assert step[:, 1].tolist() == [0.0] * 7


def test_a_partly_paid_step_is_scaled_by_the_budget_over_its_work() -> None:
    """The scale is ``budget / -work`` even where the work is far below 1 J (no floor
    distorts it)."""
    p = port(2, slave_drift_rate_per_s=4.0, slave_drift_speed_max_m_per_s=1.0)
    gap = np.array([[2.0 ** -8, 0.0], [2.0 ** -8, 0.0]])
    full = 2.0 ** -8 * 4.0 * TS
    force = np.array([[3.0, 0.0], [3.0, 0.0]])  # the tool pushes +x into its environment
    p.tank_J[:] = [3.0 * full / 8, 3.0 * full * 0.75]
    step = p.drift_shift(gap, force)
    exact(step[:, 0], [full / 8, full * 0.75])


def test_the_slave_drift_is_paid_from_the_account_only() -> None:
    """``-ft . d`` >= 0 (the environment's release) is free; into the environment the step
    is paid from ``max(account, 0)``; a non-finite force counts as none."""
    p = port(5, slave_drift_rate_per_s=4.0, slave_drift_speed_max_m_per_s=1.0)
    full = 2.0 ** -8 * 4.0 * TS
    gap = np.array([[-(2.0 ** -8), 0.0], [2.0 ** -8, 0.0], [2.0 ** -8, 0.0],
                    [2.0 ** -8, 0.0], [2.0 ** -8, 0.0]])
    force = np.array([[1.0, 0.0], [1.0, 0.0], [1.0, 0.0], [np.nan, 5.0], [1.0, 0.0]])
    p.tank_J[:] = [0.0, full / 2, -1.0, 0.0, 10.0]
    p.active[4] = False
    step = p.drift_shift(gap, force)
    exact(step[:, 0], [-full, full / 2, 0.0, full, 0.0])
    assert step[:, 1].tolist() == [0.0] * 5


def test_the_damper_takes_the_smallest_of_its_limits_lane_by_lane() -> None:
    """``alpha`` = excess / (Ts |v|^2), capped at ``damper_max``; its force ``alpha |v|`` at
    most ``damper_force_max`` and the last force + ``rate`` Ts; nothing below the velocity
    floor (acting at it exactly), on a switched-off lane or where the account covers it."""
    s = PassivitySettings(damper_max_N_s_per_m=100.0, damper_force_max_N=8.0,
                          damper_force_rate_N_per_s=4000.0, velocity_floor_m_per_s=2.0 ** -10)
    p = PassivityPort.create(s, TS, 10)
    rate = 4000.0 * TS  # 1.953125 N a step
    velocity = np.array([[0.6, 0.8], [0.05, 0.0], [0.5, 0.0], [0.5, 0.0], [0.25, 0.0],
                         [2.0 ** -11, 0.0], [2.0 ** -10, 0.0], [0.5, 0.0], [0.5, 0.0],
                         [0.5, 0.0]])
    port_force = np.array([[3.0, 4.0], [1e3, 0.0], [1e3, 0.0], [1e4, 0.0], [1e3, 0.0],
                           [1e3, 0.0], [1e3, 0.0], [1e3, 0.0], [4.0, 0.0], [0.25, 0.0]])
    p.damper_force_N[:] = [5.0, 10.0, 10.0, 5.0, 0.0, 3.0, 0.0, 3.0, 3.0, 0.0]
    p.active[7] = False
    p.tank_J[0] = 1.25 * TS  # a quarter of the step's work out, ft . v Ts = 5 Ts
    p.tank_J[8] = 2.0 * TS  # all of it
    actuator = np.tile([1.0, -1.0], (10, 1))
    out = p.damp(actuator, velocity, port_force)
    speed = np.hypot(velocity[:, 0], velocity[:, 1])
    magnitude = [3.75,  # the excess binds: alpha = 3.75 Ts / (Ts 1 m^2/s^2)
                 100.0 * 0.05,  # alpha capped
                 8.0,  # the force capped (alpha capped: 50 N)
                 5.0 + rate,  # the rise from the last force binds
                 rate,  # from none
                 0.0,  # below the floor
                 100.0 * 2.0 ** -10,  # at the floor exactly: it acts
                 0.0,  # switched off
                 0.0,  # the account covers the step
                 0.25]  # alpha = 0.125 Ts / (Ts 0.25) = 0.5 N s/m: the excess binds
    exact(p.damper_force_N, magnitude)
    alpha = np.asarray(magnitude) / speed
    exact(out, actuator - alpha[:, None] * velocity)
    for lane in (5, 7, 8):
        assert out[lane].tolist() == [1.0, -1.0]
    assert p.active_steps.tolist() == [1, 1, 1, 1, 1, 0, 1, 0, 0, 1]
    exact(p.dissipated_energy_J, alpha * speed ** 2 * TS)
    assert p.dissipated_energy_J[0] == pytest.approx(3.75 * TS, rel=1e-12)  # the excess


def test_the_drift_spring_is_capped_and_paid_beyond_the_steps_own_work() -> None:
    """``F = k gap`` at most ``drift_force_max``; where it drives the tool (``F . v Ts`` >
    0) it is paid from ``max(account - max(ft . v Ts, 0), 0)``, scaled to it beyond; braking
    is free; a non-finite gap pulls with nothing; a switched-off lane gets none."""
    p = port(8, drift_stiffness_N_per_m=100.0, drift_force_max_N=2.0)
    gap = np.array([[3e-3, -4e-3], [0.03, 0.04], [0.01, 0.0], [0.01, 0.0], [0.01, 0.0],
                    [0.01, 0.0], [np.nan, 0.0], [0.01, 0.0]])
    velocity = np.array([[-1.0, 1.0], [0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [1.0, 0.0],
                         [1.0, 0.0], [1.0, 0.0], [-1.0, 0.0]])
    port_force = np.zeros((8, 2))
    port_force[4] = [0.25, 0.0]  # the step's own work out, ft . v Ts = 0.25 Ts: paid first
    port_force[5] = [-5.0, 0.0]  # its own work in: not a budget
    p.tank_J[:] = [0.0, 0.0, 0.0, 0.5 * TS, 0.75 * TS, 0.5 * TS, 0.0, 0.0]
    p.active[7] = False
    force = p.drift_force(gap, velocity, port_force)
    exact(force, [[0.3, -0.4],  # braking, under the cap
                  [1.2, 1.6],  # capped at 2 N along the gap
                  [0.0, 0.0],  # driving, nothing to pay with
                  [0.5, 0.0],  # driving: 1 N Ts of work, half paid
                  [0.5, 0.0],  # 0.75 Ts - 0.25 Ts of budget
                  [0.5, 0.0],  # the own input adds nothing
                  [0.0, 0.0],  # no gap
                  [0.0, 0.0]])  # switched off
    assert p.tank_J[3] == 0.5 * TS  # paying is the observer's business, not the spring's
    small = port(1, drift_stiffness_N_per_m=100.0, drift_force_max_N=0.5)
    exact(small.drift_force(np.array([[4.8e-3, 6.4e-3]]), np.zeros((1, 2)), np.zeros((1, 2))),
          [[0.3, 0.4]])  # 0.8 N capped at 0.5 N along the gap


def test_the_masters_passivity_step_composes_yield_drift_limits_and_observer() -> None:
    """In place: the force read from the inputs (NaN as 0, clipped to the limit), the
    command yields and drifts (none on a faulted lane, no drift where forces are not
    enabled), is clipped to the work area, the offset and the last command follow it, and
    the port observes ``fh . (command - previous)`` and remembers the command."""
    lanes = 6
    p = port(lanes, master_drift_rate_per_s=4.0, master_drift_speed_max_m_per_s=1.0)
    full = 2.0 ** -8 * 4.0 * TS
    inputs = np.zeros((lanes, 6))
    inputs[:, 0:2] = [[np.nan, 0.0], [-50.0, 0.0], [0.0, 0.0], [-1.0, 0.0], [0.0, 0.0],
                      [1.0, 0.0]]
    command = np.zeros((lanes, 2))
    previous = 0.05 - 1e-5
    p.previous_position_m[3] = [previous, 0.0]
    command[3] = [0.05, 0.0]  # the kernel's command went 10 um against the push: it yields
    command[4] = [0.2, 0.0]  # beyond the work area
    command[5] = [-1e-5, 0.0]  # against the push, then a drift along it
    last = np.full((lanes, 2), 0.001)
    origin = np.full((lanes, 2), 0.01)
    target = np.zeros((lanes, 2))
    target[:, 0] = 2.0 ** -8
    target[3] = np.nan
    faulted = np.array([False, False, True, False, False, False])
    enabled = np.array([True, True, True, True, False, True])
    p.tank_J[1] = 10.0 * full  # pays the drift against the -10 N push
    master_step_reference(p, inputs, command, last, origin, faulted, 10.0,
                          np.array([-0.1, -0.1]), np.array([0.1, 0.1]), target, enabled)
    yielded3 = 0.05 - previous  # what the step gave out against the push: the excess binds
    yielded5 = 1e-5
    assert yielded3 < 0.05 * TS and yielded5 < 0.05 * TS  # under the conductance's cap
    drifted5 = -1e-5 + yielded5  # the command after the yield, which the drift starts from
    drifted5 += (2.0 ** -8 - drifted5) * 4.0 * TS
    moved = np.array([[full, 0.0], [full, 0.0], [0.0, 0.0], [0.05 - yielded3, 0.0],
                      [0.1, 0.0], [drifted5, 0.0]])
    exact(command, moved)
    exact(last, moved)
    exact(origin, 0.01 + moved - 0.001)
    exact(p.previous_position_m, moved)
    work = np.array([0.0, -10.0 * full, 0.0, -1.0 * (moved[3, 0] - previous), 0.0, drifted5])
    np.testing.assert_allclose(p.input_energy_J, np.maximum(work, 0.0), rtol=1e-12,
                               atol=1e-18)
    np.testing.assert_allclose(p.output_energy_J, np.maximum(-work, 0.0), rtol=1e-12,
                               atol=1e-18)
    exact(p.correction_m, [0.0, 0.0, 0.0, yielded3, 0.0, yielded5])
    # without a target, no drift: the command stays where the kernel put it
    q = port(1)
    command = np.array([[0.002, 0.0]])
    master_step_reference(q, np.zeros((1, 6)), command, np.zeros((1, 2)), np.zeros((1, 2)),
                          np.array([False]), 10.0, np.array([-0.1, -0.1]),
                          np.array([0.1, 0.1]))
    assert command.tolist() == [[0.002, 0.0]]
    assert q.previous_position_m.tolist() == [[0.002, 0.0]]
    # a target and no enabled mask: every lane drifts
    r = port(1, master_drift_rate_per_s=4.0, master_drift_speed_max_m_per_s=1.0)
    command = np.zeros((1, 2))
    master_step_reference(r, np.zeros((1, 6)), command, np.zeros((1, 2)), np.zeros((1, 2)),
                          np.array([False]), 10.0, np.array([-0.1, -0.1]),
                          np.array([0.1, 0.1]), np.array([[2.0 ** -8, 0.0]]))
    exact(command, [[full, 0.0]])
    assert math.isfinite(float(r.tank_J[0]))
