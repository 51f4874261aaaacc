"""Per-stage tick timing: durations between the marks, percentiles, tick order kept."""

from __future__ import annotations

import json

import pytest

from haptic.common.runtime.stage_times import StageTimes, format_stages, in_tick_order


def test_stages_are_the_differences_between_consecutive_marks() -> None:
    stages = StageTimes(("read", "node", "send"))
    for tick in range(100):
        start = tick * 1_000_000
        stages.record(start, (start + 10_000, start + 15_000, start + 45_000 + tick * 10))
    summary = stages.summary()
    assert stages.ticks == 100
    assert summary["read"]["p50_s"] == pytest.approx(10e-6, rel=0.01)
    assert summary["node"]["p99_s"] == pytest.approx(5e-6, rel=0.01)
    assert summary["send"]["max_s"] == pytest.approx(30e-6 + 990e-9)
    assert summary["send"]["mean_s"] == pytest.approx(30e-6 + 495e-9)


def test_tick_order_survives_a_json_round_trip_with_sorted_keys() -> None:
    stages = StageTimes(("write", "poll", "node"))
    stages.record(0, (1_000, 3_000, 6_000))
    restored = json.loads(json.dumps(stages.summary(), sort_keys=True))
    assert list(restored) == ["node", "poll", "write"]
    assert [name for name, _ in in_tick_order(restored)] == ["write", "poll", "node"]
    assert format_stages(restored).startswith("write 1.0/1.0  poll 2.0/2.0  node 3.0/3.0")


def test_a_mark_count_that_does_not_match_the_stages_is_refused() -> None:
    stages = StageTimes(("a", "b"))
    with pytest.raises(ValueError):
        stages.record(0, (1, 2, 3))
    with pytest.raises(ValueError):
        StageTimes(())
