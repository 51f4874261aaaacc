"""The TDPA port's bookkeeping at its edges (common/model/passivity.py): switching lanes on
and off, a switched-off lane's account, carrying counters over a node state made afresh, the
peer's restart, the credit cap at its level, the summary's keys. Exact values throughout;
tests/common/model/test_passivity.py tests the controllers' physics."""

from __future__ import annotations

import json

import numpy as np
import pytest

from haptic.common.model.passivity import PassivityPort, PassivitySettings, passivity_summary

TS = 0.00054


def port(lanes: int = 1, keep_J: float = 0.0, active: bool = True,
         **changes: float) -> PassivityPort:
    return PassivityPort.create(PassivitySettings(**changes), TS, lanes, keep_J, active=active)


def test_a_new_port_is_empty_and_on_or_off_as_asked() -> None:
    p = port(2)
    for name in ("tank_J", "sent_J", "peer_sent_J", "input_energy_J", "output_energy_J",
                 "forgotten_energy_J", "dissipated_energy_J", "correction_m",
                 "damper_force_N"):
        assert getattr(p, name).tolist() == [0.0, 0.0], name
    assert p.active_steps.dtype == np.int64 and p.active_steps.tolist() == [0, 0]
    assert p.previous_position_m.shape == (2, 2) and not p.previous_position_m.any()
    assert p.active.dtype == np.bool_ and p.active.tolist() == [True, True]
    assert port(2, active=False).active.tolist() == [False, False]
    assert (p.period_s, p.keep_J) == (TS, 0.0)


def test_a_port_keeps_nothing_unless_asked_and_is_compared_by_identity() -> None:
    """``keep_J`` defaults to 0 (Artigas' TDPN); ports hold arrays, so two ports with the
    same values are two ports (no element-wise ``==``), and a port can key a dict."""
    p = PassivityPort.create(PassivitySettings(), TS, 2)
    assert p.keep_J == 0.0
    twin = PassivityPort.create(PassivitySettings(), TS, 2)
    assert p == p and p != twin
    assert {p: 1, twin: 2}[twin] == 2


def test_switching_on_starts_the_account_empty_and_only_where_it_changed() -> None:
    p = port(3, active=False)
    p.active[0] = True
    for name, value in (("tank_J", 0.3), ("correction_m", 1e-4), ("damper_force_N", 2.0),
                        ("sent_J", 0.7), ("peer_sent_J", 0.9)):
        getattr(p, name)[...] = value
    changed = p.switch(np.array([True, True, False]), True)
    assert changed.tolist() == [False, True, False]  # lane 0 was on, lane 2 not asked
    assert p.active.tolist() == [True, True, False]
    assert p.tank_J.tolist() == [0.3, 0.0, 0.3]
    assert p.correction_m.tolist() == [1e-4, 0.0, 1e-4]
    assert p.damper_force_N.tolist() == [2.0, 0.0, 2.0]
    assert p.sent_J.tolist() == [0.7] * 3 and p.peer_sent_J.tolist() == [0.9] * 3
    changed = p.switch(np.array([True, False, True]), False)  # off: the account is kept
    assert changed.tolist() == [True, False, False]
    assert p.active.tolist() == [False, True, False] and p.tank_J.tolist() == [0.3, 0.0, 0.3]


def test_a_switched_off_lane_notes_the_peers_energy_and_credits_nothing() -> None:
    p = port(2, active=False)
    p.active[1] = True
    p.receive(np.array([0.2, 0.2]))
    assert p.peer_sent_J.tolist() == [0.2, 0.2] and p.tank_J.tolist() == [0.0, 0.2]
    p.observe(np.array([0.05, 0.05]))
    assert p.input_energy_J.tolist() == [0.0, 0.05] and p.sent_J.tolist() == [0.0, 0.05]
    p.observe(np.array([-0.01, -0.01]))
    assert p.output_energy_J.tolist() == [0.0, 0.01]


