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
(messages lost or bunched by the network), at most ``max_steps_per_tick`` so a slave that
cannot keep up does not fall further behind by trying. The slave's virtual world so runs on
the master's sample clock: its simulated time is the master's sample count times Ts, and
nothing is integrated twice or skipped. While the tool is halted (waiting, tripped,
resyncing) every tick takes one step, as before, and the count restarts at the next message.

``[slave.pacing] follow_master_samples = false`` restores one step per tick.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class PacingSettings:
    """``follow_master_samples``: one node step per master sample (else one per tick);
    ``max_steps_per_tick``: the most steps one tick takes to catch up."""

    follow_master_samples: bool = True
    max_steps_per_tick: int = 4

    @classmethod
    def from_config(cls, config: dict[str, Any]) -> PacingSettings:
        section = config["slave"]["pacing"]
        return cls(bool(section["follow_master_samples"]), int(section["max_steps_per_tick"]))


class MasterSamplePacing:
    """Per tick, the number of node steps (see the module docstring); counts the steps it
    waited (``waited_ticks``), caught up (``caught_up_steps``) and gave up
    (``dropped_samples``: samples beyond ``max_steps_per_tick``)."""

    def __init__(self, settings: PacingSettings) -> None:
        self.settings = settings
        self._last: tuple[int, int] | None = None  # (epoch, seq) of the last sample stepped
        self.waited_ticks = 0
        self.caught_up_steps = 0
        self.dropped_samples = 0

    def steps(self, running: bool, sample: tuple[int, int] | None) -> int:
        """Node steps for this tick. ``running``: the tool follows the handle this tick;
        ``sample``: (epoch, seq) of the fresh, admitted master message, or None."""
        if not self.settings.follow_master_samples:
            return 1
        if not running:
            # halted: one step per tick; the count restarts with the next message
            self._last = sample
            return 1
        if sample is None:
            if self._last is None:  # running without a sample yet (a warm start)
                return 1
            self.waited_ticks += 1
            return 0
        last, self._last = self._last, sample
        if last is None or last[0] != sample[0]:
            return 1  # the first sample, or a new epoch (the master restarted)
        ahead = sample[1] - last[1]
        if ahead <= 0:  # the receive filter drops these; never step backwards
            return 0
        limit = self.settings.max_steps_per_tick
        if ahead > limit:
            self.dropped_samples += ahead - limit
            ahead = limit
        self.caught_up_steps += ahead - 1
        return ahead

    def summary(self) -> dict[str, Any]:
        """The counters, for the slave's summary."""
        return {"pacing_follow_master_samples": self.settings.follow_master_samples,
                "pacing_waited_ticks": self.waited_ticks,
                "pacing_caught_up_steps": self.caught_up_steps,
                "pacing_dropped_samples": self.dropped_samples}
