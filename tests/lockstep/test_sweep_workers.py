"""A sweep split between forked processes is the one-process sweep, bit for bit
(lockstep/sweep.py ``run_sweep(..., workers)``)."""

from __future__ import annotations

import json
import multiprocessing
import os
import threading
from dataclasses import replace

import numpy as np
import pytest

from haptic.common.config import load_config
from haptic.common.config.scenario import load_scenario
from haptic.common.model.teleop import model_from_config
from haptic.common.wire.injection import InjectionConfig
from haptic.lockstep import sweep
from haptic.lockstep.cli import main
from haptic.lockstep.simulator import LockstepSimulator, concatenate_results, line_schedules
from haptic.lockstep.sweep import (
    MIN_LANES_PER_WORKER,
    SweepSettings,
    auto_workers,
    available_workers,
    can_fork_workers,
    lane_parts,
    run_sweep,
    write_csv,
)
from haptic.master.simulated_rig.operator import parse_operator_spec


@pytest.fixture(scope="module")
def model():
    return model_from_config(load_config())


def _csv(result, tmp_path, name: str) -> str:
    path = tmp_path / name
    write_csv(result, str(path))
    return path.read_text()


def test_lane_parts_split_between_whole_gains() -> None:
    gains = np.repeat([1.0, 3.0, 8.0, 13.0, 19.0], 4)
    assert lane_parts(gains, 1) == ((0, 20),)
    parts = lane_parts(gains, 2)
    assert parts[0][0] == 0 and parts[-1][1] == 20 and len(parts) == 2
    for first, end in parts:  # whole gains: a cut only where the gain changes
        assert first == 0 or gains[first] != gains[first - 1]
        assert end == 20 or gains[end] != gains[end - 1]
    assert parts == ((0, 12), (12, 20)) or parts == ((0, 8), (8, 20))
    # never more parts than gains, never an empty part
    assert lane_parts(np.repeat([13.0, 19.0], 3), 8) == ((0, 3), (3, 6))
    assert lane_parts(np.full(6, 13.0), 4) == ((0, 6),)


def test_auto_workers_keeps_enough_lanes_per_worker() -> None:
    assert auto_workers(MIN_LANES_PER_WORKER - 1) == 1
    assert auto_workers(10 * MIN_LANES_PER_WORKER) == min(available_workers(), 10)


def _simulator(model, gains):
    operator = parse_operator_spec("constant:fx=0,fy=0")
    return LockstepSimulator(model, load_scenario("constant-rate"), operator, gains, "linear",
                             device="cpu")


def test_a_run_on_line_schedules_of_its_arguments_is_the_run(model) -> None:
    """run() draws exactly line_schedules(...) of its arguments; handing each part of a
    split run its columns of the whole run's draws gives the whole run, lane for lane."""
    injection = InjectionConfig(jitter_s=0.002, loss_probability=0.1)
    gains, delays = np.array([3.0, 3.0, 13.0, 13.0]), np.array([2, 9, 4, 17])
    steps, ts = 600, model.sample_period_s
    pulse = np.ones((20, 2))
    whole = _simulator(model, gains).run(steps * ts, delays, to_slave=injection,
                                         to_master=injection, seed=5, excitation_N=pulse)
    schedules = line_schedules(steps, ts, delays, injection, injection, 5)
    quiet = line_schedules(steps, ts, delays, None, None, 5)
    assert not np.array_equal(schedules[0], quiet[0])  # the injection was drawn
    parts = [_simulator(model, gains[a:b]).run(
        steps * ts, delays[a:b], to_slave=injection, to_master=injection, seed=5,
        excitation_N=pulse, schedules=tuple(s[:, a:b] for s in schedules))
        for a, b in ((0, 2), (2, 4))]
    joined = concatenate_results(parts)
    for name in ("peak_handle_force_N", "peak_tool_force_N", "position_error_rms_m",
                 "diverged", "force_error_rms_N", "final_position_gap_m", "gains_k",
                 "round_trip_delay_samples"):
        assert np.array_equal(getattr(joined, name), getattr(whole, name)), name
    assert np.array_equal(joined.stats.handle_force_sumsq_N2, whole.stats.handle_force_sumsq_N2)
    assert np.array_equal(joined.stats.tool_force_max_N, whole.stats.tool_force_max_N)
    with pytest.raises(ValueError):
        _simulator(model, gains).run(steps * ts, delays, schedules=(quiet[0][:, :2], quiet[1]))


