"""Where a tick's time goes: per-stage durations of every tick, as percentiles over the run.

A program marks the clock (:func:`time.perf_counter_ns`, the runner's clock) at the end of each
stage of its tick and hands the marks to :meth:`StageTimes.record` with the tick's start. One
:class:`~haptic.common.records.histogram.LogHistogram` per stage keeps the figures in constant
memory; a record costs well under a microsecond per stage. The run summary gets
``stages``: stage name -> ``{"index", "p50_s", "p99_s", "max_s", "mean_s"}`` (``index``: the
stage's place in the tick, since JSON summaries sort their keys).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from haptic.common.records.histogram import LogHistogram


class StageTimes:
    """Durations of the named stages of each tick, s."""

    def __init__(self, names: Sequence[str]) -> None:
        if not names:
            raise ValueError("need at least one stage")
        self.names = tuple(names)
        self._histograms = tuple(LogHistogram() for _ in self.names)

    def record(self, start_ns: int, marks_ns: Sequence[int]) -> None:
        """One tick: ``start_ns`` when it began and the clock at the end of each stage, ns (one
        mark per stage, in order)."""
        previous = start_ns
        for histogram, mark in zip(self._histograms, marks_ns, strict=True):
            histogram.record((mark - previous) * 1e-9)
            previous = mark

    @property
    def ticks(self) -> int:
        """Ticks recorded."""
        return self._histograms[0].count

    def summary(self) -> dict[str, dict[str, float]]:
        """Per stage: its index in the tick, and p50, p99, max and mean duration, s (NaN
        before the first tick)."""
        result = {}
        for index, (name, histogram) in enumerate(zip(self.names, self._histograms,
                                                      strict=True)):
            p50, p99 = histogram.percentiles((50.0, 99.0))
            count = histogram.count
            result[name] = {
                "index": index, "p50_s": p50, "p99_s": p99,
                "max_s": histogram.max_s if count else math.nan,
                "mean_s": histogram.sum_s / count if count else math.nan,
            }
        return result


def in_tick_order(stages: dict[str, dict[str, float]]) -> list[tuple[str, dict[str, float]]]:
    """The stages of a summary in the order they run in the tick."""
    return sorted(stages.items(), key=lambda item: item[1].get("index", 0))


def format_stages(stages: dict[str, dict[str, float]]) -> str:
    """One line: ``read 12.3/20.1  poll ... us (p50/p99)`` in tick order."""
    return "  ".join(f"{name} {_us_figure(figures.get('p50_s'))}/"
                     f"{_us_figure(figures.get('p99_s'))}"
                     for name, figures in in_tick_order(stages)) + " us (p50/p99)"


def _us_figure(value_s: float | None) -> str:
    """A stage figure in us, one decimal; "n/a" where the run gave none (no tick)."""
    if value_s is None or not math.isfinite(value_s):
        return "n/a"
    return f"{value_s * 1e6:.1f}"


class StepSplitTimes:
    """A stage that runs a varying number of steps a tick (the slave's node: one step per
    master sample, none while the next has not come, several after a gap;
    slave_sim/pacing.py): its time per step over the ticks with at least one step, its time
    by the tick's step count, and the ticks that took each count, so a reader sees what the
    stage's p99 holds. A record costs about a microsecond (a tick of one step less); the
    caller records outside the timed stages."""

    def __init__(self) -> None:
        #: ticks of two steps or more, per step (a tick of one is in ``_by_steps[1]`` only)
        self._per_step = LogHistogram()
        self._one_step = LogHistogram()
        self._by_steps: dict[int, LogHistogram] = {1: self._one_step}
        self._no_step_ticks = 0

    @property
    def ticks_by_steps(self) -> dict[int, int]:
        """Ticks by the steps they took (only the counts that occurred)."""
        counts = {0: self._no_step_ticks} if self._no_step_ticks else {}
        counts.update((steps, histogram.count) for steps, histogram
                      in sorted(self._by_steps.items()) if histogram.count)
        return counts

    def record(self, steps: int, duration_ns: int) -> None:
        """One tick: ``steps`` steps (0: none) that took ``duration_ns``, ns. A tick of one
        step (the common one) is recorded once: its time per step is its time, which
        :meth:`summary` adds to the per-step figures."""
        if steps == 1:
            self._one_step.record(duration_ns * 1e-9)
            return
        if steps <= 0:
            self._no_step_ticks += 1
            return
        duration_s = duration_ns * 1e-9
        self._per_step.record(duration_s / steps)
        histogram = self._by_steps.get(steps)
        if histogram is None:
            histogram = self._by_steps[steps] = LogHistogram()
        histogram.record(duration_s)

    def summary(self) -> dict[str, object]:
        """``per_step``: p50, p99, max and mean of the stage's time divided by its steps, over
        the ticks with at least one step, s; ``by_steps``: the step count (a string, for
        JSON) -> the ticks with that count and their stage time's p50 and p99, s
        (``ticks`` only for 0 steps)."""
        per_step = LogHistogram()
        per_step.merge(self._one_step)
        per_step.merge(self._per_step)
        p50, p99 = per_step.percentiles((50.0, 99.0))
        count = per_step.count
        by_steps: dict[str, dict[str, float]] = {}
        for steps, ticks in self.ticks_by_steps.items():
            entry: dict[str, float] = {"ticks": ticks}
            if steps > 0:
                entry["p50_s"], entry["p99_s"] = self._by_steps[steps].percentiles((50.0, 99.0))
            by_steps[str(steps)] = entry
        return {"per_step": {"p50_s": p50, "p99_s": p99,
                             "max_s": per_step.max_s if count else math.nan,
                             "mean_s": per_step.sum_s / count if count else math.nan,
                             "ticks": count},
                "by_steps": by_steps}
