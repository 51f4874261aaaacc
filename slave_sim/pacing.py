"""How many node steps the slave takes in one tick: one per master sample, not one per tick.

The paper's scheme has no position feedback: the tool follows the handle because both sides
integrate the same force samples (Ch1 and Ch2 the handle force, Ct1 and Ct2 the tool force),
once each (docs/model.md section 6). On one clock the two loops step together and each
master sample is used once. When the master falls behind real time (a busy or slow rig PC:
966 Hz measured against 1852 Hz on a 2-core VM with the emulated CAN rig), a slave stepping
once per tick of its own uses every handle force about twice, and the tool runs ahead of the
handle (38 mm after a 51 mm move in 3 s).

:class:`MasterSamplePacing` counts the master's samples by their sequence numbers instead:
while the tool runs, a tick with no new master sample takes no node step (the virtual tool
and the clay wait for the master's next sample, as a physical plant could not but a
simulated one can), and a tick whose newest message is ``n`` samples on takes ``n`` steps
(messages lost or bunched by the network), at most ``max_steps_per_tick`` so one tick stays
short; the samples beyond that are owed (a backlog) and taken by the next ticks, at most
``max_steps_per_tick`` each, those without a new sample too. The slave's virtual world so runs
on the master's sample clock: its simulated time is the master's sample count times Ts, and
nothing is integrated twice or skipped. A backlog delays the tool (it adds to the loop's
delay), so it is bounded: samples beyond ``max_backlog_samples`` are given up and counted
(``dropped_samples``; each leaves the tool behind the handle by what that sample would have
moved it). Measured on a loaded 2-core VM with 5 % loss and 2 ms jitter, giving up at once
what one tick could not take left the tool 1.6 mm behind a 2 cm sine after 6 s (710 samples
given up of 11 000). While the tool is halted (waiting, tripped,
resyncing) every tick takes one step, as before, and the count restarts at the next message.

``[slave.pacing] follow_master_samples = false`` restores one step per tick.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class PacingSettings:
    """``follow_master_samples``: one node step per master sample (else one per tick);
    ``max_steps_per_tick``: the most steps one tick takes; ``max_backlog_samples``: the most
    samples owed to later ticks (beyond: given up and counted)."""

    follow_master_samples: bool = True
    max_steps_per_tick: int = 4
    max_backlog_samples: int = 32

    @classmethod
    def from_config(cls, config: dict[str, Any]) -> PacingSettings:
        section = config["slave"]["pacing"]
        return cls(bool(section["follow_master_samples"]), int(section["max_steps_per_tick"]),
                   int(section["max_backlog_samples"]))


class MasterSamplePacing:
    """Per tick, the number of node steps (see the module docstring); counts the ticks it
    waited (``waited_ticks``), the steps it caught up (``caught_up_steps``: beyond one per
    tick), the samples it gave up (``dropped_samples``: beyond the backlog's bound) and the
    largest backlog (``max_backlog``)."""

    def __init__(self, settings: PacingSettings) -> None:
        self.settings = settings
        self._last: tuple[int, int] | None = None  # (epoch, seq) of the last sample stepped
        self.waited_ticks = 0
        self.caught_up_steps = 0
        self.dropped_samples = 0
        self.backlog = 0  # samples received but not yet stepped
        self.max_backlog = 0

    def steps(self, running: bool, sample: tuple[int, int] | None) -> int:
        """Node steps for this tick. ``running``: the tool follows the handle this tick;
        ``sample``: (epoch, seq) of the fresh, admitted master message, or None."""
        if not self.settings.follow_master_samples:
            return 1
        if not running:
            # halted: one step per tick; the count restarts with the next message
            self._last = sample
            self.backlog = 0
            return 1
        if sample is None:
            if self._last is None:  # running without a sample yet (a warm start)
                return 1
            if self.backlog == 0:
                self.waited_ticks += 1
                return 0
            return self._take(0)
        last, self._last = self._last, sample
        if last is None or last[0] != sample[0]:
            self.backlog = 0
            return 1  # the first sample, or a new epoch (the master restarted)
        ahead = sample[1] - last[1]
        if ahead <= 0:  # the receive filter drops these; never step backwards
            return self._take(0) if self.backlog else 0
        return self._take(ahead)

    def _take(self, new_samples: int) -> int:
        """Steps for this tick from the backlog plus ``new_samples``; the rest stays owed,
        up to ``max_backlog_samples`` (beyond: given up and counted)."""
        owed = self.backlog + new_samples
        steps = min(owed, self.settings.max_steps_per_tick)
        rest = owed - steps
        if rest > self.settings.max_backlog_samples:
            self.dropped_samples += rest - self.settings.max_backlog_samples
            rest = self.settings.max_backlog_samples
        self.backlog = rest
        self.max_backlog = max(self.max_backlog, rest)
        self.caught_up_steps += steps - 1 if new_samples else steps
        return steps

    def summary(self) -> dict[str, Any]:
        """The counters, for the slave's summary."""
        return {"pacing_follow_master_samples": self.settings.follow_master_samples,
                "pacing_waited_ticks": self.waited_ticks,
                "pacing_caught_up_steps": self.caught_up_steps,
                "pacing_dropped_samples": self.dropped_samples,
                "pacing_max_backlog_samples": self.max_backlog}
