"""A node state activated again in place (``MasterNode.activate(state, ...)``) is a new
state: every array, the passivity port and the recorded launches give what a freshly made state
gives, whatever the state went through; and the tick's renewals set its one state afresh in
place, the prepared one, so a (re)activation in the loop allocates nothing.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from haptic.common.config import load_config
from haptic.common.model.passivity import PassivitySettings
from haptic.common.wire.messages import Flags, ToolState
from haptic.master.node import MasterNode
from haptic.master.settings import master_settings
from haptic.master.supervisor import MasterSupervisor, Transition
from haptic.master.tick import MasterTick


def _safety(**changes):
    return dataclasses.replace(master_settings(load_config()).safety, **changes)


def _node(paper_model, mode: str) -> MasterNode:
    safety = _safety(ramp_small_samples=2, ramp_time_s=0.01)
    if mode == "paper":
        return MasterNode.from_model(paper_model, safety)
    settings = PassivitySettings(credit_max_J=0.002, master_keep_J=0.0005,
                                 master_drift_rate_per_s=1.0)
    return MasterNode.from_model(paper_model, safety, settings,
                                 passivity_standby=(mode == "standby"))


def _churn(node: MasterNode, state, rng: np.random.Generator, steps: int = 300) -> None:
    """Drive ``state`` through the gate, the ramp, saturations, a trip and (tdpa) the port."""
    lanes = state.lanes
    yh = np.full((lanes, 2), 0.01)
    for k in range(steps):
        fh = rng.normal(0.0, 0.02 if k < 20 else 8.0, (lanes, 2))
        yh = yh + rng.normal(0.0, 1e-5, (lanes, 2))  # a handle moving at about 20 mm/s
        ft = rng.normal(0.0, 20.0, (lanes, 2))
        if k == steps // 2:
            fh[0, 0] = 500.0  # beyond the force trip
            state.gain_ratio[1:] = 0.7  # as the margin governor lowers k
        if state.passivity is not None:
            state.peer_energy_J[...] = 1e-4 * k
            state.peer_target_m[...] = yh
        node.step(state, fh, yh, ft)


def _arrays(state) -> dict[str, np.ndarray]:
    """Every array of a state, its passivity port's included, by name."""
    found = {}
    for item in dataclasses.fields(state):
        value = getattr(state, item.name)
        if isinstance(value, np.ndarray):
            found[item.name] = value
    if state.passivity is not None:
        for item in dataclasses.fields(state.passivity):
            value = getattr(state.passivity, item.name)
            if isinstance(value, np.ndarray):
                found[f"passivity.{item.name}"] = value
    return found


def _assert_same(state, expected) -> None:
    mine, theirs = _arrays(state), _arrays(expected)
    assert mine.keys() == theirs.keys()
    for name, value in theirs.items():
        np.testing.assert_array_equal(mine[name], value, err_msg=name)
    assert state.step == expected.step
    assert [(e.step, e.lane, e.kind, e.reason, e.axis) for e in state.events] == [
        (e.step, e.lane, e.kind, e.reason, e.axis) for e in expected.events]


@pytest.mark.parametrize("mode", ["paper", "tdpa", "standby"])
@pytest.mark.parametrize("renewal", ["activate", "resume"])
def test_a_reused_state_is_a_new_state_and_steps_like_one(paper_model, mode, renewal) -> None:
    node = _node(paper_model, mode)
    rng = np.random.default_rng(7)
    reused = node.initial_state(np.full((3, 2), 0.01))
    _churn(node, reused, rng)
    assert reused.faulted[0] and reused.forces_enabled.any() and reused.events
    start = np.array([[0.01, -0.002], [np.nan, 0.0], [0.03, 0.004]])  # lane 1 trips at start
    fresh = node.initial_state(start)
    if renewal == "activate":
        node.activate(reused, start)
    else:
        node.resume(reused, start)
        node.resume(fresh, start)
    _assert_same(reused, fresh)
    inputs = np.random.default_rng(11)
    for _ in range(200):  # the same law from here on: the recorded launches are intact
        fh, yh, ft = (inputs.normal(0.0, s, (3, 2)) for s in (1.0, 1e-3, 5.0))
        if mode != "paper":
            for state in (reused, fresh):
                state.peer_energy_J[...] = 0.002
                state.peer_target_m[...] = yh
        np.testing.assert_array_equal(node.step(reused, fh, yh, ft),
                                      node.step(fresh, fh, yh, ft))
    _assert_same(reused, fresh)


def test_activation_refuses_a_state_of_another_lane_count(paper_model) -> None:
    node = _node(paper_model, "paper")
    with pytest.raises(ValueError, match="2 lanes for 3"):
        node.activate(node.initial_state(np.zeros((2, 2))), np.zeros((3, 2)))


def _scenario_tick(node: MasterNode, paper_model, prepared: bool) -> tuple[list, list]:
    """One lane through its first ACTIVATE and two outages (HOLD, then RESUME); returns the
    node state after each tick and the commands. ``prepared=False``: the first activation
    allocates the state (no :meth:`MasterTick.prepare`), the reference."""
    ts = paper_model.sample_period_s
    ratio = tuple(float(a.position_ratio_ah1) for a in paper_model.axes)
    tick = MasterTick(node, [MasterSupervisor(ratio, 0.001, 0.01, 5)])
    tick.start(np.zeros(2))
    if prepared:
        tick.prepare(np.zeros(2))
    made = tick._prepared
    outages = (range(150, 200), range(300, 350))
    position = np.zeros((1, 2))
    states, commands, transitions = [], [], []
    last_heard = 0
    for k in range(450):
        quiet = any(k in outage for outage in outages)
        message = None
        if not quiet:
            last_heard = k
            tool_m = (ratio[0] * position[0, 0], ratio[1] * position[0, 1])
            message = ToolState(1, k, 0, Flags.FORCES_ENABLED, (0.3, 0.0), tool_m,
                                (0.0, 0.0), 0.0, 0.0)
        transitions += tick.supervise(k * ts, [message], position,
                                      silence_s=[(k - last_heard) * ts])
        force = np.array([[0.05 if k < 60 else 1.5, 0.2]])
        out = tick.control(force, position)
        states.append(tick.state)
        commands.append(out.command_m.copy())
        position = out.command_m.copy()
    assert transitions.count(Transition.ACTIVATE) == 1
    assert transitions.count(Transition.RESUME) == 2
    assert (made is not None) == prepared and (made is None or states[-1] is made)
    return states, commands


def test_the_tick_renews_its_prepared_state_in_place(paper_model) -> None:
    node = _node(paper_model, "tdpa")
    states, commands = _scenario_tick(node, paper_model, prepared=True)
    _, reference = _scenario_tick(node, paper_model, prepared=False)
    np.testing.assert_array_equal(np.array(commands), np.array(reference))
    distinct = []
    for state in states:
        if state is not None and not any(state is seen for seen in distinct):
            distinct.append(state)
    # the prepared state through three renewals: one state, set afresh in place
    assert len(distinct) == 1
    assert states[-1].forces_enabled.all()
