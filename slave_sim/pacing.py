"""How many node steps the slave takes in one tick: one per master sample, not one per tick.

The paper's scheme has no position feedback: the tool follows the handle because both sides
integrate the same force samples (Ch1 and Ch2 the handle force, Ct1 and Ct2 the tool force),
once each (docs/model.md section 6). On one clock the two loops step together and each
master sample is used once. When the master falls behind real time (a busy or slow rig PC
at half its rate), a slave stepping once per tick of its own uses every handle force about
twice, and the tool runs ahead of the handle (by centimetres within seconds).

:class:`MasterSamplePacing` counts the master's samples by their sequence numbers instead:
while the tool runs, a tick with no new master sample takes no node step (the virtual tool
and the clay wait for the master's next sample, as a physical plant could not but a
simulated one can), and a tick whose newest message is ``n`` samples on takes ``n`` steps
(messages lost or bunched by the network), at most ``max_steps_per_tick`` so one tick stays
short; the samples beyond that are owed (a backlog) and taken by the next ticks, at most
``max_steps_per_tick`` each, those without a new sample too. The slave's virtual world so runs
on the master's sample clock: its simulated time is the master's sample count times Ts, and
nothing is integrated twice or skipped. A backlog delays the tool (it adds to the loop's
delay), so it is bounded: a tick that would leave more than ``max_backlog_samples`` owed takes
the excess at once (a longer tick; ``burst_steps`` counts those steps, ``max_tick_steps`` the
most one tick took) instead of giving samples up. A sample given up is a force Ch1 integrated
and Ch2 never will: it leaves the tool behind the handle for good in the paper's scheme, which
has no position feedback: on a loaded host with loss and jitter, giving up at once what one
tick could not take left the tool millimetres behind a 2 cm sine within seconds, each sample
given up a sample's motion (tests/master/test_governed_programs.py runs the slave beside
CPU hogs). The burst is bounded in practice by the watchdog (``[link.watchdog]
max_message_age_s``, 30 ms: a longer stall halts the tool and clears the backlog), and what
one message can make owed is bounded below. Samples are given up (``dropped_samples``) only
where a jump in the sequence (messages lost on the way) owes more than ``max_steps_per_tick +
max_backlog_samples`` interpolated steps: the oldest of those, which no sample carried. While
the tool is halted (waiting, tripped, resyncing) every tick takes one step, as before, and the
count restarts at the next message.

Each step uses its own sample's bounded force, position and force scale (the master's force
ramp), not the newest's: the link hands over every message delivered in the tick
(``Link.delivered``), each passes the input guard (slave_sim/tick.py, ``SlaveTick.samples``),
and :meth:`MasterSamplePacing.plan` returns one entry per step. A lost sample (a gap in the
sequence) is stepped with the values interpolated linearly between the samples on either side
of it: the master's Ch1 integrated the force it measured then, which lies closer to that line
than to either end.

``[slave.pacing] follow_master_samples = false`` restores one step per tick.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

#: One admitted master sample: (epoch, seq, (fx, fy) N, (x, y) m, the master's force ramp
#: 0..1) (``SlaveTick.samples``).
Sample = tuple[int, int, tuple[float, float], tuple[float, float], float]
#: One node step: the handle force (fx, fy) N, position (x, y) m and force scale to step
#: with, or ``None``: the tick's own input (the newest admitted message's, as ``SlaveTick``
#: holds it).
Step = tuple[float, float, float, float, float] | None


@dataclass(frozen=True)
class PacingSettings:
    """``follow_master_samples``: one node step per master sample (else one per tick);
    ``max_steps_per_tick``: the steps one tick takes while the backlog is within bounds;
    ``max_backlog_samples``: the most samples owed to later ticks (beyond: taken at once)."""

    follow_master_samples: bool = True
    max_steps_per_tick: int = 4
    max_backlog_samples: int = 32

    @classmethod
    def from_config(cls, config: dict[str, Any]) -> PacingSettings:
        section = config["slave"]["pacing"]
        return cls(bool(section["follow_master_samples"]), int(section["max_steps_per_tick"]),
                   int(section["max_backlog_samples"]))


class MasterSamplePacing:
    """Per tick, the node steps to take, each with its sample's input (see the module
    docstring); counts the ticks it waited (``waited_ticks``), the steps it caught up
    (``caught_up_steps``: beyond one per tick), the steps for lost samples
    (``interpolated_steps``), the steps it took at once because the backlog was full
    (``burst_steps``) and the most steps in one tick (``max_tick_steps``), the lost samples it
    gave up (``dropped_samples``: beyond what one sequence jump may owe) and the largest backlog
    (``max_backlog``)."""

    def __init__(self, settings: PacingSettings) -> None:
        self.settings = settings
        self._last: Sample | None = None  # the last sample queued for a step
        self._owed: deque[tuple[float, float, float, float, float]] = deque()
        self.waited_ticks = 0
        self.caught_up_steps = 0
        self.interpolated_steps = 0
        self.dropped_samples = 0
        self.burst_steps = 0
        self.max_tick_steps = 0
        self.max_backlog = 0

    @property
    def backlog(self) -> int:
        """Samples received but not yet stepped."""
        return len(self._owed)

    def plan(self, running: bool, samples: Sequence[Sample]) -> list[Step]:
        """The node steps of this tick, one entry each. ``running``: the tool follows the
        handle this tick; ``samples``: the admitted master samples delivered this tick, in
        order (none: nothing new)."""
        if not self.settings.follow_master_samples:
            return [None]
        owed = self._owed
        if not running:
            # halted: one step per tick with the tick's input; the count restarts with the
            # next sample
            self._last = samples[-1] if samples else None
            owed.clear()
            return [None]
        if not samples:
            if self._last is None:  # running without a sample yet (a warm start)
                return [None]
            if not owed:
                self.waited_ticks += 1
                return []
            return self._take(False)
        new = any([self._queue(sample) for sample in samples])  # every one queued
        return self._take(new)  # none new and none owed: no step

    def _queue(self, sample: Sample) -> bool:
        """Owe the steps up to ``sample``: one per sample since the last one queued, the lost
        ones interpolated; returns whether it queued any (not for an old sequence)."""
        last = self._last
        owed = self._owed
        epoch, seq, (fx, fy), (x, y), scale = sample
        if last is None or last[0] != epoch:
            owed.clear()  # the first sample, or a new epoch (the master restarted)
            owed.append((fx, fy, x, y, scale))
            self._last = sample
            return True
        ahead = seq - last[1]
        if ahead <= 0:  # the receive filter drops these; never step backwards
            return False
        self._last = sample
        _, _, (fx0, fy0), (x0, y0), scale0 = last
        keep = self.settings.max_steps_per_tick + self.settings.max_backlog_samples
        first = max(1, ahead - keep + 1)  # the oldest lost samples beyond the bound: given up
        self.dropped_samples += first - 1
        for index in range(first, ahead + 1):
            weight = index / ahead
            owed.append((fx0 + weight * (fx - fx0), fy0 + weight * (fy - fy0),
                         x0 + weight * (x - x0), y0 + weight * (y - y0),
                         scale0 + weight * (scale - scale0)))
        self.interpolated_steps += ahead - first
        return True

    def _take(self, new_sample: bool) -> list[Step]:
        """This tick's steps, the oldest owed first: ``max_steps_per_tick``, and all that
        would leave more than ``max_backlog_samples`` owed (counted as ``burst_steps``);
        ``new_sample``: the tick brought one (its step is the tick's own, not caught up)."""
        owed = self._owed
        settings = self.settings
        count = min(len(owed), settings.max_steps_per_tick)
        burst = max(len(owed) - count - settings.max_backlog_samples, 0)
        count += burst
        self.burst_steps += burst
        steps: list[Step] = [owed.popleft() for _ in range(count)]
        self.max_backlog = max(self.max_backlog, len(owed))
        self.max_tick_steps = max(self.max_tick_steps, count)
        self.caught_up_steps += len(steps) - 1 if new_sample else len(steps)
        return steps

    def summary(self) -> dict[str, Any]:
        """The counters, for the slave's summary."""
        return {"pacing_follow_master_samples": self.settings.follow_master_samples,
                "pacing_waited_ticks": self.waited_ticks,
                "pacing_caught_up_steps": self.caught_up_steps,
                "pacing_interpolated_steps": self.interpolated_steps,
                "pacing_dropped_samples": self.dropped_samples,
                "pacing_burst_steps": self.burst_steps,
                "pacing_max_tick_steps": self.max_tick_steps,
                "pacing_max_backlog_samples": self.max_backlog}
