"""A resync never carries the tool through clay: a forced outage in the middle of a cut."""

from __future__ import annotations

import numpy as np
import pytest

from haptic.common.config.scenario import load_scenario
from haptic.common.model.teleop import model_from_config
from haptic.slave_sim.node import SlaveNode
from haptic.slave_sim.resync import (
    MAX_STEP_PERIODS,
    RESYNC_FREE_SPEED_M_S,
    RESYNC_SPEED_M_S,
    ToolResync,
)

SYNC_TOLERANCE_M = 0.001  # haptic-slave's default --sync-tolerance
HANDLE_AHEAD_M = 0.02  # the handle ran 2 cm ahead during the outage (issue 15's bridge)


def _cut_with_outage(paper_config, policy: str):
    """Cut the constant-rate block with a steady 3.6 N; after 0.6 s the link fails, the tool
    stops, and when the link is back the handle is 2 cm ahead. ``policy``: "through" (the
    program's ToolResync) or "teleport" (placing the tool at the handle)."""
    model = model_from_config(paper_config)
    node = SlaveNode(model, load_scenario("constant-rate").with_grid(512, 128),
                     device="cpu")
    state = node.initial_state(1, start_position_m=np.array([0.03, 0.0]))
    force = np.array([[3.6, 0.0]])
    ticks = 0

    def cut(seconds: float) -> None:
        nonlocal ticks
        for _ in range(int(round(seconds / model.sample_period_s))):
            node.step(state, force, state.tool_position_m())
            ticks += 1

    cut(0.6)
    node.safe_stop(state)  # the watchdog trips: the tool stops where it is
    stopped_at = state.tool_position_m()[0].copy()
    handle = (stopped_at + [HANDLE_AHEAD_M, 0.0])[None]
    distances = []
    if policy == "through":
        resync = ToolResync(node)
        distance = np.inf
        while distance > SYNC_TOLERANCE_M:
            distance = float(resync.step(state, handle)[0])
            distances.append(distance)
            assert len(distances) < 10 * HANDLE_AHEAD_M / (RESYNC_SPEED_M_S
                                                             * model.sample_period_s)
    else:
        node.resync(state, handle)
    node.resume(state)
    cut(0.4)
    return node, state, stopped_at, np.array(distances)


@pytest.fixture(scope="module")
def through(paper_config):
    return _cut_with_outage(paper_config, "through")


def test_resync_brings_the_tool_through_the_clay_at_a_bounded_speed(through) -> None:
    node, state, stopped_at, distances = through
    step = RESYNC_SPEED_M_S * node.sample_period_s
    travelled = -np.diff(np.concatenate([[HANDLE_AHEAD_M], distances]))
    assert (travelled <= step * (1 + 1e-9)).all()
    assert distances[-1] <= SYNC_TOLERANCE_M
    # about (2 cm - 1 mm) / 0.02 m/s of resync, and the tool cut on after it
    assert distances.size * node.sample_period_s == pytest.approx(
        (HANDLE_AHEAD_M - SYNC_TOLERANCE_M) / RESYNC_SPEED_M_S, rel=0.01)
    assert state.tool_position_m()[0, 0] > stopped_at[0] + HANDLE_AHEAD_M


def test_no_uncut_bridge_after_an_outage_mid_cut(through) -> None:
    """Along the groove's centre line every cell from where the cut started to where the
    proxy is now is cut to the tool's bottom: the resync cut its way to the handle."""
    node, state, _, _ = through
    clay = node.environment.clay
    heights = state.environment.heights_m()[0]
    xs, ys = clay.workpiece.cell_centers_m()
    row = int(np.argmin(np.abs(ys)))
    radius = clay.scenario.tool.radius_m
    end = state.environment.proxy_position_m()[0, 0]
    span = (xs > 0.03 + radius) & (xs < end - radius)
    assert span.sum() > 100
    bottom = clay.scenario.tool.bottom_height_m
    assert heights[row, span].max() == pytest.approx(bottom, abs=1e-12)
    conservation = state.environment.conservation_error_m3()[0]
    assert abs(conservation) < 1e-12 * state.environment.removed_total_m3[0]


def test_placing_the_tool_at_the_handle_leaves_a_bridge(paper_config) -> None:
    """The former policy (the tool placed at the handle) skips the clay in between: the
    test above would fail for it."""
    node, state, stopped_at, _ = _cut_with_outage(paper_config, "teleport")
    clay = node.environment.clay
    heights = state.environment.heights_m()[0]
    xs, ys = clay.workpiece.cell_centers_m()
    row = int(np.argmin(np.abs(ys)))
    radius = clay.scenario.tool.radius_m
    bridge = (xs > stopped_at[0] + radius + 0.001) & (xs < stopped_at[0] + HANDLE_AHEAD_M
                                                      - radius - 0.001)
    assert heights[row, bridge].min() == pytest.approx(clay.scenario.blocks[0].height_m)


