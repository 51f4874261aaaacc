"""The master node's limits pinned by value: every force that reaches the compensator, the
drive (the position command) or the operator (the felt tool force), both signs, both axes,
just under, at and just over each limit.

The node reports what its compensator used (``handle_force_used_N``, ``tool_force_used_N``:
the tool force is also what the operator feels) and the command it sends to the drives
(``command_m``); these tests compare them with the clipped value and with the compensator's
own response to it, exactly, so that a missing bound, a bound on one side only or a limit
moved by a little fails.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from haptic.common.model.passivity import PassivitySettings
from haptic.master.node import MasterNode, master_compensator
from haptic.master.settings import SafetySettings

LIMIT_N = 2.0
TRIP_N = 60.0
#: Just under / just over a limit: far above float64 rounding, far below any real force.
EPS = 1e-6


def _safety(**changes) -> SafetySettings:
    base = SafetySettings(
        force_limit_N=LIMIT_N, force_trip_N=TRIP_N, velocity_limit_m_per_s=50.0,
        velocity_trip_m_per_s=20.0, workspace_min_m=(-0.5, -0.4), workspace_max_m=(0.4, 0.5),
        workspace_trip_margin_m=0.01, ramp_small_force_N=0.5, ramp_small_samples=3,
        ramp_time_s=0.0,
    )
    return dataclasses.replace(base, **changes)


@pytest.fixture(scope="module")
def block(paper_model):
    return master_compensator(paper_model)


def _enabled(node: MasterNode, start: np.ndarray | None = None):
    """A lane past its small-force gate (compensator still zero), at ``start``."""
    start = np.zeros((1, 2)) if start is None else start
    state = node.initial_state(start)
    for _ in range(node.safety.ramp_small_samples):
        node.step(state, np.zeros((1, 2)), start, np.zeros((1, 2)))
    assert state.forces_enabled[0] and not state.faulted[0]
    return state


def _value(level: str, sign: float) -> float:
    return sign * {"under": LIMIT_N - EPS, "at": LIMIT_N, "over": LIMIT_N + EPS,
                   "far": 7.5 * LIMIT_N}[level]


@pytest.mark.parametrize("level", ["under", "at", "over", "far"])
@pytest.mark.parametrize("sign", [1.0, -1.0])
@pytest.mark.parametrize("axis", [0, 1])
@pytest.mark.parametrize("which", ["handle", "tool"])
def test_each_force_saturates_at_the_limit(block, which, axis, sign, level) -> None:
    """The force the compensator integrates (and, for the tool force, the force the operator
    feels) is the input clipped to +-force_limit_N; the command is the compensator's exact
    response to that clipped force; one saturation event at the onset, only beyond the limit."""
    node = MasterNode(block, _safety())
    state = _enabled(node)
    value = _value(level, sign)
    expected = min(max(value, -LIMIT_N), LIMIT_N)
    forces = {"handle": np.zeros((1, 2)), "tool": np.zeros((1, 2))}
    forces[which][0, axis] = value
    clipped = np.zeros((1, 4))
    clipped[0, axis if which == "handle" else 2 + axis] = expected
    reference = block.initial_state(1)
    for _ in range(6):
        command = node.step(state, forces["handle"], np.zeros((1, 2)), forces["tool"])
        used = state.handle_force_used_N if which == "handle" else state.tool_force_used_N
        other = state.tool_force_used_N if which == "handle" else state.handle_force_used_N
        assert used[0, axis] == expected
        assert used[0, 1 - axis] == 0.0 and np.all(other == 0.0)
        np.testing.assert_allclose(command, block.step(reference, clipped), rtol=1e-12,
                                   atol=1e-18)
        np.testing.assert_array_equal(state.command_m, command)
    saturations = [e for e in state.events if e.kind == "saturate"]
    if level in ("over", "far"):
        assert [(e.reason, e.axis, e.step) for e in saturations] == [
            (f"{which} force saturated at {LIMIT_N:g} N", "xy"[axis], 3)]
        assert state.limiting[0, 0 if which == "handle" else 1, axis]
    else:
        assert saturations == []
        assert not state.limiting.any()


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_both_forces_on_both_axes_saturate_together_and_release(block, sign) -> None:
    node = MasterNode(block, _safety())
    state = _enabled(node)
    fh = np.array([[sign * 9.0, -sign * 3.0]])
    ft = np.array([[-sign * 4.0, sign * 50.0]])
    node.step(state, fh, np.zeros((1, 2)), ft)
    np.testing.assert_array_equal(state.handle_force_used_N, [[sign * 2.0, -sign * 2.0]])
    np.testing.assert_array_equal(state.tool_force_used_N, [[-sign * 2.0, sign * 2.0]])
    assert len([e for e in state.events if e.kind == "saturate"]) == 4
    # Back inside the limit: the forces pass unchanged and a new onset is a new event.
    node.step(state, fh / 10.0, np.zeros((1, 2)), ft / 100.0)
    np.testing.assert_array_equal(state.handle_force_used_N, fh / 10.0)
    np.testing.assert_array_equal(state.tool_force_used_N, ft / 100.0)
    assert not state.limiting[0, :2].any()
    node.step(state, fh, np.zeros((1, 2)), np.zeros((1, 2)))
    assert len([e for e in state.events if e.kind == "saturate"]) == 6


def test_forces_scale_with_the_ramp_after_saturation(block) -> None:
    """Saturation comes first, then the ramp scales: used = scale * clip(f)."""
    node = MasterNode(block, _safety(ramp_time_s=10 * block.period_s))
    state = _enabled(node)
    for k in range(12):
        node.step(state, np.array([[-8.0, 1.5]]), np.zeros((1, 2)), np.array([[3.0, -0.25]]))
        scale = min((k + 1) / 10.0, 1.0)  # the gate opened one period ago
        assert state.force_scale[0] == pytest.approx(scale, abs=1e-12)
        np.testing.assert_allclose(state.handle_force_used_N[0], [-2.0 * scale, 1.5 * scale],
                                   rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(state.tool_force_used_N[0], [2.0 * scale, -0.25 * scale],
                                   rtol=1e-12, atol=1e-15)


def test_a_faulted_lane_uses_no_force_and_reports_no_saturation(block) -> None:
    node = MasterNode(block, _safety())
    state = _enabled(node)
    node.trip(state, np.array([True]), "test: outside trip")
    for _ in range(3):
        command = node.step(state, np.array([[9.0, -9.0]]), np.zeros((1, 2)),
                            np.array([[-9.0, 9.0]]))
    np.testing.assert_array_equal(command, [[0.0, 0.0]])
    assert np.all(state.handle_force_used_N == 0.0) and np.all(state.tool_force_used_N == 0.0)
    assert [e.kind for e in state.events] == ["enable", "trip"]


@pytest.mark.parametrize("level,trips", [("under", False), ("at", False), ("over", True)])
@pytest.mark.parametrize("sign", [1.0, -1.0])
@pytest.mark.parametrize("axis", [0, 1])
def test_handle_force_trip_level(block, axis, sign, level, trips) -> None:
    node = MasterNode(block, _safety())
    state = _enabled(node)
    force = np.zeros((1, 2))
    force[0, axis] = sign * {"under": TRIP_N - EPS, "at": TRIP_N, "over": TRIP_N + EPS}[level]
    command = node.step(state, force, np.zeros((1, 2)), np.zeros((1, 2)))
    assert bool(state.faulted[0]) is trips
    if trips:
        assert (state.events[-1].kind, state.events[-1].reason, state.events[-1].axis) == (
            "trip", f"handle force beyond {TRIP_N:g} N", "xy"[axis])
        np.testing.assert_array_equal(command, [[0.0, 0.0]])
        assert np.all(state.handle_force_used_N == 0.0)
    else:
        assert state.handle_force_used_N[0, axis] == sign * LIMIT_N


@pytest.mark.parametrize("level,trips", [("under", False), ("over", True)])
@pytest.mark.parametrize("sign", [1.0, -1.0])
@pytest.mark.parametrize("axis", [0, 1])
def test_handle_speed_trip_level(block, axis, sign, level, trips) -> None:
    ts = block.period_s
    limit = 0.5
    node = MasterNode(block, _safety(velocity_trip_m_per_s=limit))
    start = np.array([[0.01, -0.02]])
    state = _enabled(node, start)
    moved = start.copy()
    speed = limit * (1.0 - 1e-6 if level == "under" else 1.0 + 1e-6)
    moved[0, axis] += sign * speed * ts
    node.step(state, np.zeros((1, 2)), moved, np.zeros((1, 2)))
    assert bool(state.faulted[0]) is trips
    if trips:
        assert (state.events[-1].reason, state.events[-1].axis) == (
            f"handle speed beyond {limit:g} m/s", "xy"[axis])
        np.testing.assert_array_equal(state.hold_m, moved)  # holds where it was measured


@pytest.mark.parametrize("level,trips", [("under", False), ("at", False), ("over", True)])
@pytest.mark.parametrize("side", ["min", "max"])
@pytest.mark.parametrize("axis", [0, 1])
def test_workspace_trip_margin(block, axis, side, level, trips) -> None:
    """Walls and margin in binary fractions, so that "at" is exactly at the trip level."""
    safety = _safety(workspace_min_m=(-0.5, -0.25), workspace_max_m=(0.25, 0.5),
                     workspace_trip_margin_m=0.25, velocity_trip_m_per_s=1e9)
    node = MasterNode(block, safety)
    edge = (safety.workspace_min_m if side == "min" else safety.workspace_max_m)[axis]
    outward = -1.0 if side == "min" else 1.0
    offset = {"under": 0.25 - 2.0**-20, "at": 0.25, "over": 0.25 + 2.0**-20}[level]
    position = np.zeros((1, 2))
    position[0, axis] = edge + outward * offset
    state = node.initial_state(np.zeros((1, 2)))
    node.step(state, np.zeros((1, 2)), position, np.zeros((1, 2)))
    assert bool(state.faulted[0]) is trips
    if trips:
        assert (state.events[-1].reason, state.events[-1].axis) == (
            "handle outside the workspace", "xy"[axis])


@pytest.mark.parametrize("column", range(6))
def test_each_non_finite_input_trips_with_its_reason_and_axis(block, column) -> None:
    """NaN in any of the six inputs (fh x y, yh x y, ft x y): the lane trips at once, names
    the input and the axis, holds the last finite position and keeps it as such."""
    node = MasterNode(block, _safety())
    start = np.array([[0.01, -0.02]])
    state = _enabled(node, start)
    inputs = np.array([[0.0, 0.0, 0.01 + 1e-5, -0.02 - 1e-5, 0.0, 0.0]])  # the handle moved
    inputs[0, column] = np.nan
    command = node.step(state, inputs[:, 0:2], inputs[:, 2:4], inputs[:, 4:6])
    assert state.faulted[0]
    reason = ("handle force", "handle position", "tool force")[column // 2]
    assert (state.events[-1].kind, state.events[-1].reason, state.events[-1].axis) == (
        "trip", f"non-finite {reason}", "xy"[column % 2])
    # it holds where it was before this sample, whichever input failed
    np.testing.assert_array_equal(command, start)
    np.testing.assert_array_equal(state.hold_m, start)
    measured = np.where(np.isfinite(inputs[:, 2:4]), inputs[:, 2:4], start)
    np.testing.assert_array_equal(state.last_position_m, measured)


@pytest.mark.parametrize("sign", [1.0, -1.0])
@pytest.mark.parametrize("axis", [0, 1])
def test_command_rate_limit_both_signs_both_axes(block, axis, sign) -> None:
    """The command to the drives moves by at most velocity_limit * Ts per period, in the
    direction of the push, and the limit acts only beyond it."""
    ts = block.period_s
    limit = 0.01
    node = MasterNode(block, _safety(velocity_limit_m_per_s=limit))
    state = _enabled(node)
    force = np.zeros((1, 2))
    force[0, axis] = sign * 2.0
    previous = np.zeros(2)
    steps = []
    for _ in range(300):
        command = node.step(state, force, np.zeros((1, 2)), np.zeros((1, 2)))[0]
        steps.append(command - previous)
        previous = command
    steps = np.array(steps)
    assert np.all(steps[:, 1 - axis] == 0.0)
    assert np.all(sign * steps[:, axis] >= 0.0)
    assert np.max(np.abs(steps[:, axis])) == pytest.approx(limit * ts, rel=1e-12)
    assert np.sum(np.abs(steps[:, axis]) >= limit * ts * (1 - 1e-12)) > 100
    events = [e for e in state.events if e.kind == "saturate"]
    assert [(e.reason, e.axis) for e in events] == [
        (f"command rate limited to {limit:g} m/s", "xy"[axis])]
    # The first steps, still slower than the limit, pass unchanged.
    assert 0.0 < abs(steps[0, axis]) < limit * ts


@pytest.mark.parametrize("sign", [1.0, -1.0])
@pytest.mark.parametrize("axis", [0, 1])
def test_command_is_clamped_to_each_wall_of_the_workspace(block, axis, sign) -> None:
    safety = _safety(workspace_min_m=(-0.003, -0.002), workspace_max_m=(0.002, 0.003))
    node = MasterNode(block, safety)
    state = _enabled(node)
    force = np.zeros((1, 2))
    force[0, axis] = sign * 2.0
    for _ in range(2000):
        command = node.step(state, force, np.zeros((1, 2)), np.zeros((1, 2)))
    wall = (safety.workspace_max_m if sign > 0 else safety.workspace_min_m)[axis]
    assert command[0, axis] == wall
    assert command[0, 1 - axis] == 0.0
    events = [e for e in state.events if e.kind == "saturate"]
    assert [(e.reason, e.axis) for e in events] == [
        ("command clamped to the workspace", "xy"[axis])]


@pytest.mark.parametrize("side", ["min", "max"])
def test_a_command_resting_exactly_on_a_wall_is_not_clamped(block, side) -> None:
    """The workspace is closed: a command exactly on a wall (the shared work area puts the
    handle there) is inside, so it is neither clamped nor reported, on both axes."""
    safety = _safety()
    wall = safety.workspace_min_m if side == "min" else safety.workspace_max_m
    start = np.array([wall], dtype=float)
    node = MasterNode(block, safety)
    state = _enabled(node, start)
    for _ in range(50):
        command = node.step(state, np.zeros((1, 2)), start, np.zeros((1, 2)))
    assert np.array_equal(command, start)
    assert [e for e in state.events if e.kind == "saturate"] == []


@pytest.mark.parametrize("samples", [1, 4])
def test_the_force_gate_needs_exactly_n_strictly_small_samples(block, samples) -> None:
    node = MasterNode(block, _safety(ramp_small_samples=samples, ramp_small_force_N=0.5))
    state = node.initial_state(np.zeros((1, 2)))
    for at_threshold in ([[0.0, -0.5]], [[0.5, 0.0]]):  # not small: |f| < 0.5 N is required
        for _ in range(samples + 3):
            node.step(state, np.array(at_threshold), np.zeros((1, 2)), np.zeros((1, 2)))
        assert not state.forces_enabled[0] and state.small_force_count[0] == 0
    small = np.array([[0.5 - EPS, -(0.5 - EPS)]])
    for _ in range(samples - 1):
        node.step(state, small, np.zeros((1, 2)), np.zeros((1, 2)))
    assert not state.forces_enabled[0]
    assert np.all(state.handle_force_used_N == 0.0)
    node.step(state, small, np.zeros((1, 2)), np.zeros((1, 2)))
    assert state.forces_enabled[0] and state.small_force_count[0] == samples
    assert [e.kind for e in state.events] == ["enable"]
    assert state.events[0].reason == f"forces enabled after {samples} small-force samples"
    np.testing.assert_array_equal(state.handle_force_used_N, small)  # ramp_time 0: at once


# --- the node's bookkeeping: lanes, events' times and order, outside trips by index ---------


def test_events_carry_step_and_time_and_are_frozen(block) -> None:
    node = MasterNode(block, _safety())
    state = _enabled(node)
    for _ in range(4):
        node.step(state, np.zeros((1, 2)), np.zeros((1, 2)), np.zeros((1, 2)))
    node.step(state, np.array([[0.0, 9.0]]), np.zeros((1, 2)), np.zeros((1, 2)))
    event = state.events[-1]
    assert (event.kind, event.step) == ("saturate", 7)
    assert event.time_s == pytest.approx(7 * block.period_s, rel=1e-12)
    node.trip(state, np.array([0]), "test: outside trip")  # indices, not a mask
    assert state.faulted[0]
    trip = state.events[-1]
    assert (trip.kind, trip.step, trip.reason) == ("trip", 8, "test: outside trip")
    assert trip.time_s == pytest.approx(8 * block.period_s, rel=1e-12)
    with pytest.raises(AttributeError):  # immutable
        trip.kind = "enable"


def test_resume_events_are_at_step_zero(block) -> None:
    node = MasterNode(block, _safety())
    state = node.initial_state(np.zeros((2, 2)))
    node.resume(state, np.zeros((2, 2)))
    assert state.lanes == 2
    assert [(e.kind, e.step, e.time_s, e.lane) for e in state.events] == [
        ("enable", 0, 0.0, 0), ("enable", 0, 0.0, 1)]


def test_trips_in_one_step_are_ordered_by_reason_then_lane(block) -> None:
    node = MasterNode(block, _safety())
    state = node.initial_state(np.zeros((3, 2)))
    position = np.zeros((3, 2))
    position[0, 1] = np.nan  # lane 0: non-finite position, y (code 3)
    position[1, 0] = np.nan  # lane 1: non-finite position, x (code 2)
    tool = np.zeros((3, 2))
    tool[2, 0] = np.inf  # lane 2: non-finite tool force, x (code 4)
    node.step(state, np.zeros((3, 2)), position, tool)
    assert [(e.lane, e.reason, e.axis) for e in state.events] == [
        (0, "non-finite handle position", "y"), (1, "non-finite handle position", "x"),
        (2, "non-finite tool force", "x")]
    state = node.initial_state(np.zeros((2, 2)))
    position = np.zeros((2, 2))
    position[1, 1] = np.nan  # lane 1: position y (code 3), before lane 0's tool force
    tool = np.zeros((2, 2))
    tool[0, 0] = np.nan  # lane 0: tool force x (code 4)
    node.step(state, np.zeros((2, 2)), position, tool)
    assert [e.lane for e in state.events] == [1, 0]


def test_a_compensator_with_other_inputs_or_outputs_is_refused(block) -> None:
    import dataclasses as dc

    for change in ({"output_names": ("vt_x", "vt_y")},
                   {"input_names": ("a", "b", "c", "d")}):
        with pytest.raises(ValueError, match="compensator must map"):
            MasterNode(dc.replace(block, **change), _safety())


def test_a_stacked_compensator_needs_one_lane_each(paper_model) -> None:
    from haptic.lockstep.stacked import StackedLTI

    stacked = StackedLTI.from_blocks([master_compensator(paper_model.with_gain(k))
                                      for k in (1.0, 5.0, 13.0)])
    node = MasterNode(stacked, _safety())
    with pytest.raises(ValueError, match="compensator stacked for 3 lanes, activated with 2"):
        node.initial_state(np.zeros((2, 2)))
    assert node.initial_state(np.zeros((3, 2))).lanes == 3


def test_the_kernel_steps_a_general_coupled_block(block) -> None:
    """Every entry of A, B, C and D counts (the paper's block is diagonal per axis, so its
    cross terms are zero): a random stable coupled block gives its own exact response."""
    from haptic.common.model.lti import DiscreteLTI

    rng = np.random.default_rng(5)
    n = 3
    a = rng.normal(0.0, 0.2, (n, n))
    coupled = DiscreteLTI(a, rng.normal(0.0, 1e-3, (n, 4)), rng.normal(0.0, 1e-2, (2, n)),
                          rng.normal(0.0, 1e-4, (2, 4)), block.period_s, block.input_names,
                          block.output_names)
    node = MasterNode(coupled, _safety())
    state = _enabled(node)
    reference = coupled.initial_state(1)
    for _ in range(20):
        fh, ft = rng.uniform(-1.5, 1.5, (1, 2)), rng.uniform(-1.5, 1.5, (1, 2))
        command = node.step(state, fh, np.zeros((1, 2)), ft)
        expected = coupled.step(reference, np.concatenate([fh, ft], axis=1))
        np.testing.assert_allclose(command, expected, rtol=1e-12, atol=1e-18)


def test_the_passivity_layer_waits_switched_off_only_when_asked_and_built(block) -> None:
    """``tdpa`` mode: the layer runs from the start; ``passivity_standby``: it is built
    switched off for the governor; without the layer there is nothing to stand by."""
    running = MasterNode(block, _safety(), PassivitySettings())
    assert running.passivity_standby is False
    assert running.initial_state(np.zeros((1, 2))).passivity.active.tolist() == [True]
    standby = MasterNode(block, _safety(), PassivitySettings(), passivity_standby=True)
    assert standby.passivity_standby is True
    assert standby.initial_state(np.zeros((1, 2))).passivity.active.tolist() == [False]
    assert MasterNode(block, _safety(), None, passivity_standby=True).passivity_standby is False
