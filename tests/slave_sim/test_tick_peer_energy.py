"""The master's handed-over energy into the slave's passivity layer
(slave_sim/tick.py ``SlaveTick.receive_peer_energy``): one way for the program's lane (a fresh
message's float) and the lockstep's lanes (arrays), on a layer switched on and on one on
standby."""

from __future__ import annotations

import numpy as np
import pytest

from haptic.common.config.scenario import load_scenario
from haptic.common.model.passivity import PassivitySettings
from haptic.lockstep.simulator import LockstepSimulator
from haptic.master.simulated_rig.operator import parse_operator_spec
from haptic.slave_sim.tick import SlaveTick


def _slave_tick(paper_model, lanes: int, standby: bool) -> SlaveTick:
    """A slave tick as the programs and the lockstep build it, with the passivity layer
    switched on (``tdpa``) or on standby for the governor."""
    scenario = load_scenario("constant-rate")
    simulator = LockstepSimulator(paper_model, scenario, parse_operator_spec("constant:fx=0"),
                                  np.ones(lanes), "linear", device="cpu",
                                  passivity=PassivitySettings(), passivity_standby=standby)
    tool_start = np.broadcast_to(np.asarray(scenario.tool.start_position_m, float), (lanes, 2))
    ratio = np.array([axis.position_ratio_ah1 for axis in paper_model.axes])
    return simulator.ticks(tool_start / ratio, tool_start)[1]


def test_a_switched_on_layer_credits_the_newest_energy_once(paper_model) -> None:
    tick = _slave_tick(paper_model, 1, standby=False)
    port = tick.state.passivity
    for value in (0.001, 0.003, 0.002):  # the older, smaller value changes nothing
        tick.receive_peer_energy(value)
    assert port.peer_sent_J[0] == 0.003 and port.tank_J[0] == pytest.approx(0.003)
    port.peer_restarted()  # a new epoch (PassivityLink.peer_energy): counts from zero
    tick.receive_peer_energy(0.0005)
    assert port.peer_sent_J[0] == 0.0005 and port.tank_J[0] == pytest.approx(0.0035)


def test_a_standby_layer_notes_the_energy_without_crediting_it(paper_model) -> None:
    tick = _slave_tick(paper_model, 1, standby=True)
    port = tick.state.passivity
    for value in (0.001, 0.003, 0.002, float("nan")):
        tick.receive_peer_energy(value)
    assert port.peer_sent_J[0] == 0.003 and port.tank_J[0] == 0.0
    # switched on, only what the peer hands over from then on is credited
    port.switch(np.ones(1, bool), True)
    tick.receive_peer_energy(0.004)
    assert port.tank_J[0] == pytest.approx(0.001)


@pytest.mark.parametrize("standby", [False, True])
def test_the_programs_floats_and_the_locksteps_arrays_give_the_same_account(paper_model,
                                                                           standby) -> None:
    """Lane by lane in floats (the program) and every lane at once in arrays (the lockstep):
    the same counts and tanks, bit for bit."""
    values = np.array([[0.001, 0.002], [0.0035, np.nan], [0.003, 0.0025], [0.006, 0.004]])
    lanes = _slave_tick(paper_model, 2, standby)
    lanes.receive_peer_energy(values[0])
    singles = [_slave_tick(paper_model, 1, standby) for _ in range(2)]
    for lane, single in enumerate(singles):
        single.receive_peer_energy(float(values[0, lane]))
    if standby:  # switched on after the first value: later ones are credited
        lanes.state.passivity.switch(np.ones(2, bool), True)
        for single in singles:
            single.state.passivity.switch(np.ones(1, bool), True)
    for row in values[1:]:
        lanes.receive_peer_energy(row)
        for lane, single in enumerate(singles):
            single.receive_peer_energy(float(row[lane]))
    port = lanes.state.passivity
    for name in ("peer_sent_J", "tank_J"):
        np.testing.assert_array_equal(
            getattr(port, name), [getattr(s.state.passivity, name)[0] for s in singles])
    assert port.tank_J.min() > 0.0
