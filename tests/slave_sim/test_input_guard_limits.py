"""The slave's input guard pinned by value: every bound on both axes and both signs, just
inside and just outside, the jump allowance over the sender's own time, the exact saturation
and rate-limit steps, the fault latch and its clearing count (slave_sim/input_guard.py)."""

from __future__ import annotations

import math

import pytest

from haptic.common.config import ConfigError, load_config, override
from haptic.common.wire.messages import Flags, HandleState
from haptic.slave_sim.input_guard import InputGuard, InputGuardSettings

PERIOD_S = 0.0005
PERIOD_NS = 500_000
SETTINGS = InputGuardSettings(force_limit_N=16.0, force_trip_N=32.0,
                              force_rate_limit_N_per_s=8000.0,  # 4 N per period
                              position_min_m=(-0.125, -0.25), position_max_m=(0.125, 0.25),
                              velocity_trip_m_per_s=1.0, jump_margin_m=0.001,
                              clear_after_messages=5)
STEP_N = 4.0
TINY = 1e-9


def msg(seq: int, force=(0.0, 0.0), position=(0.0, 0.0), epoch: int = 3,
        send_ns: int | None = None) -> HandleState:
    send_time_ns = seq * PERIOD_NS if send_ns is None else send_ns
    return HandleState(epoch, seq, send_time_ns, Flags.FORCES_ENABLED, force, position)


def guard(**changes) -> InputGuard:
    settings = InputGuardSettings(**{**SETTINGS.__dict__, **changes})
    return InputGuard(settings, PERIOD_S)


def primed(force=(0.0, 0.0), position=(0.0, 0.0)) -> InputGuard:
    g = guard()
    assert g.admit(msg(0, force, position), 0.0)
    return g


# --- configuration -----------------------------------------------------------------------

def test_trip_equal_to_the_limit_is_allowed_below_it_refused() -> None:
    config = load_config()
    equal = override(override(config, "slave.safety.force_limit_N", 30.0),
                     "slave.safety.force_trip_N", 30.0)
    assert InputGuardSettings.from_config(equal).force_trip_N == 30.0
    below = override(equal, "slave.safety.force_trip_N", 29.999)
    with pytest.raises(ConfigError, match="slave.safety.force_trip_N"):
        InputGuardSettings.from_config(below)


@pytest.mark.parametrize("axis", [0, 1])
def test_an_empty_position_box_on_either_axis_is_refused(axis) -> None:
    config = load_config()
    low = list(config["slave"]["safety"]["position_min_m"])
    high = list(config["slave"]["safety"]["position_max_m"])
    high[axis] = low[axis]
    bad = override(config, "slave.safety.position_max_m", high)
    with pytest.raises(ConfigError, match="slave.safety.position_max_m"):
        InputGuardSettings.from_config(bad)


def test_list_values_become_tuples() -> None:
    settings = InputGuardSettings.from_config(load_config())
    assert isinstance(settings.position_min_m, tuple)
    assert isinstance(settings.position_max_m, tuple)


# --- faults: non-finite, force trip, the plausible box ------------------------------------

@pytest.mark.parametrize("where", range(4))
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_any_non_finite_value_is_a_fault(where, bad) -> None:
    g = primed(force=(1.0, -1.0), position=(0.01, 0.02))
    values = [1.0, -1.0, 0.01, 0.02]
    values[where] = bad
    assert not g.admit(msg(1, tuple(values[:2]), tuple(values[2:])), PERIOD_S)
    assert g.faulted and g.counters.non_finite == 1 and g.counters.faults == 1
    assert (g.force_N, g.position_m) == ((1.0, -1.0), (0.01, 0.02))  # the last input kept
    assert g.events[-1] == {"time_s": PERIOD_S, "kind": "input_fault",
                            "reason": "non-finite handle force or position"}


