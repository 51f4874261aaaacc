"""The margin governor as a pure block: its round-trip estimate and its decisions."""

from __future__ import annotations

import math

import pytest

from haptic.common.analysis.margin_table import build_margin_table, gain_scalable, table_from_pairs
from haptic.master.margin_governor import GovernorSettings, MarginGovernor

TS = 0.00054
# the paper's loop, sampled (haptic-analyze --sampled-analysis): tau*(13) 14.3 ms, k <= 8.5
# stable for every delay
TABLE = table_from_pairs([(13.0, 0.0143), (10.4, 0.0228), (8.32, None)])


def _run(governor: MarginGovernor, rtt_of_time, until_s: float, start_s: float = 0.0):
    decision = None
    t = start_s
    while t < until_s:
        decision = governor.update(t, rtt_of_time(t))
        t += TS
    return decision


def test_the_usable_gain_is_the_largest_within_the_safety_factor() -> None:
    governor = MarginGovernor(GovernorSettings(safety_factor=0.7), TABLE)
    assert governor.best_gain(0.005) == 13.0  # 5 ms <= 0.7 x 14.3 ms
    assert governor.best_gain(0.0105) == 10.4  # > 10.0 ms, <= 0.7 x 22.8 = 16.0 ms
    assert governor.best_gain(0.5) == 8.32  # delay-independent
    assert TABLE.margin_s(9.0) == pytest.approx(0.0228)  # between entries: the higher one's


def test_steady_small_round_trip_keeps_the_nominal_gain_and_no_event() -> None:
    governor = MarginGovernor(GovernorSettings(), TABLE)
    decision = _run(governor, lambda t: 0.004, 2.0)
    assert decision.gain_k == 13.0 and not governor.events
    assert governor.rtt_s == pytest.approx(0.004)


def test_no_echo_yet_changes_nothing() -> None:
    governor = MarginGovernor(GovernorSettings(), TABLE)
    assert governor.update(0.0, None).gain_k == 13.0 and math.isnan(governor.rtt_s)


def test_a_step_in_the_round_trip_lowers_k_smoothly_to_a_usable_gain() -> None:
    settings = GovernorSettings(ramp_time_s=0.1, recover_after_s=0.0)
    governor = MarginGovernor(settings, TABLE)
    gains = []
    t = 0.0
    while t < 1.0:
        rtt = 0.004 if t < 0.5 else 0.042
        gains.append(governor.update(t, rtt).gain_k)
        t += TS
    assert gains[0] == 13.0 and gains[-1] == 8.32
    steps = [abs(b - a) for a, b in zip(gains, gains[1:], strict=False)]
    # no jump: the largest change per tick is the lag's first, 2 % of the way (0.1 of 4.68)
    assert max(steps) == pytest.approx((13.0 - 8.32) * (1 - math.exp(-4 * TS / 0.1)))
    assert max(steps) < 0.11
    after_ramp = gains[int((0.5 + settings.ramp_time_s) / TS) + 2]
    assert 8.32 < after_ramp < 8.32 + 0.02 * (13.0 - 8.32)  # 98 % of the way in ramp_time_s
    reached = next(i for i, g in enumerate(gains) if g == 8.32) * TS
    assert 0.5 + settings.ramp_time_s < reached < 0.5 + 3 * settings.ramp_time_s
    assert [e["kind"] for e in governor.events] == ["governor_lower_k"]
    assert "42.0 ms" in governor.events[0]["reason"]
    assert "k 8.32" in governor.status() and "42.0 ms" in governor.status()


def test_it_acts_before_the_margin_on_a_slow_ramp() -> None:
    governor = MarginGovernor(GovernorSettings(safety_factor=0.7), TABLE)
    lowered_at = None
    t = 0.0
    while t < 2.0:
        rtt = 0.004 + 0.01 * t  # +10 ms per second
        decision = governor.update(t, rtt)
        if lowered_at is None and governor.target_k < 13.0:
            lowered_at = rtt
        t += TS
    assert lowered_at is not None and lowered_at < 0.0143  # before tau*(13)
    # confirm_s (20 ms) after the ramp passed 0.7 tau*: 0.2 ms further up it
    assert lowered_at == pytest.approx(0.7 * 0.0143 + 0.01 * 0.02, abs=1e-4)
    assert decision.gain_k < 13.0


def test_k_goes_back_up_one_step_after_the_peak_allowed_it_long_enough() -> None:
    settings = GovernorSettings(hold_s=0.5, recover_after_s=1.0)
    governor = MarginGovernor(settings, TABLE)
    _run(governor, lambda t: 0.042 if t < 1.0 else 0.004, 1.2)
    assert governor.target_k == 8.32
    _run(governor, lambda t: 0.004, 2.4, start_s=1.2)  # peak still high until 1.5 s
    assert governor.target_k == 8.32
    _run(governor, lambda t: 0.004, 2.6, start_s=2.4)  # allowed from 1.5 s, 1 s later
    assert governor.target_k == 10.4
    _run(governor, lambda t: 0.004, 4.0, start_s=2.6)
    assert governor.gain_k == 13.0
    assert [e["kind"] for e in governor.events] == [
        "governor_lower_k", "governor_raise_k", "governor_raise_k"]


def test_a_growing_silence_counts_as_a_growing_round_trip() -> None:
    governor = MarginGovernor(GovernorSettings(), TABLE)
    # the newest tool message echoes a handle sent at 1.0 s: its age grows until one comes
    _run(governor, lambda t: t - 1.0 + 0.004 if t >= 1.0 else 0.004, 1.03)
    assert governor.target_k < 13.0


