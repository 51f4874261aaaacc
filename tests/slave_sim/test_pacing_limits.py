"""The slave's sample pacing at exact values (slave_sim/pacing.py): its shipped settings, a
tick whose only sample is old (nothing queued, the backlog still taken), the counters of the
first sample and of a one-sample gap, the interpolated values of every field, and a burst of
exactly one step. tests/slave_sim/test_pacing.py covers the behaviour over runs."""

from __future__ import annotations

import dataclasses

import pytest

from haptic.common.config import load_config
from haptic.slave_sim.pacing import MasterSamplePacing, PacingSettings, Sample


def sample(seq: int, force_N: float = 0.0, position_m: float = 0.0, scale: float = 1.0,
           epoch: int = 1) -> Sample:
    return (epoch, seq, (force_N, -force_N), (position_m, -position_m), scale)


def counters(pacing: MasterSamplePacing) -> dict[str, int]:
    return {k: v for k, v in pacing.summary().items() if k != "pacing_follow_master_samples"}


def test_the_shipped_settings_and_a_fresh_pacing() -> None:
    assert PacingSettings() == PacingSettings(True, 4, 32)
    assert PacingSettings.from_config(load_config()) == PacingSettings()
    with pytest.raises(dataclasses.FrozenInstanceError):
        PacingSettings().max_steps_per_tick = 1  # type: ignore[misc]
    pacing = MasterSamplePacing(PacingSettings())
    assert pacing.backlog == 0 and set(counters(pacing).values()) == {0}
    assert pacing.summary()["pacing_follow_master_samples"] is True


def test_the_first_sample_is_the_ticks_own_step() -> None:
    pacing = MasterSamplePacing(PacingSettings())
    assert pacing.plan(True, [sample(7, 1.0, 0.01)]) == [(1.0, -1.0, 0.01, -0.01, 1.0)]
    assert counters(pacing)["pacing_caught_up_steps"] == 0
    assert counters(pacing)["pacing_max_tick_steps"] == 1


def test_a_tick_whose_only_sample_is_old_queues_nothing_and_counts_nothing() -> None:
    pacing = MasterSamplePacing(PacingSettings())
    pacing.plan(True, [sample(7)])
    before = counters(pacing)
    for seq in (7, 6):
        assert pacing.plan(True, [sample(seq)]) == []
    assert counters(pacing) == before and pacing.backlog == 0


def test_an_old_sample_still_lets_the_backlog_be_taken() -> None:
    pacing = MasterSamplePacing(PacingSettings(True, 2, 32))
    pacing.plan(True, [sample(1)])
    assert len(pacing.plan(True, [sample(6)])) == 2  # 5 owed, 2 taken
    assert pacing.backlog == 3
    caught_up = counters(pacing)["pacing_caught_up_steps"]
    assert len(pacing.plan(True, [sample(6)])) == 2  # nothing new: both caught up
    assert pacing.backlog == 1
    assert counters(pacing)["pacing_caught_up_steps"] == caught_up + 2


def test_a_one_sample_gap_is_interpolated_in_every_field() -> None:
    pacing = MasterSamplePacing(PacingSettings())
    pacing.plan(True, [sample(10, 1.0, 0.01, 0.5)])
    steps = pacing.plan(True, [sample(12, 3.0, 0.03, 1.0)])
    assert steps == [pytest.approx((2.0, -2.0, 0.02, -0.02, 0.75), rel=1e-12),
                     (3.0, -3.0, 0.03, -0.03, 1.0)]
    assert counters(pacing) == {
        "pacing_waited_ticks": 0, "pacing_caught_up_steps": 1, "pacing_interpolated_steps": 1,
        "pacing_dropped_samples": 0, "pacing_burst_steps": 0, "pacing_max_tick_steps": 2,
        "pacing_max_backlog_samples": 0}


def test_a_backlog_one_beyond_its_bound_takes_one_more_step() -> None:
    pacing = MasterSamplePacing(PacingSettings(True, 2, 2))
    pacing.plan(True, [sample(1)])
    assert len(pacing.plan(True, [sample(5)])) == 2  # 4 owed: 2 taken, 2 may wait
    assert pacing.backlog == 2 and counters(pacing)["pacing_burst_steps"] == 0
    steps = pacing.plan(True, [sample(8)])  # 2 + 3 owed: 2 a tick, 2 may wait, 1 more now
    assert len(steps) == 3 and pacing.backlog == 2
    assert counters(pacing)["pacing_burst_steps"] == 1
    assert counters(pacing)["pacing_max_tick_steps"] == 3
    assert counters(pacing)["pacing_max_backlog_samples"] == 2
    assert counters(pacing)["pacing_dropped_samples"] == 0