def test_concatenate_refuses_parts_it_cannot_join(model) -> None:
    with pytest.raises(ValueError):
        concatenate_results([])
    simulator = _simulator(model, np.array([13.0, 13.0]))
    recorded = simulator.run(0.3, np.array([2, 4]), record_lanes=np.array([0]))
    with pytest.raises(ValueError):
        concatenate_results([recorded, recorded])
    short, longer = simulator.run(0.3, np.array([2, 4])), simulator.run(0.6, np.array([2, 4]))
    with pytest.raises(ValueError):
        concatenate_results([short, longer])


@pytest.mark.parametrize("case", ["plain", "jitter and loss", "tdpa"])
def test_a_sweep_split_between_processes_is_the_one_process_sweep(model, tmp_path,
                                                                  case) -> None:
    assert threading.active_count() == 1, "a test left a thread running (workers cannot fork)"
    assert can_fork_workers()
    settings = SweepSettings((3.0, 13.0, 19.0), (0.0, 0.006, 0.009, 0.016), "linear", 1.5)
    if case == "jitter and loss":
        settings = replace(settings, jitter_s=0.001, loss_probability=0.05, seed=3)
    elif case == "tdpa":
        settings = replace(settings, control="tdpa")
    one = run_sweep(model, settings, workers=1)
    split = run_sweep(model, settings, workers=2)
    assert one.extra["workers"] == 1 and split.extra["workers"] == 2
    assert _csv(one, tmp_path, "one.csv") == _csv(split, tmp_path, "split.csv")
    assert one.extra["per_cell"] == split.extra["per_cell"]
    assert np.array_equal(one.energy_ratio, split.energy_ratio, equal_nan=True)
    assert split.summary()["workers"] == 2


def _fail_in_workers(monkeypatch, failure) -> None:
    """Make every forked worker's part call ``failure()`` (this process's part runs)."""
    parent, real = os.getpid(), sweep._simulate_lanes

    def part(job, first, end):
        if os.getpid() != parent:
            failure()
        return real(job, first, end)

    monkeypatch.setattr(sweep, "_simulate_lanes", part)


def test_a_worker_s_error_is_raised_here_with_its_traceback_and_the_worker_reaped(
        model, monkeypatch) -> None:
    def failure():
        raise ValueError("lane trouble")

    _fail_in_workers(monkeypatch, failure)
    settings = SweepSettings((3.0, 13.0), (0.0, 0.006), "linear", 0.3)
    with pytest.raises(ValueError, match="lane trouble") as raised:
        run_sweep(model, settings, workers=2)
    assert "in sweep worker" in str(raised.value.__cause__)
    assert "failure" in str(raised.value.__cause__)  # the worker's own traceback
    assert multiprocessing.active_children() == []


def test_a_worker_that_dies_is_an_error_not_a_hang(model, monkeypatch) -> None:
    _fail_in_workers(monkeypatch, lambda: os._exit(3))
    settings = SweepSettings((3.0, 13.0), (0.0, 0.006), "linear", 0.3)
    with pytest.raises(RuntimeError, match=r"stopped without a result \(exit status 3\)"):
        run_sweep(model, settings, workers=2)
    assert multiprocessing.active_children() == []


def test_cli_sweep_workers(tmp_path, capsys) -> None:
    assert main(["sweep", "--gains", "3,13", "--delays", "0.004,0.02", "--duration", "1.5",
                 "--workers", "2", "--json", "--check"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["cells"] == 4 and summary["agree"] == 4 and summary["workers"] == 2
    with pytest.raises(SystemExit) as exit_info:
        main(["sweep", "--workers", "0"])
    assert exit_info.value.code == 2
    assert "--workers" in capsys.readouterr().err