@pytest.mark.parametrize("axis", [0, 1])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_the_force_trip_is_exclusive_on_each_axis_and_sign(axis, sign) -> None:
    at = [0.0, 0.0]
    at[axis] = sign * 32.0
    g = primed()
    assert g.admit(msg(1, tuple(at)), PERIOD_S)  # exactly the trip: an input (saturated)
    assert not g.faulted
    beyond = [0.0, 0.0]
    beyond[axis] = sign * (32.0 + TINY)
    assert not g.admit(msg(2, tuple(beyond)), 2 * PERIOD_S)
    assert g.faulted and g.counters.faults == 1 and g.counters.non_finite == 0
    assert "beyond +-32 N" in g.events[-1]["reason"]


@pytest.mark.parametrize(("axis", "edge"), [(0, -0.125), (0, 0.125), (1, -0.25), (1, 0.25)])
def test_the_plausible_box_includes_its_edges(axis, edge) -> None:
    position = [0.0, 0.0]
    position[axis] = edge
    g = guard()
    assert g.admit(msg(0, position=tuple(position)), 0.0)  # first message: no jump check
    assert g.position_m == tuple(position)
    position[axis] = edge + math.copysign(TINY, edge)
    g = guard()
    assert not g.admit(msg(0, position=tuple(position)), 0.0)
    assert g.faulted and g.position_m is None
    assert "outside the plausible box" in g.events[-1]["reason"]


# --- the jump allowance: speed times the sender's elapsed time, plus the margin -----------

@pytest.mark.parametrize("axis", [0, 1])
@pytest.mark.parametrize("sign", [1.0, -1.0])
@pytest.mark.parametrize("periods", [1, 4])
def test_a_jump_up_to_speed_times_time_plus_margin_is_plausible(axis, sign, periods) -> None:
    allowed_m = 1.0 * periods * PERIOD_S + 0.001
    inside = [0.0, 0.0]
    inside[axis] = sign * allowed_m * (1.0 - 1e-6)
    g = primed()
    assert g.admit(msg(periods, position=tuple(inside)), periods * PERIOD_S)
    outside = [0.0, 0.0]
    outside[axis] = sign * allowed_m * (1.0 + 1e-6)
    g = primed()
    assert not g.admit(msg(periods, position=tuple(outside)), periods * PERIOD_S)
    assert g.faulted and "jumped" in g.events[-1]["reason"]


def test_the_elapsed_time_is_the_senders_and_at_least_one_period() -> None:
    """Two messages sent at the same instant span one period (not zero), however much loop
    time (``now_s``) passed: the loop's own time only caps the span (common/wire/
    send_clock.py), it never lengthens it."""
    g = primed()
    allowed_m = 1.0 * PERIOD_S + 0.001
    assert g.admit(msg(1, position=(allowed_m * 0.999, 0.0), send_ns=0), 99.0)
    g = primed()
    assert not g.admit(msg(1, position=(allowed_m * 1.001, 0.0), send_ns=0), 99.0)


def test_a_new_epoch_skips_the_jump_check_but_not_the_box() -> None:
    g = primed()
    assert g.admit(msg(0, position=(0.1, 0.2), epoch=4), PERIOD_S)
    assert not g.admit(msg(0, position=(0.2, 0.0), epoch=5), 2 * PERIOD_S)


# --- saturation and the rate limit --------------------------------------------------------

@pytest.mark.parametrize("axis", [0, 1])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_saturation_holds_the_force_at_the_limit_exactly(axis, sign) -> None:
    g = guard(force_rate_limit_N_per_s=1e12)  # no rate limit in the way
    assert g.admit(msg(0), 0.0)
    force = [0.0, 0.0]
    force[axis] = sign * 16.0
    assert g.admit(msg(1, tuple(force)), PERIOD_S)
    assert g.force_N == tuple(force) and g.counters.saturated == 0  # at the limit: untouched
    force[axis] = sign * 20.0
    assert g.admit(msg(2, tuple(force)), 2 * PERIOD_S)
    expected = [0.0, 0.0]
    expected[axis] = sign * 16.0
    assert g.force_N == tuple(expected) and g.counters.saturated == 1
    assert g.events[-1]["kind"] == "input_saturated"