def test_back_along_its_own_groove_at_the_free_speed(through) -> None:
    """A tool that ran ahead of the handle goes back through its cut groove. While the
    coupling's spring is still compressed the proxy goes on cutting (the clay yields to it)
    and the tool backs off at the cutting speed; then nothing is cut and it goes at the free
    speed (the master's handle rate limit)."""
    node, state, _, _ = through
    node.safe_stop(state)
    clay = state.environment
    lag = state.tool_position_m()[0, 0] - clay.proxy_position_m()[0, 0]
    assert 0.001 < lag < 0.003  # B v / K at the cut's speed
    removed = clay.removed_total_m3[0]
    handle = state.tool_position_m() - [0.01, 0.0]
    resync = ToolResync(node)
    distances = np.array([float(resync.step(state, handle)[0]) for _ in range(600)])
    steps = -np.diff(np.concatenate([[0.01], distances]))
    ts = node.sample_period_s
    slow = np.isclose(steps, RESYNC_SPEED_M_S * ts)
    fast = np.isclose(steps, RESYNC_FREE_SPEED_M_S * ts)
    first_fast = int(np.argmax(fast))
    assert slow[:first_fast].all() and first_fast > 10  # backing off the spring, cutting
    assert first_fast * RESYNC_SPEED_M_S * ts < lag
    # then free, but for a few single steps that meet clay the cut left (cut-cap residue)
    later = slow[first_fast:] | fast[first_fast:]
    assert fast[first_fast:].sum() > 0.75 * later.sum()
    assert distances[-1] == 0.0
    arrived = int(np.argmax(distances == 0.0))
    assert arrived < first_fast + 1.2 * 0.01 / (RESYNC_FREE_SPEED_M_S * ts)
    assert clay.removed_total_m3[0] - removed < node.environment.clay.reference_area_m2 * lag


def test_resync_keeps_its_speed_when_the_loop_runs_late(paper_config) -> None:
    """Given the caller's clock, a step covers the time since the last one (capped): a loop
    that handles one message in five still resyncs at the set speed."""
    model = model_from_config(paper_config)
    node = SlaveNode(model, load_scenario("constant-rate").with_grid(256, 64), device="cpu")
    ts = model.sample_period_s
    state = node.initial_state(1)  # at x = 0, in free air
    node.safe_stop(state)
    resync = ToolResync(node)
    handle = np.array([[0.01, 0.0]])
    left = [float(resync.step(state, handle, now_s=k * 5 * ts)[0]) for k in range(4)]
    # the first call has no previous time (one period), the others cover five each
    assert left[0] == pytest.approx(0.01 - RESYNC_SPEED_M_S * ts)
    assert left[1] == pytest.approx(left[0] - 5 * RESYNC_FREE_SPEED_M_S * ts)
    assert left[2] == pytest.approx(left[1] - 5 * RESYNC_FREE_SPEED_M_S * ts)
    # a stall longer than MAX_STEP_PERIODS counts as that many periods: no jump
    stalled = float(resync.step(state, handle, now_s=1.0)[0])
    assert stalled == pytest.approx(left[3] - MAX_STEP_PERIODS * RESYNC_FREE_SPEED_M_S * ts)


def test_resync_moves_halted_tools_only(paper_config) -> None:
    model = model_from_config(paper_config)
    node = SlaveNode(model, load_scenario("constant-rate").with_grid(256, 64), device="cpu")
    state = node.initial_state(1)
    with pytest.raises(ValueError, match="halted"):
        ToolResync(node).step(state, np.zeros((1, 2)))
    with pytest.raises(ValueError, match="speed"):
        ToolResync(node, 0.0)
    with pytest.raises(ValueError, match="speed"):
        ToolResync(node, 0.05, 0.01)


def test_the_resync_speeds_and_stall_cap_are_pinned() -> None:
    """The values the module's docs and docs/clay.md state (m/s, periods)."""
    assert (RESYNC_SPEED_M_S, RESYNC_FREE_SPEED_M_S, MAX_STEP_PERIODS) == (0.02, 0.25, 20)


def _halted(paper_config, lanes: int):
    """``lanes`` halted tools in free air with motion, compensator and forces left over."""
    model = model_from_config(paper_config)
    node = SlaveNode(model, load_scenario("constant-rate").with_grid(256, 64), device="cpu")
    state = node.initial_state(lanes)  # at x = 0, in free air
    node.safe_stop(state)
    state.tool[:, 1::2] = 0.3  # m/s
    state.compensator[...] = 1.5
    state.actuator_force_N = np.full((lanes, 2), 2.0)
    state.tool_force_N = np.full((lanes, 2), 3.0)
    state.handle_position_m = np.full((lanes, 2), 0.07)
    return node, state


