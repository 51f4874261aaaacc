"""The margin governor in lockstep: one governor per lane, fed the echo the delay lines imply.

In the programs the tool message echoes the send time of the handle message the slave had
used (common/wire/messages.py). Here the delay lines say the same exactly: the tool message the
master reads at tick k was sent at tick ``j = tool_schedule[k]``, when the slave had the
handle message of tick ``handle_schedule[j]``; the echo age is ``k - handle_schedule[j]``
ticks. The governed gain goes to the master's compensator at once (``gain_ratio``) and
travels to the slave on the handle line, as ``gain_k`` does in the handle message.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from haptic.master.margin_governor import MarginGovernor


class GovernedLanes:
    """Governors for every lane; ``base_gains_k`` (lanes,) the gains the compensators were
    synthesised for (the ratio k/k0 scales their inputs)."""

    def __init__(self, governors: Sequence[MarginGovernor], base_gains_k: np.ndarray,
                 steps: int) -> None:
        self.governors = list(governors)
        self.base_gains_k = np.asarray(base_gains_k, float)
        if len(self.governors) != self.base_gains_k.size:
            raise ValueError("one governor per lane")
        self.ratio = np.ones(self.base_gains_k.size)
        self.gains_k = np.empty((steps, self.base_gains_k.size))
        """The gain k every lane used at every tick (steps, lanes)."""
        self.beyond_margin = np.zeros(self.base_gains_k.size, bool)
        #: (lanes,) the lanes whose governor asked this tick for the passivity layer
        #: (``tdpa``) and for the paper's scheme back (``paper``): the simulator switches
        #: them (master/tick.py ``switch_passivity``)
        self.switch_on = np.zeros(self.base_gains_k.size, bool)
        self.switch_off = np.zeros(self.base_gains_k.size, bool)
        self.switches = 0
        """Mode requests over the run."""

    def update(self, tick: int, period_s: float, tool_schedule: np.ndarray,
               handle_schedule: np.ndarray) -> np.ndarray:
        """Step every governor at ``tick``; returns the gain ratios k/k0 (lanes,)."""
        sources = tool_schedule[tick]
        self.switch_on[...] = False
        self.switch_off[...] = False
        for lane, governor in enumerate(self.governors):
            j = int(sources[lane])
            echo = int(handle_schedule[j, lane]) if j >= 0 else -1
            age_s = (tick - echo) * period_s if echo >= 0 else None
            decision = governor.update(tick * period_s, age_s)
            self.ratio[lane] = decision.gain_k / self.base_gains_k[lane]
            self.gains_k[tick, lane] = decision.gain_k
            self.beyond_margin[lane] |= decision.beyond_margin
            if decision.mode_request is not None:
                self.switches += 1
                (self.switch_on if decision.mode_request == "tdpa" else self.switch_off)[
                    lane] = True
        return self.ratio

    @property
    def events(self) -> list[dict]:
        """Every governor's events with its lane."""
        return [{**event, "lane": lane} for lane, governor in enumerate(self.governors)
                for event in governor.events]
