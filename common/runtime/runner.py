"""The real-time runner: paces one node's step at the period Ts, in one process.

:class:`RealTimeRunner` calls a user step function once per tick and does none of the node's
work itself. Pacing: sleep until ``spin_s`` before the deadline, then spin on the clock (pure
sleep misses by 50-350 us on a loaded Linux box; the spin absorbs the sleep's lateness). With
``realtime`` (:class:`~haptic.common.runtime.realtime.RealtimeSettings`) the loop thread gets tight
timers, and SCHED_FIFO or pinned CPUs if asked, for the run: a sleep then wakes within a few us
and the spin can be short, which leaves the CPUs to Zenoh's threads (common/runtime/realtime.py).

Definitions (all on the runner's monotonic clock, :func:`time.perf_counter_ns`):

- period error: ``|t_k - t_(k-1) - Ts|`` between the starts of two consecutive ticks;
- step time: how long the step function ran, tick start to return (``step_p50_s`` ...): the
  CPU budget a node uses of each period;
- overrun: a step that ends after the next tick's deadline;
- CPU: the loop thread's CPU time over the run (``loop_thread_cpu_s``: its steps, its spin
  and the system calls it makes; per tick ``loop_thread_cpu_per_step_s``) and the whole
  process's (``process_cpu_s``, also Zenoh's and the display's threads; as a share of one CPU,
  ``process_cpu_cores``): the budget a tick takes from a machine the programs share;
- stall: a tick that starts a whole period or more after its deadline (the process was not
  scheduled, or a step took very long). The schedule is then re-anchored at the late start:
  the missed ticks are counted in ``skipped_ticks`` and never fired back to back.

SIGINT and SIGTERM set a flag the loop checks every tick, so a run ends within one period
plus one step; the previous handlers are restored when :meth:`RealTimeRunner.run` returns
(handlers are installed only from the main thread). A program that must also be stoppable
before the loop starts (while it waits for its peer) holds a :class:`StopSignals` for its
whole life and hands it to the runner.
"""

from __future__ import annotations

import contextlib
import math
import signal
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TextIO

from haptic.common.records.histogram import LogHistogram
from haptic.common.runtime.gc_pauses import GcPauses, frozen_heap
from haptic.common.runtime.realtime import AppliedScheduling, LoopThreadScheduling, RealtimeSettings


class StopSignals:
    """Context manager: while inside, SIGINT and SIGTERM set :attr:`requested` (and
    :attr:`reason`, the signal's name) instead of raising; the previous handlers come back on
    exit. Outside the main thread it installs nothing (Python allows handlers only there)."""

    def __init__(self) -> None:
        self.requested = False
        self.reason = ""
        self._previous: dict[int, object] = {}

    def _handler(self, signum: int, _frame: object) -> None:
        if not self.requested:
            self.reason = signal.Signals(signum).name
        self.requested = True

    def __enter__(self) -> StopSignals:
        if threading.current_thread() is threading.main_thread():
            for signum in (signal.SIGINT, signal.SIGTERM):
                self._previous[signum] = signal.signal(signum, self._handler)
        return self

    def __exit__(self, *_exc: object) -> None:
        previous, self._previous = self._previous, {}
        for signum, handler in previous.items():
            signal.signal(signum, handler)  # type: ignore[arg-type]


StepFunction = Callable[[int, int], None]
"""``step(tick, now_ns)``: ``tick`` counts from 0; ``now_ns`` is the tick's start on the
runner's clock (ns). It may call :meth:`RealTimeRunner.request_stop`."""

LeadFunction = Callable[[int], None]
"""``lead(tick)``: called ``lead_s`` before tick ``tick``'s deadline, while the loop waits for
it (e.g. the CAN master's SYNC, so the drives sample and answer before the tick reads them)."""


