"""What mutation testing of master/node.py found unchecked: a resume of some lanes enables
only those, its events carry the step's time, and a renewal within a run (``continue_run``)
clears the passivity port's other arrays while keeping its monotone counters."""

from __future__ import annotations

import dataclasses

import numpy as np

from haptic.common.config import load_config
from haptic.common.model.passivity import PassivitySettings
from haptic.master.node import MasterNode
from haptic.master.settings import master_settings


def _node(paper_model, passivity: PassivitySettings | None = None) -> MasterNode:
    safety = dataclasses.replace(master_settings(load_config()).safety,
                                 ramp_small_samples=2, ramp_time_s=0.01)
    return MasterNode.from_model(paper_model, safety, passivity)


def test_resuming_some_lanes_enables_only_those_at_the_steps_time(paper_model) -> None:
    node = _node(paper_model)
    start = np.full((3, 2), 0.01)
    state = node.initial_state(start)
    pushing = np.full((3, 2), 4 * node.safety.ramp_small_force_N)  # the gate stays shut
    assert pushing[0, 0] < node.safety.force_trip_N
    for _ in range(7):
        node.step(state, pushing, start, np.zeros((3, 2)))
    assert not state.forces_enabled.any() and not state.faulted.any()
    node.resume(state, start, lanes=np.array([True, False, False]))
    assert state.forces_enabled.tolist() == [True, False, False]
    enables = [e for e in state.events if e.kind == "enable"]
    assert [e.lane for e in enables] == [0]
    assert enables[0].step == 7
    assert enables[0].time_s == 7 * node.period_s


def test_a_renewal_within_a_run_clears_the_port_but_its_monotone_counters(paper_model) -> None:
    node = _node(paper_model, PassivitySettings(credit_max_J=0.002, master_keep_J=0.0005))
    rng = np.random.default_rng(3)
    yh = np.full((2, 2), 0.01)
    state = node.initial_state(yh)
    for k in range(200):
        yh = yh + rng.normal(0.0, 1e-5, (2, 2))
        state.peer_energy_J[...] = 1e-4 * k
        node.step(state, rng.normal(0.0, 0.02 if k < 20 else 5.0, (2, 2)), yh,
                  rng.normal(0.0, 10.0, (2, 2)))
    port = state.passivity
    moved = {f.name for f in dataclasses.fields(port)
             if isinstance(getattr(port, f.name), np.ndarray)
             and np.any(getattr(port, f.name) != 0)} - {"previous_position_m"}
    kept = {"sent_J", "peer_sent_J", "active"}
    assert moved - kept  # the run left something else to clear
    sent = port.sent_J.copy()
    node.activate(state, yh, continue_run=True)
    np.testing.assert_array_equal(port.sent_J, sent)
    for name in moved - kept:
        assert not np.any(getattr(port, name)), name
