"""The slave's node steps follow the master's samples, not its own ticks (slave_sim/pacing.py)."""

from __future__ import annotations

import pytest

from haptic.common.config import ConfigError, load_config
from haptic.slave_sim.pacing import MasterSamplePacing, PacingSettings


def _pacing(limit: int = 4) -> MasterSamplePacing:
    return MasterSamplePacing(PacingSettings(True, limit))


def test_one_step_per_master_sample_when_the_master_ticks_at_half_the_rate() -> None:
    pacing = _pacing()
    steps = []
    for tick in range(200):  # a new sample every second tick of the slave
        sample = (7, tick // 2) if tick % 2 == 0 else None
        steps.append(pacing.steps(True, sample))
    assert sum(steps) == 100  # one per sample: nothing integrated twice
    assert steps[:4] == [1, 0, 1, 0]
    assert pacing.waited_ticks == 100 and pacing.caught_up_steps == 0


def test_a_gap_in_the_sequence_is_caught_up_in_one_tick() -> None:
    pacing = _pacing()
    assert pacing.steps(True, (1, 10)) == 1
    assert pacing.steps(True, (1, 11)) == 1
    assert pacing.steps(True, (1, 14)) == 3  # two lost or bunched, then this one
    assert pacing.caught_up_steps == 2 and pacing.dropped_samples == 0


def test_what_one_tick_cannot_take_is_owed_to_the_next_ticks() -> None:
    pacing = _pacing(limit=4)
    pacing.steps(True, (1, 0))
    assert pacing.steps(True, (1, 10)) == 4  # ten samples on: four now, six owed
    assert pacing.backlog == 6 and pacing.dropped_samples == 0
    assert pacing.steps(True, None) == 4  # no new sample: the backlog is taken
    assert pacing.steps(True, (1, 11)) == 3  # two owed and the new one
    assert pacing.steps(True, None) == 0 and pacing.waited_ticks == 1
    # every sample 0..11 stepped exactly once: 1 + 4 + 4 + 3
    assert pacing.caught_up_steps == 3 + 4 + 2 and pacing.max_backlog == 6


def test_the_backlog_is_bounded_and_what_it_gives_up_is_counted() -> None:
    pacing = MasterSamplePacing(PacingSettings(True, 4, max_backlog_samples=3))
    pacing.steps(True, (1, 0))
    assert pacing.steps(True, (1, 20)) == 4  # 20 on: 4 now, 3 owed, 13 given up
    assert pacing.backlog == 3 and pacing.dropped_samples == 13
    assert pacing.steps(True, (1, 21)) == 4 and pacing.backlog == 0
    assert pacing.max_backlog == 3


def test_a_halt_or_a_new_epoch_clears_the_backlog() -> None:
    pacing = _pacing(limit=2)
    pacing.steps(True, (1, 0))
    pacing.steps(True, (1, 9))
    assert pacing.backlog == 7
    assert pacing.steps(False, None) == 1 and pacing.backlog == 0
    pacing.steps(True, (1, 10))
    pacing.steps(True, (1, 19))
    assert pacing.backlog == 7
    assert pacing.steps(True, (2, 0)) == 1 and pacing.backlog == 0


def test_halted_tool_steps_every_tick_and_the_count_restarts() -> None:
    pacing = _pacing()
    assert pacing.steps(False, None) == 1
    assert pacing.steps(False, (1, 5)) == 1
    assert pacing.steps(False, None) == 1
    # resumed: counts from the last sample seen while halted
    assert pacing.steps(True, (1, 6)) == 1
    assert pacing.steps(True, None) == 0
    # resumed after a silence: the first sample steps once, never a burst
    pacing = _pacing()
    pacing.steps(False, (1, 5))
    pacing.steps(False, None)
    assert pacing.steps(True, (1, 40)) == 1
    assert pacing.caught_up_steps == 0 and pacing.dropped_samples == 0


def test_a_new_epoch_or_a_stale_sequence_never_steps_backwards_or_bursts() -> None:
    pacing = _pacing()
    pacing.steps(True, (1, 100))
    assert pacing.steps(True, (2, 0)) == 1  # the master restarted
    assert pacing.steps(True, (2, 0)) == 0  # the same sample again
    assert pacing.steps(True, (2, 1)) == 1


def test_warm_start_running_without_a_sample_steps() -> None:
    pacing = _pacing()
    assert pacing.steps(True, None) == 1
    assert pacing.waited_ticks == 0


def test_off_steps_once_per_tick() -> None:
    pacing = MasterSamplePacing(PacingSettings(False, 4))
    assert [pacing.steps(True, s) for s in ((1, 0), None, (1, 5))] == [1, 1, 1]
    assert pacing.summary()["pacing_follow_master_samples"] is False


def test_settings_come_from_the_configuration() -> None:
    config = load_config(None)
    assert PacingSettings.from_config(config) == PacingSettings(True, 4, 32)


def test_an_invalid_catch_up_bound_is_refused(tmp_path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text("[slave.pacing]\nmax_steps_per_tick = 0\n")
    with pytest.raises(ConfigError, match="slave.pacing.max_steps_per_tick"):
        load_config(path)
