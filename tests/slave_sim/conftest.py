"""Shared helpers of the slave simulator tests."""

from __future__ import annotations

import numpy as np
import pytest

from haptic.common.config.scenario import Scenario, load_scenario

SAMPLE_PERIOD_S = 0.00054


@pytest.fixture(scope="session")
def variable_rate() -> Scenario:
    """The variable-rate staircase on a 512 x 128 grid (0.39 mm cells): fast and accurate."""
    return load_scenario("variable-rate").with_grid(512, 128)


def _drive(clay, state, start_xy, velocity_xy, steps: int,
           sample_period_s: float = SAMPLE_PERIOD_S):
    """Move every lane's tool at constant velocity from ``start_xy`` for ``steps`` steps;
    returns positions (steps, lanes, 2) and the per-step results."""
    velocity = np.asarray(velocity_xy, float)
    position = np.array(start_xy, float)
    positions, results = [], []
    for _ in range(steps):
        previous = position
        position = previous + velocity * sample_period_s
        results.append(clay.step(state, previous, position, velocity))
        positions.append(position)
    return np.array(positions), results


@pytest.fixture(scope="session")
def drive():
    """The constant-velocity driver: ``drive(clay, state, start_xy, velocity_xy, steps)``."""
    return _drive
