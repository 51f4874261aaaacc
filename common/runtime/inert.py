"""No silent inert sessions: a session whose peer is there but whose forces never come on.

A side is *inert* when its peer is present and its messages fresh (the link works) but this
side has not applied forces for ``[supervision] inert_after_s``: the master's start-up gate
waiting for a small handle force the operator never gives, a resync that never completes, a
tool stopped by the work-area guard or an input fault. :class:`InertMonitor` turns that into
an ``inert`` event (and ``inert_cleared`` when forces come on), a status-line suffix, and
summary keys (``inert``, ``inert_episodes``, ``inert_time_s``, ``inert_reason``) that
``haptic-session`` flags in its report.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass
class InertMonitor:
    """Watches one side; ``after_s``: the allowed time without forces with the peer present,
    s. Events go into ``events`` (the program's own list), times in loop seconds."""

    after_s: float
    events: list[dict[str, Any]] = field(default_factory=list)
    inert: bool = False
    episodes: int = 0
    inert_time_s: float = 0.0
    reason: str = ""
    _since_s: float | None = None
    _inert_from_s: float = 0.0

    def update(self, now_s: float, peer_present: bool, forces_on: bool, reason: str) -> bool:
        """One tick at ``now_s`` (s): is the peer present (alive, fresh messages), are this
        side's forces on, and why not (``reason``, only read when they are off). Returns
        whether the side is inert now."""
        if forces_on or not peer_present:
            if self.inert:
                self.inert_time_s += now_s - self._inert_from_s
                self.inert = False
                self.events.append({"time_s": now_s, "kind": "inert_cleared",
                                    "reason": "forces on" if forces_on else "peer gone"})
            self._since_s = None
            return False
        if self._since_s is None:
            self._since_s = now_s
        if not self.inert and now_s - self._since_s >= self.after_s:
            self.inert = True
            self.episodes += 1
            self.reason = reason
            self._inert_from_s = now_s
            self.events.append({"time_s": now_s, "kind": "inert",
                                "reason": f"forces off {now_s - self._since_s:.1f} s with the "
                                f"peer present: {reason}"})
        return self.inert

    def status(self) -> str:
        """The status-line suffix: empty, or ``  INERT: <reason>``."""
        return f"  INERT: {self.reason}" if self.inert else ""

    def summary(self, end_s: float) -> dict[str, Any]:
        """The summary keys, with a still-inert episode counted up to ``end_s`` (s)."""
        total = self.inert_time_s + (end_s - self._inert_from_s if self.inert else 0.0)
        return {"inert": self.episodes > 0, "inert_episodes": self.episodes,
                "inert_time_s": total, "inert_reason": self.reason or None,
                "inert_after_s": self.after_s}
