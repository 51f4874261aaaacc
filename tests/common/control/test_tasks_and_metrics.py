"""The benchmark's task environments (common/control/tasks.py) and metrics
(common/control/metrics.py) on hand-made signals whose figures are known."""

from __future__ import annotations

import numpy as np
import pytest

from haptic.common.control.metrics import (
    final_position_gap_m,
    impact_overshoot_ratio,
    perceived_stiffness_ratio,
    rms_force_error_N,
    rms_position_error_m,
)
from haptic.common.control.tasks import StiffWall, free_motion_sine


def test_the_wall_pushes_back_inside_and_never_pulls() -> None:
    wall = StiffWall(surface_m=0.01, stiffness_N_per_m=5000.0, damping_N_s_per_m=10.0)
    position = np.array([[0.005, 0.0], [0.012, 0.3], [0.012, 0.0], [0.012, 0.0],
                         [np.nan, 0.0]])
    velocity = np.array([[1.0, 0.0], [0.0, 0.0], [0.05, 0.0], [-2.0, 0.0], [0.0, 0.0]])
    force = wall.force_N(position, velocity)
    assert force[:, 1].tolist() == [0.0] * 5  # along the normal only
    assert force[0, 0] == 0.0  # outside
    assert force[1, 0] == pytest.approx(-10.0)  # 2 mm in: -k p
    assert force[2, 0] == pytest.approx(-10.5)  # moving in: the damper adds
    assert force[3, 0] == 0.0  # leaving fast: it would pull, so nothing
    assert force[4, 0] == 0.0  # no position: no force
    assert wall.penetration_m(position).tolist() == pytest.approx([0.0, 0.002, 0.002, 0.002,
                                                                   0.0])


def test_a_wall_on_the_other_side_pushes_the_other_way() -> None:
    wall = StiffWall(surface_m=-0.01, stiffness_N_per_m=1000.0, axis=1, side=-1.0)
    force = wall.force_N(np.array([[0.0, -0.013]]), np.zeros((1, 2)))
    assert force[0].tolist() == pytest.approx([0.0, 3.0])


def test_the_sine_reference_is_a_sine_and_its_derivative() -> None:
    t = np.arange(0.0, 2.0, 0.001)
    position, velocity = free_motion_sine(t, 0.02, 0.5, axis=1, centre_m=(0.1, 0.0))
    assert np.all(position[:, 0] == 0.1) and np.all(velocity[:, 0] == 0.0)
    assert position[:, 1].max() == pytest.approx(0.02, rel=1e-5)
    np.testing.assert_allclose(np.gradient(position[:, 1], t)[1:-1], velocity[1:-1, 1],
                               atol=1e-6)


def test_rms_errors_of_known_signals() -> None:
    t = np.linspace(0.0, 1.0, 1000, endpoint=False)
    master = np.stack([np.sin(2 * np.pi * 3 * t), np.zeros_like(t)], axis=1)
    slave = master - np.array([0.003, 0.004])  # a constant 5 mm offset
    assert rms_position_error_m(master, slave) == pytest.approx(0.005)
    assert rms_position_error_m(master[:, 0], master[:, 0] + 0.002 * np.sin(
        2 * np.pi * 5 * t)) == pytest.approx(0.002 / np.sqrt(2.0))
    assert rms_force_error_N(np.full(10, 3.0), np.full(10, 1.0)) == pytest.approx(2.0)
    assert np.isnan(rms_force_error_N(np.array([1.0, np.nan]), np.zeros(2)))


def test_the_final_gap_is_the_distance_at_the_end() -> None:
    master = np.zeros((5, 2))
    slave = np.zeros((5, 2))
    slave[-1] = [0.003, 0.004]
    slave[-2] = [0.001, 0.0]
    assert final_position_gap_m(master, slave) == pytest.approx(0.005)
    assert final_position_gap_m(master, slave, final_samples=2) == pytest.approx(
        np.hypot(0.002, 0.002))


def test_the_overshoot_of_a_known_impact() -> None:
    force = np.concatenate([np.linspace(0.0, 3.0, 10), np.full(90, 2.0)])  # peak 3, settles 2
    assert impact_overshoot_ratio(force) == pytest.approx(0.5)
    assert impact_overshoot_ratio(np.full(50, 2.0)) == pytest.approx(0.0)
    assert np.isnan(impact_overshoot_ratio(np.zeros(20)))


def test_the_perceived_stiffness_is_the_slope_in_contact_over_the_wall() -> None:
    rng = np.random.default_rng(5)
    position = 0.01 + rng.uniform(-0.002, 0.003, 500)
    contact = position > 0.01
    force = np.where(contact, 0.8 * 4000.0 * (position - 0.01) + 0.3, 0.0)
    assert perceived_stiffness_ratio(position, force, 4000.0, contact) == pytest.approx(0.8)
    assert np.isnan(perceived_stiffness_ratio(position, force, 4000.0, np.zeros(500, bool)))
