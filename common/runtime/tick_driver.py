"""The one tick driver: every program's tick, stage by stage, timed (docs/architecture.md,
"one tick").

A side (the networked master, the networked slave, the master alone, a real-link cell's two
sides) is a small object whose stages the driver runs in order once per tick, each a bound
method ``stage(tick, now_ns)`` (``tick`` counts from 0, ``now_ns`` the tick's start on the
runner's clock, :func:`time.perf_counter_ns`)::

    read -> poll -> tick -> write -> send -> telemetry

A side names its stages (:attr:`TickSide.stage_names`) and gives the ones it has
(:meth:`TickSide.stages`; the slave has no hardware to read or write). A stage talks to one
thing only (the hardware, the link, the tick object, the run's records) and hands what it
produced to the next through the side's declared input and output records, which are filled
in place: the driver builds nothing per tick. The clock is read at the end of every stage
into :class:`~haptic.common.runtime.stage_times.StageTimes` (the summary's ``stages``); a
stage that returns an int returns the clock at a boundary inside it (ns), which counts as the
end of a stage of its own: the whole-tick call's supervise | node boundary.

What a side needs from the runner is an output of its tick, not a reach into the runner:
after the stages the driver hands :attr:`TickSide.schedule_shift_ns` (the slave's phase
lock) to the runner's ``shift_schedule`` (:meth:`TickDriver.follow`) and clears it.

It imports nothing above ``common/runtime`` and does no control work itself.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Protocol

from haptic.common.runtime.stage_times import StageTimes

#: A stage of a side: ``stage(tick, now_ns)``; may return the clock (ns) at a stage
#: boundary inside it, else None.
Stage = Callable[[int, int], "int | None"]


class TickSide(Protocol):
    """One side's stages (see the module docstring)."""

    #: the names of the timed stages, in order (one more per boundary a stage returns)
    stage_names: tuple[str, ...]
    #: a schedule shift the last tick asks of the runner, ns (0: none); the driver clears it
    schedule_shift_ns: int

    def stages(self) -> Sequence[Stage]:
        """The side's stages, in tick order."""
        ...


class TickDriver:
    """Runs ``sides`` (one for a program, two for a real-link cell: the master's, then the
    slave's) once per tick with their stage times (:attr:`stage_times`, one per side).
    :meth:`step` is the runner's step function (common/runtime/runner.py)."""

    def __init__(self, sides: Sequence[TickSide],
                 clock_ns: Callable[[], int] = time.perf_counter_ns) -> None:
        if not sides:
            raise ValueError("at least one side")
        self.sides = tuple(sides)
        self.stage_times = tuple(StageTimes(side.stage_names) for side in self.sides)
        self._clock_ns = clock_ns
        # per side: its stages, its times and the marks, allocated once
        self._plan = tuple((side, tuple(side.stages()), times, [0] * len(side.stage_names))
                           for side, times in zip(self.sides, self.stage_times, strict=True))
        self._shift_schedule: Callable[[int], None] | None = None
        #: ticks stepped
        self.ticks = 0

    def follow(self, shift_schedule: Callable[[int], None]) -> None:
        """Hand the sides' schedule shifts to ``shift_schedule(delta_ns)`` (the runner's)."""
        self._shift_schedule = shift_schedule

    def step(self, tick: int, now_ns: int) -> None:
        """One tick of every side: its stages in order, each timed."""
        clock = self._clock_ns
        start_ns = now_ns
        for side, stages, times, marks in self._plan:
            index = 0
            for stage in stages:
                inner_ns = stage(tick, now_ns)
                if inner_ns is not None:
                    marks[index] = inner_ns
                    index += 1
                marks[index] = clock()
                index += 1
            times.record(start_ns, marks)
            start_ns = marks[-1]
            shift_ns = side.schedule_shift_ns
            if shift_ns:
                side.schedule_shift_ns = 0
                if self._shift_schedule is not None:
                    self._shift_schedule(shift_ns)
        self.ticks = tick + 1