def test_tdpa_action_requests_the_mode_once_and_keeps_k() -> None:
    settings = GovernorSettings(action="tdpa", recover_after_s=0.5, hold_s=0.2)
    governor = MarginGovernor(settings, TABLE, tdpa_available=True)
    requests = []
    t = 0.0
    while t < 2.0:
        decision = governor.update(t, 0.042 if t < 1.0 else 0.004)
        if decision.mode_request:
            requests.append((round(t, 2), decision.mode_request))
        assert decision.gain_k == 13.0 and not decision.beyond_margin
        t += TS
    assert [r[1] for r in requests] == ["tdpa", "paper"]
    assert requests[1][0] >= 1.0 + 0.2 + 0.5 - 0.01


def test_tdpa_action_without_the_mode_lowers_k_and_says_so() -> None:
    governor = MarginGovernor(GovernorSettings(action="tdpa"), TABLE, tdpa_available=False)
    _run(governor, lambda t: 0.042, 0.5)
    assert governor.gain_k == 8.32
    assert "no tdpa mode" in governor.events[0]["reason"]


def test_beyond_every_margin_is_flagged_once() -> None:
    table = table_from_pairs([(13.0, 0.0143), (4.0, 0.050)])
    governor = MarginGovernor(GovernorSettings(), table)
    decision = _run(governor, lambda t: 0.060, 0.5)
    assert decision.beyond_margin and governor.target_k == 4.0
    assert [e["kind"] for e in governor.events] == ["governor_lower_k",
                                                    "governor_beyond_margin"]
    assert "BEYOND" in governor.status()
    assert governor.summary()["governor_beyond_margin"] is True


def test_bad_settings_are_refused() -> None:
    with pytest.raises(ValueError, match="action"):
        GovernorSettings(action="wave")
    with pytest.raises(ValueError, match="safety_factor"):
        GovernorSettings(safety_factor=1.5)


def test_the_paper_table_from_the_sampled_analysis(paper_config, paper_model) -> None:
    model = paper_model.with_gain(13.0)
    assert gain_scalable(model)
    table = build_margin_table(model, paper_config["analysis"], min_gain_k=1.0,
                               step_ratio=0.8)
    gains = [e.k for e in table.entries]
    assert gains[0] == 13.0 and gains[1] == pytest.approx(10.4)
    assert table.entries[0].delay_margin_s == pytest.approx(0.0143, abs=3e-4)
    assert table.entries[-1].delay_margin_s is None  # stops at the first delay-independent k
    assert table.entries[-1].k < 8.6


def test_a_blip_below_the_urgent_factor_shorter_than_confirm_s_changes_nothing() -> None:
    """A scheduling blip: the round trip at 11-12 ms (above 0.7 tau*(13) = 10.0 ms, below
    0.9 tau* = 12.9 ms) for 15 ms, twice, on a steady 4.5 ms: no event, k and mode kept."""
    for action, available in (("lower_k", False), ("tdpa", True)):
        governor = MarginGovernor(GovernorSettings(action=action, confirm_s=0.02), TABLE,
                                  tdpa_available=available)

        def blips(t: float) -> float:
            return 0.0115 if (0.5 <= t < 0.515 or 1.0 <= t < 1.015) else 0.0045

        decision = _run(governor, blips, 2.0)
        assert decision.gain_k == 13.0 and decision.mode_request is None
        assert not governor.events and not governor.tdpa_requested
        assert governor.max_rtt_s == pytest.approx(0.0115)


def test_a_round_trip_held_in_the_band_is_acted_on_after_confirm_s() -> None:
    """11.5 ms from 0.5 s on: the governor lowers k confirm_s later, not before."""
    governor = MarginGovernor(GovernorSettings(confirm_s=0.02), TABLE)
    _run(governor, lambda t: 0.0115 if t >= 0.5 else 0.0045, 0.5 + 0.02 - TS)
    assert not governor.events and governor.target_k == 13.0
    _run(governor, lambda t: 0.0115, 0.5 + 0.02 + 2 * TS, start_s=0.5 + 0.02 - TS)
    assert [e["kind"] for e in governor.events] == ["governor_lower_k"]
    assert governor.events[0]["time_s"] == pytest.approx(0.52, abs=2 * TS)
    assert "0.7 x tau*(13)" in governor.events[0]["reason"]
    held_ms = float(governor.events[0]["reason"].split(" for ")[1].split(" ms")[0])
    assert 20.0 <= held_ms < 20.0 + 2 * TS * 1e3
    assert governor.target_k == 10.4


def test_above_the_urgent_factor_it_acts_at_once() -> None:
    """A jump to 42 ms: acted on at the first tick that sees it, whatever confirm_s."""
    settings = GovernorSettings(action="tdpa", confirm_s=1.0, recover_after_s=0.0)
    governor = MarginGovernor(settings, TABLE, tdpa_available=True)
    first = None
    t = 0.0
    while t < 0.6 and first is None:
        if governor.update(t, 0.042 if t >= 0.5 else 0.0045).mode_request == "tdpa":
            first = t
        t += TS
    assert first is not None and first - 0.5 < TS
    assert "42.0 ms > 0.9 x tau*(13)" in governor.events[0]["reason"]


def test_urgent_factor_and_confirm_s_are_checked() -> None:
    with pytest.raises(ValueError, match="urgent_factor"):
        GovernorSettings(safety_factor=0.7, urgent_factor=0.6)
    with pytest.raises(ValueError, match="urgent_factor"):
        GovernorSettings(urgent_factor=1.1)
    with pytest.raises(ValueError, match="confirm_s"):
        GovernorSettings(confirm_s=-0.01)
