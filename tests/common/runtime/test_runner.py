"""The real-time runner's logic on an injected clock (no timing is asserted), and its signal
handling in a child process."""

from __future__ import annotations

import json
import math
import os
import signal
import sys
import textwrap

import pytest

from haptic.common.runtime.runner import FreeRunningClock, RealTimeRunner, StopSignals
from tests.helpers.fake_clock import FakeClock
from tests.helpers.programs import Program

PERIOD_NS = 540_000

#: How long a child may take to start and say it is ready, s.
READY_S = 120.0


def make(clock: FakeClock, step, duration_s: float, **kwargs) -> RealTimeRunner:
    return RealTimeRunner(
        PERIOD_NS * 1e-9, step, duration_s=duration_s, clock_ns=clock.clock, sleep=clock.sleep,
        handle_signals=False, show_status=False, **kwargs,
    )


def test_runs_the_expected_number_of_ticks():
    clock = FakeClock(late_ns=50_000)
    starts = []
    runner = make(clock, lambda tick, now: starts.append((tick, now)), duration_s=1.0)
    stats = runner.run()
    assert stats.steps == len(starts) == pytest.approx(1.0 / (PERIOD_NS * 1e-9), abs=2)
    assert [t for t, _ in starts] == list(range(len(starts)))
    assert stats.overruns == 0 and stats.stalls == 0 and stats.skipped_ticks == 0
    assert stats.stop_reason == "duration"
    gaps = [b - a for (_, a), (_, b) in zip(starts, starts[1:], strict=False)]
    assert max(abs(g - PERIOD_NS) for g in gaps) <= 2_000  # the spin absorbs the late sleep
    assert clock.sleeps > 0


def test_stall_reanchors_without_a_burst():
    clock = FakeClock()
    starts = []

    def step(tick: int, now: int) -> None:
        starts.append(now)
        if tick == 100:
            clock.now += 10 * PERIOD_NS  # the process was frozen for ten periods

    stats = make(clock, step, duration_s=0.2).run()
    gaps = [b - a for a, b in zip(starts, starts[1:], strict=False)]
    assert stats.stalls == 1
    assert stats.skipped_ticks == 9  # the ticks due at 101..109; 110 fires, late
    assert stats.overruns == 1  # tick 100 ended after its deadline
    # no missed tick is fired back to back: every gap is at least about one period
    assert min(gaps) >= PERIOD_NS - 2_000
    assert max(gaps) >= 10 * PERIOD_NS
    assert stats.steps == pytest.approx(0.2 / (PERIOD_NS * 1e-9) - 9, abs=2)


def test_short_overrun_is_counted_and_caught_up_once():
    clock = FakeClock()
    starts = []

    def step(tick: int, now: int) -> None:
        starts.append(now)
        if tick == 10:
            clock.now += PERIOD_NS * 3 // 2

    stats = make(clock, step, duration_s=0.05).run()
    assert stats.overruns == 1
    assert stats.stalls == 0 and stats.skipped_ticks == 0
    gaps = [b - a for a, b in zip(starts, starts[1:], strict=False)]
    assert sum(g < PERIOD_NS * 0.9 for g in gaps) == 1  # one short gap to get back on grid


def test_max_steps_counts_executed_ticks_not_wall_time():
    """``max_steps`` (the master's ``--rig-time``): a run whose ticks stall still executes
    every one of its ticks, where a wall-time duration would have ended it early."""
    clock = FakeClock()
    starts = []

    def step(tick: int, now: int) -> None:
        starts.append(now)
        if tick % 50 == 0:
            clock.now += 10 * PERIOD_NS  # a loaded machine: frozen for ten periods now and then

    stats = make(clock, step, duration_s=None, max_steps=400).run()
    assert stats.steps == len(starts) == 400 and stats.stop_reason == "steps"
    assert stats.skipped_ticks == 8 * 9  # wall time went on, the steps did not
    clock = FakeClock()
    walled = make(clock, step, duration_s=400 * PERIOD_NS * 1e-9).run()
    assert walled.stop_reason == "duration" and walled.steps < 400 - 50
    # whichever comes first: a duration shorter than the steps ends the run
    clock = FakeClock()
    both = make(clock, lambda tick, now: None, duration_s=0.01, max_steps=1000).run()
    assert both.stop_reason == "duration" and both.steps < 1000