def test_a_port_made_afresh_continues_the_counters_not_the_account() -> None:
    old = port(2, active=False)
    old.active[1] = True
    old.sent_J[...] = (0.1, 0.2)
    old.peer_sent_J[...] = (0.3, 0.4)
    old.tank_J[...] = 0.25
    new = port(2, active=False)
    new.continue_from(old)
    assert new.sent_J.tolist() == [0.1, 0.2] and new.peer_sent_J.tolist() == [0.3, 0.4]
    assert new.active.tolist() == [False, True] and new.tank_J.tolist() == [0.0, 0.0]
    fresh = port(2)
    fresh.continue_from(None)
    assert fresh.sent_J.tolist() == [0.0, 0.0] and fresh.active.tolist() == [True, True]


def test_a_restarted_peer_is_counted_from_zero() -> None:
    p = port(2)
    p.receive(np.array([0.3, 0.1]))
    p.peer_restarted()
    assert p.peer_sent_J.tolist() == [0.0, 0.0]
    p.receive(np.array([0.05, 0.05]))  # its new run's first energy is credited
    assert p.tank_J.tolist() == pytest.approx([0.35, 0.15], abs=1e-15)


def test_the_credit_cap_keeps_exactly_its_level_and_counts_the_rest() -> None:
    p = port(2, credit_max_J=0.5)
    p.receive(np.array([0.5, 0.75]))
    assert p.tank_J.tolist() == [0.5, 0.5] and p.forgotten_energy_J.tolist() == [0.0, 0.25]
    p.observe(np.array([-0.25, -0.25]))  # below the cap: nothing forgotten
    assert p.forgotten_energy_J.tolist() == [0.0, 0.25] and p.tank_J.tolist() == [0.25, 0.25]


def test_observe_hands_over_only_this_steps_input_beyond_keep() -> None:
    p = port(1, keep_J=0.25)
    p.receive(np.array([0.5]))  # received energy stays (it does not bounce back)
    p.observe(np.array([0.125]))
    assert p.sent_J.tolist() == [0.125] and p.tank_J.tolist() == [0.5]
    q = port(1, keep_J=0.25)
    q.observe(np.array([0.125]))  # all of it kept: under keep_J
    assert q.sent_J.tolist() == [0.0] and q.tank_J.tolist() == [0.125]
    q.observe(np.array([0.25]))  # 0.375 held: 0.125 beyond keep_J goes
    assert q.sent_J.tolist() == [0.125] and q.tank_J.tolist() == [0.25]
    q.observe(np.array([np.nan]))  # no measurement: no work
    assert q.tank_J.tolist() == [0.25] and q.input_energy_J.tolist() == [0.375]


def test_the_summary_of_each_layer() -> None:
    assert passivity_summary(None, False) == {"tdpa_layer": "off", "tdpa_active": False}
    assert passivity_summary(None, True) == {"tdpa_layer": "standby", "tdpa_active": False}
    p = port(2)
    p.active[1] = False
    p.sent_J[...] = (0.125, 9.0)
    p.peer_sent_J[...] = (0.25, 9.0)
    p.input_energy_J[...] = (0.5, 9.0)
    p.output_energy_J[...] = (0.75, 9.0)
    p.dissipated_energy_J[...] = (1.5, 9.0)
    p.forgotten_energy_J[...] = (2.5, 9.0)
    p.tank_J[...] = (-0.0625, 9.0)
    p.active_steps[...] = (7, 9)
    summary = passivity_summary(p, False)
    assert summary == {
        "tdpa_layer": "tdpa", "tdpa_active": True, "tdpa_sent_J": 0.125,
        "tdpa_received_J": 0.25, "tdpa_input_energy_J": 0.5, "tdpa_output_energy_J": 0.75,
        "tdpa_dissipated_energy_J": 1.5, "tdpa_forgotten_energy_J": 2.5,
        "tdpa_reserve_J": -0.0625, "tdpa_active_steps": 7}
    assert json.loads(json.dumps(summary)) == summary  # plain numbers for the JSON summary
    standby = passivity_summary(p, True, lane=1)
    assert standby["tdpa_layer"] == "standby" and standby["tdpa_active"] is False
    assert standby["tdpa_active_steps"] == 9