@dataclass(frozen=True)
class RunStats:
    """Figures of one run. Times in s, rates in Hz."""

    steps: int
    elapsed_s: float
    rate_hz: float
    period_s: float
    period_error_p50_s: float
    period_error_p99_s: float
    period_error_max_s: float
    overruns: int
    stalls: int
    skipped_ticks: int
    stop_reason: str
    scheduling: AppliedScheduling | None = None
    step_p50_s: float = math.nan
    step_p99_s: float = math.nan
    step_max_s: float = math.nan
    loop_thread_cpu_s: float = math.nan
    process_cpu_s: float = math.nan
    #: the garbage collector's pauses while the loop ran (common/runtime/gc_pauses.py)
    gc_pauses: dict[str, object] | None = None

    @property
    def overrun_ratio(self) -> float:
        return self.overruns / self.steps if self.steps else 0.0

    @property
    def loop_thread_cpu_per_step_s(self) -> float:
        """The loop thread's CPU time per tick, s (NaN before any tick)."""
        return self.loop_thread_cpu_s / self.steps if self.steps else math.nan

    @property
    def process_cpu_cores(self) -> float:
        """The process's CPU time over the run's elapsed time: the CPUs it kept busy (NaN for
        a run of no time; with a :class:`FreeRunningClock`, whose elapsed time counts the
        sleeps it skipped, a lower bound)."""
        return self.process_cpu_s / self.elapsed_s if self.elapsed_s > 0 else math.nan

    def as_summary(self) -> dict[str, object]:
        """The runner's keys of the run summary."""
        return {
            "rate_hz": self.rate_hz,
            "period_s": self.period_s,
            "period_p50_error_s": self.period_error_p50_s,
            "period_p99_error_s": self.period_error_p99_s,
            "period_max_error_s": self.period_error_max_s,
            "overruns": self.overruns,
            "overrun_ratio": self.overrun_ratio,
            "stalls": self.stalls,
            "skipped_ticks": self.skipped_ticks,
            "steps": self.steps,
            "duration_s": self.elapsed_s,
            "stop_reason": self.stop_reason,
            "step_p50_s": self.step_p50_s,
            "step_p99_s": self.step_p99_s,
            "step_max_s": self.step_max_s,
            "loop_thread_cpu_s": self.loop_thread_cpu_s,
            "loop_thread_cpu_per_step_s": self.loop_thread_cpu_per_step_s,
            "process_cpu_s": self.process_cpu_s,
            "process_cpu_cores": self.process_cpu_cores,
            **(self.gc_pauses or {}),
            **(self.scheduling.as_summary() if self.scheduling is not None else {}),
        }