def test_request_stop_from_the_step():
    clock = FakeClock()
    holder = {}

    def step(tick: int, _now: int) -> None:
        if tick == 41:
            holder["runner"].request_stop("done")

    runner = make(clock, step, duration_s=None)
    holder["runner"] = runner
    stats = runner.run()
    assert stats.steps == 42
    assert stats.stop_reason == "done"


def test_period_statistics_see_the_jitter():
    clock = FakeClock()

    def step(tick: int, _now: int) -> None:
        if tick % 10 == 5:
            clock.now += PERIOD_NS + 20_000  # overrun by 20 us every tenth tick

    stats = make(clock, step, duration_s=0.1).run()
    assert stats.overruns == pytest.approx(stats.steps / 10, abs=1)
    assert stats.period_error_max_s == pytest.approx(20e-6, abs=3e-6)
    assert stats.period_error_p50_s < 3e-6


def test_status_line_is_written_when_asked(tmp_path):
    clock = FakeClock()
    out = open(tmp_path / "status.txt", "w")  # noqa: SIM115 - closed below
    runner = make(
        clock, lambda t, n: None, duration_s=1.0, status=lambda: "link ok",
        status_stream=out,
    )
    runner._show_status = True
    runner.run()
    out.close()
    with open(tmp_path / "status.txt", newline="") as f:
        text = f.read()
    assert text.count("\r") >= 3
    assert "Hz" in text and "link ok" in text and text.endswith("\n")


def test_invalid_arguments():
    with pytest.raises(ValueError):
        RealTimeRunner(0.0, lambda t, n: None)
    with pytest.raises(ValueError):
        RealTimeRunner(0.001, lambda t, n: None, duration_s=-1.0)
    with pytest.raises(ValueError):
        RealTimeRunner(0.001, lambda t, n: None, max_steps=-1)


CHILD = textwrap.dedent(
    """
    import json, sys
    from haptic.common.runtime.runner import RealTimeRunner, StopSignals
    first = []
    def step(tick, now):
        if tick == 0:
            print("ready", flush=True)
    runner = RealTimeRunner(0.00054, step, show_status=False)
    stats = runner.run()
    with open(sys.argv[1], "w") as f:
        json.dump(stats.as_summary(), f)
    """
)


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_signal_ends_the_run_cleanly(tmp_path, signum):
    summary = tmp_path / "summary.json"
    with Program([sys.executable, "-c", CHILD, str(summary)],
                 env={"PYTHONUNBUFFERED": "1"}) as child:
        child.wait_for(r"^ready$", timeout_s=READY_S)
        assert child.stop(signum, grace_s=10.0) == 0, child.output()
    result = json.loads(summary.read_text())
    assert result["stop_reason"] == signal.Signals(signum).name
    assert result["steps"] >= 1


CHILD_WAITING = textwrap.dedent(
    """
    import json, sys, time
    from haptic.common.runtime.runner import RealTimeRunner, StopSignals
    with StopSignals() as signals:
        print("ready", flush=True)
        while not signals.requested:  # waiting for a peer that never comes
            time.sleep(0.001)
        stats = RealTimeRunner(0.00054, lambda t, n: None, stop_signals=signals).run()
    with open(sys.argv[1], "w") as f:
        json.dump(stats.as_summary(), f)
    """
)


def test_signal_before_the_loop_starts_ends_cleanly(tmp_path):
    summary = tmp_path / "summary.json"
    with Program([sys.executable, "-c", CHILD_WAITING, str(summary)]) as child:
        child.wait_for(r"^ready$", timeout_s=READY_S)
        assert child.stop(signal.SIGINT, grace_s=10.0) == 0, child.output()
    result = json.loads(summary.read_text())
    assert result["stop_reason"] == "SIGINT" and result["steps"] == 0


