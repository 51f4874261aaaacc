"""The master's tool-input guard at its edges (master/tool_guard.py): every bound exactly at,
just inside and just beyond, on each axis and sign, the fault latch's count, the events'
words and the summary; the twin of tests/slave_sim/test_input_guard_limits.py."""

from __future__ import annotations

import dataclasses
import math

import pytest

from haptic.common.config import ConfigError, load_config
from haptic.common.wire.messages import Flags, ToolState
from haptic.master.tool_guard import ToolGuardSettings, ToolInputGuard

PERIOD_S = 0.0005
PERIOD_NS = 500_000
SETTINGS = ToolGuardSettings(force_trip_N=50.0, position_min_m=(-0.25, -0.125),
                             position_max_m=(0.25, 0.125), velocity_trip_m_per_s=2.0,
                             jump_margin_m=0.001, clear_after_messages=4)
TINY = 1e-9


def msg(seq: int, force=(0.0, 0.0), position=(0.0, 0.0), epoch: int = 3) -> ToolState:
    return ToolState(epoch, seq, seq * PERIOD_NS, Flags.FORCES_ENABLED, force, position,
                     (0.0, 0.0), 0.0, 0.0)


def primed(position=(0.0, 0.0)) -> ToolInputGuard:
    guard = ToolInputGuard(SETTINGS, PERIOD_S)
    assert guard.admit(msg(0, position=position), 0.0)
    return guard


def test_the_shipped_defaults_are_the_configurations_and_frozen() -> None:
    shipped = ToolGuardSettings()
    assert shipped == ToolGuardSettings.from_config(load_config())
    assert ToolGuardSettings.from_config({}) == shipped  # no [master.tool_input]: these
    assert dataclasses.astuple(shipped) == (200.0, (-0.5, -0.5), (0.5, 0.5), 2.0, 0.002, 20,
                                            0.005)
    with pytest.raises(dataclasses.FrozenInstanceError):
        shipped.force_trip_N = 1e9  # type: ignore[misc]


@pytest.mark.parametrize("axis", [0, 1])
def test_an_empty_box_on_either_axis_is_refused_and_lists_become_tuples(axis) -> None:
    low, high = [-0.1, -0.1], [0.1, 0.1]
    low[axis] = high[axis]
    table = {"position_min_m": low, "position_max_m": high}
    with pytest.raises(ConfigError, match="master.tool_input.position_max_m"):
        ToolGuardSettings.from_config({"master": {"tool_input": table}})
    low[axis] = high[axis] - 1e-6
    settings = ToolGuardSettings.from_config({"master": {"tool_input": table}})
    assert settings.position_min_m == tuple(low) and settings.position_max_m == (0.1, 0.1)


@pytest.mark.parametrize("where", ["fx", "fy", "px", "py"])
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_any_non_finite_value_is_a_fault(where, bad) -> None:
    guard = primed()
    force, position = [0.0, 0.0], [0.0, 0.0]
    (force if where[0] == "f" else position)[0 if where[1] == "x" else 1] = bad
    assert not guard.admit(msg(1, tuple(force), tuple(position)), PERIOD_S)
    assert guard.faulted and guard.counters.non_finite == 1 and guard.counters.faults == 1
    assert guard.events[-1] == {"time_s": PERIOD_S, "kind": "tool_input_fault",
                                "reason": "non-finite tool force or position"}
    assert guard.position_m == (0.0, 0.0)


@pytest.mark.parametrize("axis", [0, 1])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_the_force_trip_is_exclusive_on_each_axis_and_sign(axis, sign) -> None:
    guard = primed()
    force = [0.0, 0.0]
    force[axis] = sign * 50.0
    assert guard.admit(msg(1, tuple(force)), PERIOD_S) and not guard.faulted
    force[axis] = sign * (50.0 + 1e-6)
    assert not guard.admit(msg(2, tuple(force)), 2 * PERIOD_S)
    assert guard.counters.faults == 1 and guard.counters.jumps == 0
    shown = [0, 0]
    shown[axis] = int(sign * 50)
    assert guard.events[-1]["reason"] == (f"tool force ({shown[0]}, {shown[1]}) N beyond "
                                          "+-50 N")


