"""The slave's node steps follow the master's samples, not its own ticks (slave_sim/pacing.py)."""

from __future__ import annotations

import pytest

from haptic.common.config import ConfigError, load_config
from haptic.slave_sim.pacing import MasterSamplePacing, PacingSettings, Sample


def _pacing(limit: int = 4) -> MasterSamplePacing:
    return MasterSamplePacing(PacingSettings(True, limit))


def _sample(epoch: int, seq: int, force_N: float = 0.0, position_m: float = 0.0,
            scale: float = 1.0) -> Sample:
    return (epoch, seq, (force_N, -force_N), (position_m, -position_m), scale)


def _steps(pacing: MasterSamplePacing, running: bool, sample: tuple[int, int] | None) -> int:
    """The number of node steps for a tick with at most one sample (its id), zero force."""
    return len(pacing.plan(running, [] if sample is None else [_sample(*sample)]))


def test_one_step_per_master_sample_when_the_master_ticks_at_half_the_rate() -> None:
    pacing = _pacing()
    steps = []
    for tick in range(200):  # a new sample every second tick of the slave
        sample = (7, tick // 2) if tick % 2 == 0 else None
        steps.append(_steps(pacing, True, sample))
    assert sum(steps) == 100  # one per sample: nothing integrated twice
    assert steps[:4] == [1, 0, 1, 0]
    assert pacing.waited_ticks == 100 and pacing.caught_up_steps == 0


def test_a_gap_in_the_sequence_is_caught_up_in_one_tick() -> None:
    pacing = _pacing()
    assert _steps(pacing, True, (1, 10)) == 1
    assert _steps(pacing, True, (1, 11)) == 1
    assert _steps(pacing, True, (1, 14)) == 3  # two lost or bunched, then this one
    assert pacing.caught_up_steps == 2 and pacing.dropped_samples == 0


def test_what_one_tick_cannot_take_is_owed_to_the_next_ticks() -> None:
    pacing = _pacing(limit=4)
    _steps(pacing, True, (1, 0))
    assert _steps(pacing, True, (1, 10)) == 4  # ten samples on: four now, six owed
    assert pacing.backlog == 6 and pacing.dropped_samples == 0
    assert _steps(pacing, True, None) == 4  # no new sample: the backlog is taken
    assert _steps(pacing, True, (1, 11)) == 3  # two owed and the new one
    assert _steps(pacing, True, None) == 0 and pacing.waited_ticks == 1
    # every sample 0..11 stepped exactly once: 1 + 4 + 4 + 3
    assert pacing.caught_up_steps == 3 + 4 + 2 and pacing.max_backlog == 6


def test_the_backlog_is_bounded_and_what_it_gives_up_is_counted() -> None:
    pacing = MasterSamplePacing(PacingSettings(True, 4, max_backlog_samples=3))
    _steps(pacing, True, (1, 0))
    assert _steps(pacing, True, (1, 20)) == 4  # 20 on: 4 now, 3 owed, 13 given up
    assert pacing.backlog == 3 and pacing.dropped_samples == 13
    assert _steps(pacing, True, (1, 21)) == 4 and pacing.backlog == 0
    assert pacing.max_backlog == 3


def test_a_halt_or_a_new_epoch_clears_the_backlog() -> None:
    pacing = _pacing(limit=2)
    _steps(pacing, True, (1, 0))
    _steps(pacing, True, (1, 9))
    assert pacing.backlog == 7
    assert _steps(pacing, False, None) == 1 and pacing.backlog == 0
    _steps(pacing, True, (1, 10))
    _steps(pacing, True, (1, 19))
    assert pacing.backlog == 7
    assert _steps(pacing, True, (2, 0)) == 1 and pacing.backlog == 0


def test_halted_tool_steps_every_tick_and_the_count_restarts() -> None:
    pacing = _pacing()
    assert _steps(pacing, False, None) == 1
    assert _steps(pacing, False, (1, 5)) == 1
    assert _steps(pacing, False, None) == 1
    # resumed: counts from the last sample seen while halted
    assert _steps(pacing, True, (1, 6)) == 1
    assert _steps(pacing, True, None) == 0
    # resumed after a silence: the first sample steps once, never a burst
    pacing = _pacing()
    _steps(pacing, False, (1, 5))
    _steps(pacing, False, None)
    assert _steps(pacing, True, (1, 40)) == 1
    assert pacing.caught_up_steps == 0 and pacing.dropped_samples == 0


def test_a_new_epoch_or_a_stale_sequence_never_steps_backwards_or_bursts() -> None:
    pacing = _pacing()
    _steps(pacing, True, (1, 100))
    assert _steps(pacing, True, (2, 0)) == 1  # the master restarted
    assert _steps(pacing, True, (2, 0)) == 0  # the same sample again
    assert _steps(pacing, True, (2, 1)) == 1


def test_warm_start_running_without_a_sample_steps() -> None:
    pacing = _pacing()
    assert _steps(pacing, True, None) == 1
    assert pacing.waited_ticks == 0


def test_off_steps_once_per_tick() -> None:
    pacing = MasterSamplePacing(PacingSettings(False, 4))
    assert [_steps(pacing, True, s) for s in ((1, 0), None, (1, 5))] == [1, 1, 1]
    assert pacing.plan(True, [_sample(1, 6, 3.0)]) == [None]  # the tick's own input
    assert pacing.summary()["pacing_follow_master_samples"] is False


def test_settings_come_from_the_configuration() -> None:
    config = load_config(None)
    assert PacingSettings.from_config(config) == PacingSettings(True, 4, 32)


def test_an_invalid_catch_up_bound_is_refused(tmp_path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text("[slave.pacing]\nmax_steps_per_tick = 0\n")
    with pytest.raises(ConfigError, match="slave.pacing.max_steps_per_tick"):
        load_config(path)


def test_each_sample_delivered_in_one_tick_is_stepped_with_its_own_force() -> None:
    pacing = _pacing()
    assert pacing.plan(True, [_sample(1, 0, 1.0, 0.01)]) == [(1.0, -1.0, 0.01, -0.01, 1.0)]
    # three samples bunched by jitter into one tick: three steps, in order, each its own
    plan = pacing.plan(True, [_sample(1, 1, 2.0, 0.02), _sample(1, 2, 3.0, 0.03),
                              _sample(1, 3, 4.0, 0.04)])
    assert [step[0] for step in plan] == [2.0, 3.0, 4.0]
    assert [step[2] for step in plan] == [0.02, 0.03, 0.04]
    assert pacing.interpolated_steps == 0 and pacing.caught_up_steps == 2


def test_a_lost_sample_is_stepped_with_the_force_between_its_neighbours() -> None:
    pacing = _pacing()
    pacing.plan(True, [_sample(1, 10, 1.0, 0.0, scale=0.2)])
    plan = pacing.plan(True, [_sample(1, 14, 5.0, 0.004, scale=0.6)])  # 11, 12, 13 lost
    # each step flattened to numbers: pytest.approx documents flat sequences of numbers,
    # not sequences of tuples (pytest 9.2 refuses the nested form)
    stepped = [number for step in plan for number in step]
    assert stepped == pytest.approx([2.0, -2.0, 0.001, -0.001, 0.3,
                                     3.0, -3.0, 0.002, -0.002, 0.4,
                                     4.0, -4.0, 0.003, -0.003, 0.5,
                                     5.0, -5.0, 0.004, -0.004, 0.6])
    assert all(len(step) == 5 for step in plan)
    assert pacing.interpolated_steps == 3 and pacing.dropped_samples == 0
    assert pacing.caught_up_steps == 3


def test_a_full_backlog_is_taken_at_once_in_order_and_nothing_is_given_up() -> None:
    pacing = MasterSamplePacing(PacingSettings(True, 2, max_backlog_samples=2))
    pacing.plan(True, [_sample(1, 0, 0.0)])
    plan = pacing.plan(True, [_sample(1, seq, float(seq)) for seq in range(1, 8)])
    # 7 samples delivered: 2 steps as usual, 3 more at once (the backlog holds 2), 2 owed
    assert [step[0] for step in plan] == [1.0, 2.0, 3.0, 4.0, 5.0]
    assert pacing.dropped_samples == 0 and pacing.backlog == 2
    assert pacing.burst_steps == 3 and pacing.max_tick_steps == 5
    assert [step[0] for step in pacing.plan(True, [])] == [6.0, 7.0]
    assert pacing.summary()["pacing_burst_steps"] == 3


def test_a_slave_that_stalls_steps_every_master_sample_exactly_once() -> None:
    """The master's samples arrive one per master tick; the slave's ticks stall in bursts
    (a loaded host): every sample is still stepped exactly once, in order, and the backlog
    never exceeds its bound. Giving samples up would leave the tool behind for good."""
    settings = PacingSettings(True, 4, max_backlog_samples=8)
    pacing = MasterSamplePacing(settings)
    stepped: list[float] = []
    pending: list[Sample] = []
    seq = 0
    for tick in range(600):
        pending.append(_sample(1, seq, float(seq)))
        seq += 1
        stalled = (tick // 50) % 3 == 2 and tick % 50 < 30  # 30 master ticks without a slave tick
        if stalled:
            continue
        stepped += [step[0] for step in pacing.plan(True, pending)]
        pending = []
        assert pacing.backlog <= settings.max_backlog_samples
    stepped += [step[0] for step in pacing.plan(True, pending)]
    while pacing.backlog:
        stepped += [step[0] for step in pacing.plan(True, [])]
    assert stepped == [float(n) for n in range(seq)]
    assert pacing.dropped_samples == 0 and pacing.burst_steps > 0


def test_a_stale_sample_among_new_ones_is_skipped() -> None:
    pacing = _pacing()
    pacing.plan(True, [_sample(1, 5, 1.0)])
    plan = pacing.plan(True, [_sample(1, 4, 9.0), _sample(1, 6, 2.0)])
    assert plan == [(2.0, -2.0, 0.0, -0.0, 1.0)]