def test_stop_signals_restore_the_previous_handlers():
    before = signal.getsignal(signal.SIGTERM)
    with StopSignals() as signals:
        assert signal.getsignal(signal.SIGTERM) != before
        os.kill(os.getpid(), signal.SIGTERM)
        assert signals.requested and signals.reason == "SIGTERM"
    assert signal.getsignal(signal.SIGTERM) == before


def test_shift_schedule_moves_only_the_next_tick():
    clock = FakeClock()
    starts = []
    runner = None

    def step(tick: int, now: int) -> None:
        starts.append(now)
        if tick == 10:
            runner.shift_schedule(-3_000)  # two corrections in one tick add up
            runner.shift_schedule(-2_000)

    runner = make(clock, step, duration_s=0.02)
    stats = runner.run()
    gaps = [b - a for a, b in zip(starts, starts[1:], strict=False)]
    assert abs(gaps[10] - (PERIOD_NS - 5_000)) <= 2_000  # the shifted period
    assert all(abs(g - PERIOD_NS) <= 2_000 for i, g in enumerate(gaps) if i != 10)
    assert stats.period_error_max_s >= 3e-6  # the shift shows in the period error
    assert stats.overruns == 0


def test_step_time_statistics():
    clock = FakeClock()

    def step(tick: int, _now: int) -> None:
        clock.now += 300_000 if tick % 100 == 0 else 100_000  # charge the step's work

    stats = make(clock, step, duration_s=0.5).run()
    assert stats.step_p50_s == pytest.approx(100e-6, rel=0.05)
    assert stats.step_max_s == pytest.approx(301e-6, rel=0.05)
    summary = stats.as_summary()
    assert summary["step_p50_s"] == stats.step_p50_s
    assert summary["step_p99_s"] >= summary["step_p50_s"]


def test_the_run_reports_the_cpu_its_loop_used() -> None:
    """The loop thread's CPU time over the run (here a step that keeps its thread busy for
    2 ms of its own CPU time), the process's (at least the loop thread's), and the derived
    per-tick and per-wall-second figures in the summary."""
    import time

    def busy_step(_tick: int, _now: int) -> None:
        until = time.thread_time() + 0.002
        while time.thread_time() < until:
            pass

    free = FreeRunningClock()
    runner = RealTimeRunner(0.001, busy_step, max_steps=10, spin_s=0.0,
                            clock_ns=free.clock_ns, sleep=free.sleep, handle_signals=False,
                            show_status=False)
    stats = runner.run()
    assert stats.steps == 10
    assert stats.loop_thread_cpu_s >= 0.020
    assert stats.process_cpu_s >= stats.loop_thread_cpu_s - 0.001
    assert stats.loop_thread_cpu_per_step_s == pytest.approx(stats.loop_thread_cpu_s / 10)
    assert stats.as_summary()["loop_thread_cpu_per_step_s"] >= 0.002


def test_the_cpu_figures_per_tick_and_per_wall_second() -> None:
    from haptic.common.runtime.runner import RunStats

    stats = RunStats(steps=4000, elapsed_s=2.0, rate_hz=2000.0, period_s=0.0005,
                     period_error_p50_s=0.0, period_error_p99_s=0.0, period_error_max_s=0.0,
                     overruns=0, stalls=0, skipped_ticks=0, stop_reason="duration",
                     loop_thread_cpu_s=0.8, process_cpu_s=1.5)
    summary = stats.as_summary()
    assert summary["loop_thread_cpu_per_step_s"] == pytest.approx(200e-6)
    assert summary["process_cpu_cores"] == pytest.approx(0.75)
    assert (summary["loop_thread_cpu_s"], summary["process_cpu_s"]) == (0.8, 1.5)


def test_a_runner_that_never_ran_reports_no_cpu_figures() -> None:
    runner = RealTimeRunner(0.001, lambda tick, now: None, max_steps=1, handle_signals=False,
                            show_status=False)
    stats = runner.stats()
    assert math.isnan(stats.loop_thread_cpu_per_step_s) and math.isnan(stats.process_cpu_cores)


