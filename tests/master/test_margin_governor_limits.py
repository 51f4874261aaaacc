"""The margin governor at its edges (master/margin_governor.py): its settings' bounds and
defaults, each comparison at its tie, the first and a backward tick, the lowest gain of a
longer table, the events' and the status line's words, and ``governor_for``'s check. The
twin of tests/master/test_margin_governor.py, which tests its behaviour over time."""

from __future__ import annotations

import dataclasses
import math

import pytest

from haptic.common.analysis.margin_table import table_from_pairs
from haptic.common.config import ConfigError, load_config, override
from haptic.common.model.teleop import model_from_config
from haptic.master.margin_governor import (
    _SNAP,
    GovernorDecision,
    GovernorSettings,
    MarginGovernor,
    _Peak,
    governor_for,
)

TS = 0.00054
TABLE = table_from_pairs([(13.0, 0.0143), (10.4, 0.0228), (8.32, None)])
#: Every gain with a finite margin, s: beyond the last one, no gain is stable.
FINITE = table_from_pairs([(13.0, 0.0143), (10.4, 0.0228), (8.32, 0.060)])
#: Margins of 0.1 s and more: figures in ms that show their fourth digit.
LONG = table_from_pairs([(13.0, 0.1), (10.4, 0.2), (8.32, None)])
#: A gain whose snap distance is exactly representable: (k + _SNAP k) - k == _SNAP k.
EXACT_K = 9.131


def test_the_settings_defaults_are_pinned_and_frozen() -> None:
    assert dataclasses.astuple(GovernorSettings()) == (
        False, "lower_k", 0.7, 0.9, 0.02, 0.1, 2.0, 5.0, 1.0, 0.8)
    with pytest.raises(dataclasses.FrozenInstanceError):
        GovernorSettings().safety_factor = 2.0  # type: ignore[misc]
    decision = GovernorDecision(1.0)
    assert (decision.mode_request, decision.beyond_margin) == (None, False)
    with pytest.raises(dataclasses.FrozenInstanceError):
        decision.gain_k = 2.0  # type: ignore[misc]
    governor = MarginGovernor(GovernorSettings(), TABLE)
    assert governor.tdpa_available is False and governor.invalid_echoes == 0


@pytest.mark.parametrize("changes", [
    {"safety_factor": 1.0, "urgent_factor": 1.0}, {"safety_factor": 1e-9},
    {"safety_factor": 0.8, "urgent_factor": 0.8}, {"confirm_s": 0.0}, {"confirm_s": 1.0},
])
def test_the_settings_take_their_bounds(changes) -> None:
    assert GovernorSettings(**changes) is not None


@pytest.mark.parametrize("changes, words", [
    ({"safety_factor": 0.0}, "^safety_factor"),
    ({"safety_factor": 1.0 + 1e-9, "urgent_factor": 1.0 + 1e-9}, "^safety_factor"),
    ({"urgent_factor": 0.7 - 1e-9}, "urgent_factor"),
    ({"urgent_factor": 1.0 + 1e-9}, "urgent_factor"), ({"confirm_s": -1e-9}, "confirm_s"),
    ({"confirm_s": 1.0 + 1e-9}, "confirm_s"), ({"ramp_time_s": 0.0}, "ramp_time_s"),
    ({"hold_s": 0.0}, "hold_s"),
])
def test_the_settings_refuse_beyond_their_bounds(changes, words) -> None:
    with pytest.raises(ValueError, match=words):
        GovernorSettings(**changes)


def test_the_peak_keeps_a_sample_exactly_one_window_old() -> None:
    peak = _Peak(1.0)
    assert peak.add(0.0, 5.0) == 5.0
    assert peak.add(1.0, 1.0) == 5.0  # 1 s old: still in the window
    assert peak.add(1.0 + 1e-6, 1.0) == 1.0


def test_a_round_trip_at_the_safety_factor_is_usable() -> None:
    governor = MarginGovernor(GovernorSettings(), TABLE)
    tie = governor.settings.safety_factor * TABLE.margin_s(13.0)
    assert governor.usable(13.0, tie) and not governor.usable(13.0, math.nextafter(tie, 1.0))


def test_a_gain_within_the_snap_is_the_same_gain() -> None:
    table = table_from_pairs([(10.0 * (1.0 + _SNAP), 0.01), (10.0, 0.02)])
    assert MarginGovernor(GovernorSettings(), table)._step_up(10.0) is None
    table = table_from_pairs([(10.0 * (1.0 + 2 * _SNAP), 0.01), (10.0, 0.02)])
    assert MarginGovernor(GovernorSettings(), table)._step_up(10.0) == 10.0 * (1 + 2 * _SNAP)


def test_the_first_tick_and_a_tick_back_in_time_move_nothing() -> None:
    governor = MarginGovernor(GovernorSettings(), TABLE)
    governor.target_k = 8.32  # a lowering under way
    assert governor.update(5.0, None).gain_k == 13.0  # no time has passed yet
    assert governor.update(4.0, None).gain_k == 13.0  # a clock that went back: none
    moved = governor.update(4.0 + TS, None).gain_k
    assert moved == pytest.approx(13.0 + (8.32 - 13.0) * (1 - math.exp(-4 * TS / 0.1)))


def test_beyond_every_margin_the_target_is_the_lowest_gain_and_the_event_says_so() -> None:
    governor = MarginGovernor(GovernorSettings(), FINITE)
    decision = governor.update(0.0, 0.080)
    assert governor.target_k == 8.32 and decision.beyond_margin
    assert [event["reason"] for event in governor.events] == [
        "round trip 80.0 ms > 0.9 x tau*(13) = 14.3 ms: k 13 -> 8.32",
        "round trip 80.0 ms beyond tau* of every k down to 8.32 (60.0 ms)"]
    assert governor.summary()["governor_min_k"] == 13.0  # not moved yet
    governor.update(1.0, 0.080)
    assert governor.gain_k == 8.32 and governor.summary()["governor_min_k"] == 8.32