class RealTimeRunner:
    """Calls ``step`` every ``period_s`` seconds until ``duration_s`` (None: until stopped) or
    ``max_steps`` ticks have run (None: no limit), whichever comes first.

    ``clock_ns`` and ``sleep`` are injectable (tests drive a fake clock). ``status`` returns
    extra text for the live status line (link delay, loss, force); the line is written to
    ``status_stream`` every ``status_interval_s`` when ``show_status`` is true (default: when
    the stream is a terminal). ``realtime``: how the loop thread is scheduled during
    :meth:`run` (``None``: left as it is). ``stop_signals``: an outer :class:`StopSignals`
    the loop checks (then the runner installs no handlers of its own); otherwise, with
    ``handle_signals``, the runner installs its own for the duration of :meth:`run`.
    ``lead``: called ``lead_s`` (s, at most one period) before each tick's deadline, in the
    wait before it (with the sleep's precision; right away when the previous step ended later
    than that, and never after the deadline: a late tick calls it just before its step).
    ``freeze_heap``: collect and freeze the heap before the loop (common/runtime/gc_pauses.py;
    the programs do, tests and simulations need not). Every run times the garbage
    collector's pauses (:attr:`gc_pauses`, the summary's ``gc_*`` keys). ``prepare``: called
    once just before the first tick, after the heap and the scheduling are set (the programs
    drop the peer's messages from before their start, ``Link.discard_received``).
    """

    def __init__(
        self,
        period_s: float,
        step: StepFunction,
        *,
        duration_s: float | None = None,
        max_steps: int | None = None,
        spin_s: float = 0.0003,
        clock_ns: Callable[[], int] = time.perf_counter_ns,
        sleep: Callable[[float], None] = time.sleep,
        status: Callable[[], str] | None = None,
        status_stream: TextIO | None = None,
        status_interval_s: float = 0.25,
        show_status: bool | None = None,
        handle_signals: bool = True,
        stop_signals: StopSignals | None = None,
        realtime: RealtimeSettings | None = None,
        lead: LeadFunction | None = None,
        lead_s: float = 0.0,
        freeze_heap: bool = False,
        prepare: Callable[[], None] | None = None,
    ) -> None:
        if not period_s > 0.0:
            raise ValueError(f"period_s must be > 0 (got {period_s})")
        if duration_s is not None and not duration_s >= 0.0:
            raise ValueError(f"duration_s must be >= 0 (got {duration_s})")
        if max_steps is not None and max_steps < 0:
            raise ValueError(f"max_steps must be >= 0 (got {max_steps})")
        if not lead_s >= 0.0:
            raise ValueError(f"lead_s must be >= 0 (got {lead_s})")
        self._lead = lead
        self._freeze_heap = freeze_heap
        self._prepare = prepare
        self._lead_ns = min(round(lead_s * 1e9), round(period_s * 1e9))
        self._max_steps = max_steps
        self.period_s = period_s
        self._period_ns = round(period_s * 1e9)
        self._spin_ns = round(max(spin_s, 0.0) * 1e9)
        self._step = step
        self._duration_ns = None if duration_s is None else round(duration_s * 1e9)
        self._clock_ns = clock_ns
        self._sleep = sleep
        self._status = status
        self._stream = status_stream if status_stream is not None else sys.stderr
        self._status_interval_ns = round(status_interval_s * 1e9)
        if show_status is None:
            show_status = bool(getattr(self._stream, "isatty", lambda: False)())
        self._show_status = show_status
        self._handle_signals = handle_signals
        self._signals = stop_signals
        self._realtime = realtime
        self.scheduling: AppliedScheduling | None = None
        self._stop = False
        self.stop_reason = ""
        self._errors = LogHistogram()
        self._step_times = LogHistogram()
        self.steps = 0
        self.overruns = 0
        self.stalls = 0
        self.skipped_ticks = 0
        self._elapsed_ns = 0
        self._loop_thread_cpu_s = math.nan
        self._process_cpu_s = math.nan
        self._shift_ns = 0
        #: the garbage collector's pauses while :meth:`run` runs
        self.gc_pauses = GcPauses()

    def shift_schedule(self, delta_ns: int) -> None:
        """Move the next tick's deadline by ``delta_ns`` (ns; negative: earlier), from a step
        (a :class:`~haptic.common.wire.phase_lock.PhaseLock` keeps the ticks in phase with the
        peer's this way). Corrections of one tick add up; the period error shows them."""
        self._shift_ns += delta_ns

    def request_stop(self, reason: str = "requested") -> None:
        """End the run after the current tick (safe from a signal handler or another thread)."""
        if not self._stop:
            self.stop_reason = reason
        self._stop = True

    @property
    def stopping(self) -> bool:
        return self._stop

    def run(self) -> RunStats:
        """Run until the duration is reached or a stop is requested; returns the figures."""
        own = self._signals is None and self._handle_signals
        signals = StopSignals() if own else self._signals
        try:
            if own:
                signals.__enter__()
            with frozen_heap() if self._freeze_heap else contextlib.nullcontext(), \
                    self.gc_pauses:
                if self._realtime is None:
                    self._loop(signals)
                else:
                    with LoopThreadScheduling(self._realtime) as applied:
                        self.scheduling = applied
                        self._loop(signals)
        finally:
            if own:
                signals.__exit__(None, None, None)
            if self._show_status:
                self._stream.write("\n")
                self._stream.flush()
        return self.stats()

    def _loop(self, signals: StopSignals | None) -> None:
        clock = self._clock_ns
        sleep = self._sleep
        period = self._period_ns
        spin = self._spin_ns
        errors = self._errors
        step_times = self._step_times
        step = self._step
        self._shift_ns = 0  # a shift asked for outside a run does not carry into this one
        if self._prepare is not None:
            self._prepare()
        thread_cpu_s, process_cpu_s = time.thread_time(), time.process_time()
        start = clock()
        end = None if self._duration_ns is None else start + self._duration_ns
        deadline = start
        previous_start = None
        next_status = start + self._status_interval_ns
        last_status = start
        status_steps = 0
        tick = 0
        max_steps = self._max_steps
        while not self._stop:
            if max_steps is not None and tick >= max_steps:
                self.stop_reason = self.stop_reason or "steps"
                break
            if signals is not None and signals.requested:
                self.request_stop(signals.reason)
                break
            remaining = deadline - clock()
            if self._lead is not None:
                if remaining > self._lead_ns:
                    sleep((remaining - self._lead_ns) * 1e-9)
                self._lead(tick)
                remaining = deadline - clock()
            if remaining > spin:
                sleep((remaining - spin) * 1e-9)
            now = clock()
            while now < deadline:
                now = clock()
            if end is not None and now >= end:
                self.stop_reason = self.stop_reason or "duration"
                break
            late = now - deadline
            if late >= period:  # a stall: re-anchor, never fire the missed ticks in a burst
                self.stalls += 1
                self.skipped_ticks += late // period
                deadline = now
            if previous_start is not None:
                error = now - previous_start - period
                errors.record((error if error >= 0 else -error) * 1e-9)
            previous_start = now
            step(tick, now)
            tick += 1
            self.steps = tick
            deadline += period
            if self._shift_ns:
                deadline += self._shift_ns
                self._shift_ns = 0
            after = clock()
            step_times.record((after - now) * 1e-9)
            if after > deadline:
                self.overruns += 1
            if self._show_status and after >= next_status:
                self._write_status(after, start, tick - status_steps, after - last_status)
                status_steps = tick
                last_status = after
                next_status = after + self._status_interval_ns
        self._elapsed_ns = clock() - start
        self._loop_thread_cpu_s = time.thread_time() - thread_cpu_s
        self._process_cpu_s = time.process_time() - process_cpu_s
        if not self.stop_reason:
            self.stop_reason = "requested"

    def _write_status(self, now_ns: int, start_ns: int, steps: int, span_ns: int) -> None:
        rate = steps / (span_ns * 1e-9) if span_ns > 0 else 0.0
        p99 = self._errors.percentile(99.0)
        extra = self._status() if self._status is not None else ""
        line = (
            f"\r{(now_ns - start_ns) * 1e-9:7.1f} s  {rate:7.1f} Hz  period p99 "
            f"{p99 * 1e6:6.1f} us  overruns {self.overruns}  {extra}\x1b[K"
        )
        self._stream.write(line)
        self._stream.flush()

    def stats(self) -> RunStats:
        """Figures so far (final after :meth:`run` returns)."""
        elapsed = self._elapsed_ns * 1e-9
        e = self._errors
        return RunStats(
            steps=self.steps,
            elapsed_s=elapsed,
            rate_hz=self.steps / elapsed if elapsed > 0 else 0.0,
            period_s=self.period_s,
            period_error_p50_s=e.percentile(50.0),
            period_error_p99_s=e.percentile(99.0),
            period_error_max_s=e.max_s if e.count else math.nan,
            overruns=self.overruns,
            stalls=self.stalls,
            skipped_ticks=self.skipped_ticks,
            stop_reason=self.stop_reason,
            scheduling=self.scheduling,
            step_p50_s=self._step_times.percentile(50.0),
            step_p99_s=self._step_times.percentile(99.0),
            step_max_s=self._step_times.max_s if self._step_times.count else math.nan,
            loop_thread_cpu_s=self._loop_thread_cpu_s,
            process_cpu_s=self._process_cpu_s,
            gc_pauses=self.gc_pauses.summary(),
        )


class FreeRunningClock:
    """A clock and a sleep for :class:`RealTimeRunner` that run the ticks back to back: a
    sleep advances the clock instead of waiting, so every deadline is met at once (tests,
    benchmarks and rigs simulated faster than real time; give the runner ``spin_s=0``). The
    step times and the elapsed time stay real (ns)."""

    def __init__(self) -> None:
        self._offset_ns = 0

    def clock_ns(self) -> int:
        """The real monotonic clock plus what the sleeps skipped, ns."""
        return time.perf_counter_ns() + self._offset_ns

    def sleep(self, seconds: float) -> None:
        """Skip ``seconds`` instead of waiting them."""
        self._offset_ns += math.ceil(seconds * 1e9)