def test_a_shift_asked_outside_a_run_does_not_move_the_next_run():
    clock = FakeClock()
    starts = []
    runner = make(clock, lambda tick, now: starts.append(now), duration_s=0.01)
    runner.shift_schedule(-200_000)
    runner.run()
    gaps = [b - a for a, b in zip(starts, starts[1:], strict=False)]
    assert all(abs(g - PERIOD_NS) <= 2_000 for g in gaps)


def test_a_free_running_clock_runs_the_ticks_back_to_back_on_schedule() -> None:
    """Unpaced runs (the master alone with --no-pace, bench_master) use the one runner: a
    free-running clock skips the sleeps, so a 1 s period's 5 ticks take far less than 5 s,
    and on that clock every tick starts exactly at its deadline."""
    free = FreeRunningClock()
    starts: list[int] = []

    def step(tick: int, now_ns: int) -> None:
        starts.append(now_ns)
        if tick == 4:
            runner.request_stop("done")

    runner = RealTimeRunner(1.0, step, spin_s=0.0, clock_ns=free.clock_ns, sleep=free.sleep,
                            show_status=False, handle_signals=False)
    stats = runner.run()
    assert stats.steps == 5 and stats.stop_reason == "done"
    assert stats.elapsed_s >= 4.0  # on the free-running clock: four periods skipped
    gaps = [later - earlier for earlier, later in zip(starts[:-1], starts[1:], strict=True)]
    assert all(abs(gap - 1_000_000_000) < 1_000_000 for gap in gaps), gaps
    assert stats.overruns == 0 and stats.stalls == 0


# --- before the first tick: the prepare hook and the garbage collector ------------------------


def test_prepare_runs_once_before_the_first_tick_and_the_schedule_starts_after_it():
    clock = FakeClock()
    calls: list[tuple[str, int]] = []

    def prepare() -> None:
        calls.append(("prepare", clock.now))
        clock.now += 5_000_000  # a slow preparation (5 ms) is not a late first tick

    runner = make(clock, lambda tick, now: calls.append(("step", now)), duration_s=0.01,
                  prepare=prepare)
    stats = runner.run()
    assert calls[0][0] == "prepare" and [kind for kind, _ in calls].count("prepare") == 1
    assert all(kind == "step" for kind, _ in calls[1:]) and len(calls) > 2
    assert stats.stalls == 0 and stats.overruns == 0


def test_the_run_times_the_collectors_pauses():
    import gc

    def make_cycles(tick: int, now: int) -> None:
        for _ in range(300):  # cyclic garbage: collections of the youngest generation
            node: list = []
            node.append(node)

    stats = make(FakeClock(), make_cycles, duration_s=0.05).run()
    summary = stats.as_summary()
    assert summary["gc_collections"] > 0
    assert summary["gc_collections"] == sum(summary["gc_collections_by_generation"])
    assert 0.0 < summary["gc_pause_max_s"] <= summary["gc_pause_total_s"]
    quiet = make(FakeClock(), lambda tick, now: None, duration_s=0.01).run()
    assert quiet.as_summary()["gc_pause_max_s"] <= summary["gc_pause_total_s"]
    assert not [c for c in gc.callbacks if getattr(c, "__self__", None) is not None
                and type(c.__self__).__name__ == "GcPauses"]  # removed after the run


@pytest.mark.usefixtures("thawed_heap")
def test_a_frozen_heap_is_scanned_no_more_during_the_run_and_thawed_after():
    import gc

    frozen_during: list[int] = []
    keep = [[] for _ in range(1000)]  # tracked objects from before the run
    runner = make(FakeClock(), lambda tick, now: frozen_during.append(gc.get_freeze_count()),
                  duration_s=0.002, freeze_heap=True)
    runner.run()
    assert min(frozen_during) >= len(keep)  # everything alive before the loop was frozen
    assert gc.get_freeze_count() == 0  # and thawed after it