@pytest.mark.parametrize("axis", [0, 1])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_the_rate_limit_steps_exactly_rate_times_time(axis, sign) -> None:
    g = primed()
    force = [0.0, 0.0]
    force[axis] = sign * STEP_N  # exactly one step: not limited
    assert g.admit(msg(1, tuple(force)), PERIOD_S)
    assert g.force_N == tuple(force) and g.counters.rate_limited == 0
    force[axis] = sign * 15.0
    assert g.admit(msg(2, tuple(force)), 2 * PERIOD_S)
    expected = [0.0, 0.0]
    expected[axis] = sign * 2 * STEP_N
    assert g.force_N == pytest.approx(tuple(expected), abs=1e-9)
    assert g.counters.rate_limited == 1
    # three periods of the sender's time allow three steps
    assert g.admit(msg(5, tuple(force)), 3 * PERIOD_S)
    expected[axis] = sign * 15.0
    assert g.force_N == pytest.approx(tuple(expected), abs=1e-9)


def test_the_first_message_is_rate_limited_from_zero() -> None:
    g = guard()
    assert g.admit(msg(0, (10.0, -10.0)), 0.0)
    assert g.force_N == pytest.approx((STEP_N, -STEP_N), abs=1e-9)


def test_each_onset_of_a_limit_is_one_event() -> None:
    g = guard(force_rate_limit_N_per_s=1e12)
    forces = [20.0, 20.0, 1.0, 20.0, 20.0]
    for seq, fx in enumerate(forces):
        assert g.admit(msg(seq, (fx, 0.0)), seq * PERIOD_S)
    kinds = [e["kind"] for e in g.events]
    assert kinds == ["input_saturated", "input_saturated"]
    assert g.counters.saturated == 4
    assert g.events[0]["reason"] == "handle force (20, 0) N held at +-16 N"
    g = guard()
    for seq, fx in enumerate([15.0, 15.0, 15.0, 15.0, -15.0]):
        g.admit(msg(seq, (fx, 0.0)), seq * PERIOD_S)
    kinds = [e["kind"] for e in g.events]
    assert kinds == ["input_rate_limited", "input_rate_limited"]
    assert g.events[0]["reason"] == "handle force changes faster than 8000 N/s"


def test_messages_taken_plain_end_a_limit_so_the_next_onset_is_an_event() -> None:
    """take_plain (the lockstep's quiet lanes: messages the guard takes unchanged, so neither
    saturated nor rate limited) ends a saturation: the next saturating message is a new
    onset, one event."""
    g = guard(force_rate_limit_N_per_s=1e12)
    assert g.admit(msg(0, (20.0, 0.0)), 0.0)
    assert [e["kind"] for e in g.events] == ["input_saturated"]
    g.take_plain(3, (1.0, 0.0), (0.0, 0.0), g.clock)
    assert g.counters.checked == 4
    assert g.admit(msg(4, (20.0, 0.0)), 4 * PERIOD_S)
    assert [e["kind"] for e in g.events] == ["input_saturated", "input_saturated"]
    g = guard()
    assert g.admit(msg(0, (0.0, 0.0)), 0.0)
    assert g.admit(msg(1, (15.0, 0.0)), PERIOD_S)  # rate limited
    g.take_plain(1, (4.0, 0.0), (0.0, 0.0), g.clock)
    assert g.admit(msg(2, (15.0, 0.0)), 2 * PERIOD_S)
    assert [e["kind"] for e in g.events] == ["input_rate_limited", "input_rate_limited"]


# --- the latch ----------------------------------------------------------------------------

