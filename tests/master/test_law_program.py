"""The safety layer around the master's lane law (master/law_program.py ``LawMasterGuard``):
the operator's force as the law gets it, the faults that latch the safe state, and the handle
command the drives are given."""

from __future__ import annotations

import numpy as np

from haptic.common.config import load_config
from haptic.common.config.scenario import load_scenario
from haptic.common.model.work_area import work_area_from_config
from haptic.master.hardware.interface import HandleReading
from haptic.master.law_program import COMMAND_WINDOW_M, LawMasterGuard
from haptic.master.settings import master_settings

PERIOD_S = 0.00054


def _guard() -> LawMasterGuard:
    config = load_config(None)
    grid = load_scenario("constant-rate").grid
    return LawMasterGuard(master_settings(config).safety,
                          work_area_from_config(config, grid.x_range_m, grid.y_range_m))


def _reading(force_N, position_m=(0.0, 0.0), faults=()) -> HandleReading:
    return HandleReading(np.array(force_N, float), np.array(position_m, float), 1,
                         list(faults))


def test_the_operator_force_reaches_the_law_finite_and_clamped() -> None:
    guard = _guard()
    limit = guard.safety.force_limit_N
    force = guard.operator_force_N(np.array([np.nan, 10.0 * limit]))
    assert force.shape == (1, 2)
    assert force[0, 0] == 0.0 and force[0, 1] == limit


def test_a_force_above_the_trip_or_a_hardware_fault_latches_with_a_reason() -> None:
    guard = _guard()
    trip = guard.safety.force_trip_N
    assert guard.trip_reason(_reading([0.5 * trip, 0.0])) is None
    assert "above the trip" in guard.trip_reason(_reading([0.0, -1.01 * trip]))
    assert "hardware fault: x drive EMCY" in guard.trip_reason(
        _reading([0.0, 0.0], faults=["x drive EMCY"]))
    assert guard.trip_reason(_reading([np.nan, 0.0])) is None  # a missed PDO holds, no trip


def test_the_command_is_rate_limited_kept_near_the_handle_and_in_the_work_area() -> None:
    guard = _guard()
    step = guard.safety.velocity_limit_m_per_s * PERIOD_S
    here = np.array([0.05, 0.0])
    # a law's position far ahead: one rate-limited step from the previous command
    command = guard.command(here + 0.1, here, here, PERIOD_S)
    np.testing.assert_allclose(command, here + step)
    # a previous command already ahead of a lagging handle: held within the window
    command = guard.command(here + 0.1, here + 0.02, here, PERIOD_S)
    np.testing.assert_allclose(command, here + COMMAND_WINDOW_M)
    # the work area's box wins over both
    high = np.array(guard.area.handle_high_m)
    command = guard.command(high + 0.01, high, high, PERIOD_S)
    np.testing.assert_allclose(command, high)