@pytest.mark.parametrize("mask", [None, [True, False, True]])
def test_a_step_moves_the_chosen_tools_at_rest_and_leaves_the_others(paper_config,
                                                                     mask) -> None:
    """Each moving lane: the tool steps towards Ah1 yh, its velocity, compensator and forces
    are zero, and it holds the handle's position; a lane outside the mask is left exactly as
    it was. No array the state shared with another is written through."""
    node, state = _halted(paper_config, 3)
    shared = state.actuator_force_N
    before = {name: np.array(getattr(state, name)) for name in (
        "tool", "compensator", "actuator_force_N", "tool_force_N", "handle_position_m")}
    handle = np.array([[0.01, 0.0], [0.02, 0.0], [0.0, -0.01]])
    left = ToolResync(node).step(state, handle, lanes=None if mask is None else np.array(mask))
    moving = np.ones(3, bool) if mask is None else np.array(mask)
    step = RESYNC_SPEED_M_S * node.sample_period_s  # unknown ground: the cutting speed
    target = node.position_ratio * handle
    for lane in range(3):
        if moving[lane]:
            direction = target[lane] / np.linalg.norm(target[lane])
            assert state.tool_position_m()[lane] == pytest.approx(direction * step, abs=1e-15)
            assert left[lane] == pytest.approx(np.linalg.norm(target[lane]) - step)
            assert (state.tool[lane, 1::2] == 0.0).all()
            assert (state.compensator[lane] == 0.0).all()
            assert (state.actuator_force_N[lane] == 0.0).all()
            assert (state.tool_force_N[lane] == 0.0).all()
            assert (state.handle_position_m[lane] == handle[lane]).all()
        else:
            for name, value in before.items():
                np.testing.assert_array_equal(getattr(state, name)[lane], value[lane], name)
            assert left[lane] == 0.0
    assert (shared == 2.0).all()  # the old array, not written through


def test_a_tool_that_did_not_move_keeps_what_it_knew_of_the_ground(paper_config) -> None:
    """Unknown ground counts as clay (the cutting speed); a step that moves nothing (the
    handle where the tool is) learns nothing, so the next move is still at the cutting
    speed; one free move later, the free speed."""
    node, state = _halted(paper_config, 1)
    resync = ToolResync(node)
    ts = node.sample_period_s
    assert resync.step(state, np.zeros((1, 2)))[0] == 0.0  # at the handle: no move
    handle = np.array([[0.01, 0.0]])
    first = float(resync.step(state, handle)[0])
    assert first == pytest.approx(0.01 * node.position_ratio[0] - RESYNC_SPEED_M_S * ts)
    second = float(resync.step(state, handle)[0])
    assert second == pytest.approx(first - RESYNC_FREE_SPEED_M_S * ts)


def test_equal_cutting_and_free_speeds_are_allowed(paper_config) -> None:
    model = model_from_config(paper_config)
    node = SlaveNode(model, load_scenario("constant-rate").with_grid(256, 64), device="cpu")
    resync = ToolResync(node, 0.05, 0.05)
    assert resync.speed_m_s == resync.free_speed_m_s == 0.05


def test_a_resync_in_the_linear_environment(paper_config) -> None:
    """The sweep's lanes resync in the linear environment (ft = Tt yt): the tool reaches the
    handle in free steps (it cuts nothing), nothing is removed."""
    model = model_from_config(paper_config)
    node = SlaveNode(model, load_scenario("constant-rate"), environment="linear")
    state = node.initial_state(2)
    node.safe_stop(state)
    resync = ToolResync(node)
    handle = np.array([[0.001, 0.0], [0.0, 0.0]])
    left = [resync.step(state, handle) for _ in range(10)]
    assert left[-1].tolist() == [0.0, 0.0]
    assert state.tool_position_m()[0] == pytest.approx(node.position_ratio * handle[0])


def test_the_clay_is_told_the_resyncs_speed(paper_config) -> None:
    """A resync step through clay moves the proxy as a cut at the resync's speed does: the
    coupling's damping sees the tool's velocity over the step (move / elapsed time), by the
    proxy's law (slave_sim/clay/clay_numpy.py proxy_numpy)."""
    model = model_from_config(paper_config)
    node = SlaveNode(model, load_scenario("constant-rate").with_grid(512, 128), device="cpu")
    state = node.initial_state(1, start_position_m=np.array([0.03, 0.0]))
    node.safe_stop(state)
    resync = ToolResync(node)
    handle = np.array([[0.05, 0.0]]) / node.position_ratio
    for _ in range(200):  # into the clay at 0.02 m/s
        resync.step(state, handle)
    clay = state.environment
    contact = node.environment.clay.contact
    proxy = clay.proxy_position_m()[0].copy()
    resistance = float(clay.resistance_N_s_per_m()[0])
    assert resistance > 0.0  # cutting
    resync.step(state, handle)
    tool = state.tool_position_m()[0]
    velocity = RESYNC_SPEED_M_S * np.array([1.0, 0.0])  # m/s, along x
    push = contact.stiffness * (tool - proxy) + contact.damping * velocity
    expected = proxy + contact.period * push / (
        resistance + contact.stiffness * contact.period + contact.damping)
    assert clay.proxy_position_m()[0] == pytest.approx(expected, rel=0, abs=1e-12)