@pytest.mark.parametrize("axis, edge", [(0, -0.25), (0, 0.25), (1, -0.125), (1, 0.125)])
def test_the_plausible_box_includes_its_edges(axis, edge) -> None:
    """A first message (no jump check) exactly on each edge is an input; just beyond it, a
    fault."""
    guard = ToolInputGuard(SETTINGS, PERIOD_S)
    position = [0.0, 0.0]
    position[axis] = edge
    assert guard.admit(msg(0, position=tuple(position)), 0.0)
    outside = ToolInputGuard(SETTINGS, PERIOD_S)
    position[axis] = edge * (1 + 1e-9)
    assert not outside.admit(msg(0, position=tuple(position)), 0.0)
    assert outside.events[-1]["reason"].endswith("m outside the plausible box")
    assert outside.position_m is None


@pytest.mark.parametrize("axis", [0, 1])
@pytest.mark.parametrize("sign", [1.0, -1.0])
@pytest.mark.parametrize("periods", [1, 3])
def test_a_jump_up_to_speed_times_time_plus_margin_is_plausible(axis, sign, periods) -> None:
    start = (0.01, -0.02)
    allowed_m = 2.0 * (periods * PERIOD_NS * 1e-9) + 0.001
    position = list(start)
    position[axis] = start[axis] + sign * allowed_m
    guard = primed(start)
    assert guard.admit(msg(periods, position=tuple(position)), periods * PERIOD_S)
    assert not guard.faulted
    position[axis] = start[axis] + sign * (allowed_m + TINY)
    guard = primed(start)
    assert not guard.admit(msg(periods, position=tuple(position)), periods * PERIOD_S)
    assert guard.counters.jumps == 1 and guard.position_m == start


def test_the_jump_is_measured_from_the_previous_position_on_each_axis() -> None:
    """A tool resting at y = 0.1 m stays there: no jump (measured as the difference, on each
    axis), and the event names the jump, the time and the bound."""
    guard = primed((0.1, 0.1))
    assert guard.admit(msg(1, position=(0.1, 0.1)), PERIOD_S)
    assert guard.admit(msg(2, position=(-0.0, 0.1)), 2 * PERIOD_S) is False
    assert guard.events[-1]["reason"] == ("tool position jumped 100 mm in 0.5 ms (the tool "
                                          "moves at most 2 mm)")
    # 4.495 ms later by both clocks, 99.9 mm: at most 2 m/s x 4.495 ms + 1 mm = 9.99 mm
    late = ToolState(3, 2, 4_495_000, Flags.FORCES_ENABLED, (0.0, 0.0), (0.0, 0.0999),
                     (0.0, 0.0), 0.0, 0.0)
    guard = primed()
    assert not guard.admit(late, 0.004495)
    assert guard.events[-1]["reason"] == ("tool position jumped 99.9 mm in 4.5 ms (the tool "
                                          "moves at most 9.99 mm)")


def test_a_box_of_the_wrong_length_is_an_error_not_a_partial_check() -> None:
    table = {"position_min_m": [-0.1, -0.1, -0.1], "position_max_m": [0.1, 0.1]}
    with pytest.raises(ValueError):
        ToolGuardSettings.from_config({"master": {"tool_input": table}})


def test_a_fault_clears_after_exactly_the_configured_plausible_run() -> None:
    guard = primed()
    assert not guard.admit(msg(1, force=(99.0, 0.0)), PERIOD_S)
    for seq in range(2, 5):  # 3 plausible: still faulted
        assert guard.admit(msg(seq), seq * PERIOD_S) and guard.faulted
    assert not guard.admit(msg(5, force=(99.0, 0.0)), 5 * PERIOD_S)  # the run starts again
    for seq in range(6, 9):
        assert guard.admit(msg(seq), seq * PERIOD_S) and guard.faulted
    assert guard.admit(msg(9), 9 * PERIOD_S) and not guard.faulted  # the 4th in a row
    assert guard.events[-1] == {"time_s": 9 * PERIOD_S, "kind": "tool_input_fault_cleared",
                                "reason": "4 plausible tool messages in a row"}
    assert [event["kind"] for event in guard.events].count("tool_input_fault_cleared") == 1


def test_counters_and_summary() -> None:
    guard = primed()
    guard.admit(msg(1, force=(math.nan, 0.0)), PERIOD_S)
    guard.admit(msg(2, position=(0.2, 0.0)), 2 * PERIOD_S)  # a jump
    guard.admit(msg(3), 3 * PERIOD_S)
    assert guard.summary() == {"tool_input_guard": {"checked": 4, "faults": 2, "jumps": 1,
                                                    "non_finite": 1, "faulted": True}}