def test_beyond_starts_at_the_lowest_gains_margin_itself() -> None:
    governor = MarginGovernor(GovernorSettings(), FINITE)
    assert governor.update(0.0, FINITE.margin_s(8.32)).beyond_margin
    assert not MarginGovernor(GovernorSettings(), FINITE).update(
        0.0, math.nextafter(FINITE.margin_s(8.32), 0.0)).beyond_margin


def test_at_the_urgent_factor_itself_it_waits_confirm_s_and_says_for_how_long() -> None:
    settings = GovernorSettings(confirm_s=0.6)
    governor = MarginGovernor(settings, LONG)
    tie = settings.urgent_factor * LONG.margin_s(13.0)  # not above it: not urgent
    governor.update(0.0, tie)
    assert governor.target_k == 13.0 and not governor.events
    governor.update(0.3, tie)
    assert governor.target_k == 13.0
    governor.update(0.6, tie)  # confirm_s exactly
    assert governor.target_k == 10.4
    assert governor.events == [{"time_s": 0.6, "kind": "governor_lower_k", "reason":
                                "round trip 90.0 ms > 0.7 x tau*(13) = 100.0 ms for 600 ms: "
                                "k 13 -> 10.4"}]


def test_recover_after_s_of_zero_never_raises_k() -> None:
    governor = MarginGovernor(GovernorSettings(recover_after_s=0.0, hold_s=0.1), TABLE)
    governor.update(0.0, 0.042)
    for tick in range(1, 2000):
        governor.update(tick * 0.01, 0.004)
    assert governor.target_k == 8.32 and len(governor.events) == 1


def test_k_is_raised_at_exactly_recover_after_s_and_the_event_says_why() -> None:
    governor = MarginGovernor(GovernorSettings(hold_s=0.25, recover_after_s=0.5), LONG)
    governor.update(0.0, 0.3)  # urgent: down to 8.32
    governor.update(0.5, 0.3)  # k there (the lag's 0.5 s)
    governor.update(1.0, 0.12)  # the peak over 0.25 s allows 10.4 from here
    assert governor.target_k == 8.32
    governor.update(1.5, 0.12)  # recover_after_s later, exactly
    assert governor.target_k == 10.4
    assert governor.events[-1] == {
        "time_s": 1.5, "kind": "governor_raise_k", "reason":
        "peak round trip 120.0 ms over 0.25 s allows k 10.4 (tau* 200.0 ms): k 8.32 -> 10.4"}


def test_the_paper_request_clears_the_tdpa_request_and_says_why() -> None:
    settings = GovernorSettings(action="tdpa", hold_s=0.25, recover_after_s=0.5)
    governor = MarginGovernor(settings, LONG, tdpa_available=True)
    assert governor.update(0.0, 0.3).mode_request == "tdpa"
    assert governor.status() == "  gov k 13 rtt 300.0 ms TDPA"
    assert governor.update(1.0, 0.06).mode_request is None
    assert governor.update(1.5, 0.06).mode_request == "paper"
    assert governor.tdpa_requested is False
    assert governor.summary()["governor_tdpa_requested"] is False
    assert governor.events[-1]["reason"] == "peak round trip 60.0 ms allows k 13 again"
    assert governor.status() == "  gov k 13 rtt 60.0 ms"


def test_a_gain_exactly_the_snap_from_its_target_is_the_target() -> None:
    """Within ``_SNAP`` of its target (the tie included) k is the target: the ramp snaps it
    there and the status line shows no change under way."""
    governor = MarginGovernor(GovernorSettings(), TABLE)
    governor.target_k = EXACT_K
    governor.gain_k = EXACT_K + _SNAP * EXACT_K
    assert abs(governor.gain_k - EXACT_K) == _SNAP * EXACT_K  # the tie, exactly
    assert governor.status() == "  gov k 9.13 rtt -"
    governor.update(0.0, None)  # no time passes: only the snap
    assert governor.gain_k == EXACT_K


def test_the_status_line() -> None:
    governor = MarginGovernor(GovernorSettings(), TABLE)
    assert governor.status() == "  gov k 13 rtt -"
    governor.update(0.0, 0.004)
    assert governor.status() == "  gov k 13 rtt 4.0 ms"
    governor.update(TS, 0.042)
    governor.update(2 * TS, 0.042)
    assert governor.status() == "  gov k 12.8->8.32 rtt 42.0 ms"
    governor.update(10.0, 0.042)
    assert governor.status() == "  gov k 8.32 rtt 42.0 ms"


def test_governor_for_checks_the_design_unless_it_runs_tdpa(paper_config) -> None:
    governor = governor_for(model_from_config(paper_config), paper_config)
    assert governor.tdpa_available is False and governor.nominal_k == 1.0
    # a compliance that rolls off as fast as Gh: the design is not linear in k
    config = override(paper_config, "model.x.handle_compliance_sh_num", [1e-4])
    config = override(config, "model.x.handle_compliance_sh_den", [1e-4, 0.02, 1.0])
    model = model_from_config(config)
    with pytest.raises(ConfigError, match=r"governor\.action"):
        governor_for(model, config)
    tdpa = override(config, "governor.action", "tdpa")
    with pytest.raises(ConfigError, match=r"governor\.action"):
        governor_for(model, tdpa)  # tdpa asked, but the caller cannot run it: lowers k
    assert governor_for(model, tdpa, tdpa_available=True).tdpa_available


def test_load_config_governor_is_off() -> None:
    assert GovernorSettings.from_config(load_config()).enabled is False
