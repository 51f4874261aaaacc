"""The display's back-off: the live view gives way to the control loops.

The loops come first. Everything that only shows the run (the programs' display threads, the
view's server and the page it feeds) runs at a fraction of its rate while a loop misses its
ticks, so on a small machine the display loses frames before a loop loses a tick
(docs/interfaces.md, "The view backs off").

:class:`DisplayBackoff` turns a loop's running counts (ticks stepped, overruns) into a rate
scale in ``[min_scale, 1]``: each :meth:`update` looks at the ticks since the previous one;
where more than ``overrun_ratio_limit`` of them overran, the scale halves (down to
``min_scale``); after ``recover_s`` without an overrun beyond the limit it doubles (up to 1).
Counts that go backwards (a program restarted) start a new baseline. Pure arithmetic on the
caller's clock, so any thread can own one.
"""

from __future__ import annotations

from dataclasses import dataclass

#: A loop that overruns more than this fraction of its ticks is missing its period (the
#: loops' own target is 0.1 %).
DEFAULT_OVERRUN_RATIO_LIMIT = 0.001
#: The lowest scale: 60 Hz display frames become 3.75 Hz, the 10 Hz clay maps 0.6 Hz.
DEFAULT_MIN_SCALE = 0.0625
#: Time without overruns before the scale doubles again, s.
DEFAULT_RECOVER_S = 2.0


@dataclass
class DisplayBackoff:
    """The display rate scale (0..1] from a loop's tick and overrun counts."""

    overrun_ratio_limit: float = DEFAULT_OVERRUN_RATIO_LIMIT
    min_scale: float = DEFAULT_MIN_SCALE
    recover_s: float = DEFAULT_RECOVER_S
    #: the current scale of the display rates, 0..1
    scale: float = 1.0
    #: how many times the scale was lowered
    backoffs: int = 0
    _ticks: int | None = None
    _overruns: int = 0
    _since_s: float | None = None

    def __post_init__(self) -> None:
        if not 0.0 < self.min_scale <= 1.0:
            raise ValueError(f"min_scale must be in (0, 1] (got {self.min_scale})")
        if not self.overrun_ratio_limit >= 0.0 or not self.recover_s > 0.0:
            raise ValueError("need overrun_ratio_limit >= 0 and recover_s > 0")

    def update(self, now_s: float, ticks: int, overruns: int) -> float:
        """The loop has stepped ``ticks`` ticks, ``overruns`` of them late, at ``now_s`` (s,
        any monotonic clock); returns the new scale."""
        if self._since_s is None:
            self._since_s = now_s
        if self._ticks is None or ticks < self._ticks or overruns < self._overruns:
            self._ticks, self._overruns = ticks, overruns  # first call or a restart
            return self.scale
        new_ticks = ticks - self._ticks
        if new_ticks <= 0:
            return self.scale
        late = overruns - self._overruns
        self._ticks, self._overruns = ticks, overruns
        if late > self.overrun_ratio_limit * new_ticks:
            if self.scale > self.min_scale:
                self.scale = max(self.min_scale, self.scale * 0.5)
                self.backoffs += 1
            self._since_s = now_s
        elif self.scale < 1.0 and now_s - self._since_s >= self.recover_s:
            self.scale = min(1.0, self.scale * 2.0)
            self._since_s = now_s
        return self.scale


__all__ = ["DEFAULT_MIN_SCALE", "DEFAULT_OVERRUN_RATIO_LIMIT", "DEFAULT_RECOVER_S",
           "DisplayBackoff"]