def test_a_fault_clears_after_exactly_the_configured_plausible_run() -> None:
    g = primed()
    assert not g.admit(msg(1, (99.0, 0.0)), PERIOD_S)
    for seq in range(2, 2 + 4):
        assert g.admit(msg(seq), seq * PERIOD_S)
        assert g.faulted, seq  # 4 of 5
    # a new fault restarts the count
    assert not g.admit(msg(6, (0.0, 99.0)), 6 * PERIOD_S)
    for seq in range(7, 7 + 4):
        assert g.admit(msg(seq), seq * PERIOD_S)
    assert g.faulted
    assert g.admit(msg(11), 11 * PERIOD_S)
    assert not g.faulted
    assert g.events[-1] == {"time_s": 11 * PERIOD_S, "kind": "input_fault_cleared",
                            "reason": "5 plausible messages in a row"}
    assert g.admit(msg(12), 12 * PERIOD_S)
    assert g.events[-1]["kind"] == "input_fault_cleared"  # no second clearing event


def test_counters_and_summary() -> None:
    g = primed()
    g.admit(msg(1, (math.nan, 0.0)), PERIOD_S)
    g.admit(msg(2, (20.0, 0.0)), 2 * PERIOD_S)
    assert g.summary() == {"input_guard": {"checked": 3, "faults": 1, "saturated": 1,
                                           "rate_limited": 1, "non_finite": 1,
                                           "faulted": True}}


def test_the_shipped_defaults_are_the_configurations_and_frozen() -> None:
    import dataclasses

    shipped = InputGuardSettings()
    assert shipped == InputGuardSettings.from_config(load_config())
    assert (shipped.force_limit_N, shipped.force_trip_N, shipped.force_rate_limit_N_per_s,
            shipped.position_min_m, shipped.position_max_m, shipped.velocity_trip_m_per_s,
            shipped.jump_margin_m, shipped.clear_after_messages,
            shipped.jitter_allowance_s) == (
        20.0, 60.0, 20000.0, (-0.16, -0.16), (0.16, 0.16), 1.0, 0.001, 20, 0.005)
    with pytest.raises(dataclasses.FrozenInstanceError):
        shipped.force_limit_N = 1e9  # type: ignore[misc]


def test_a_box_of_the_wrong_length_is_an_error_not_a_partial_check() -> None:
    table = {"position_min_m": [-0.1, -0.1, -0.1], "position_max_m": [0.1, 0.1]}
    with pytest.raises(ValueError):
        InputGuardSettings.from_config({"slave": {"safety": table}})


@pytest.mark.parametrize("axis", [0, 1])
def test_the_jump_is_measured_from_the_previous_position_on_each_axis(axis) -> None:
    start = (0.05, -0.03)
    g = primed(position=start)
    moved = list(start)
    moved[axis] += 0.0005
    assert g.admit(msg(1, position=tuple(moved)), PERIOD_S)
    assert not g.faulted


def test_a_jump_of_exactly_the_allowance_is_plausible() -> None:
    dt_s = max(PERIOD_NS * 1e-9, PERIOD_S)
    allowed_m = 1.0 * dt_s + 0.001  # computed as the guard does
    g = primed()
    assert g.admit(msg(1, position=(allowed_m, 0.0)), PERIOD_S)
    g = primed()
    assert g.admit(msg(1, position=(0.0, -allowed_m)), PERIOD_S)


def test_a_jumps_reason_gives_millimetres_and_milliseconds() -> None:
    g = primed()
    assert not g.admit(msg(1, position=(0.01, 0.0)), PERIOD_S)
    assert g.events[-1]["reason"] == "handle position jumped 10 mm in 0.5 ms (at most 1.5 mm)"


def test_a_jumps_reason_keeps_three_significant_digits() -> None:
    g = primed()
    assert not g.admit(msg(1, position=(0.0999, 0.0)), PERIOD_S)
    assert g.events[-1]["reason"] == "handle position jumped 99.9 mm in 0.5 ms (at most 1.5 mm)"
    g = guard(jump_margin_m=0.0994)  # allows 0.5 mm + 99.4 mm in one period
    assert g.admit(msg(0), 0.0)
    assert not g.admit(msg(1, position=(0.12, 0.0)), PERIOD_S)
    assert g.events[-1]["reason"] == ("handle position jumped 120 mm in 0.5 ms "
                                      "(at most 99.9 mm)")
