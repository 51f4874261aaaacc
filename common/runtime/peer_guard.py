"""The peer-input guard both sides put on what they receive: the peer's force and position.

The master bounds each received :class:`~haptic.common.wire.messages.ToolState`
(``[master.tool_input]``, master/tool_guard.py) and the slave each received
:class:`~haptic.common.wire.messages.HandleState` (``[slave.safety]``,
slave_sim/input_guard.py) with the same checks; a :class:`PeerSide` names what differs (the
message's fields, the events' kinds and wording, the summary's key), the side's settings the
limits:

1. a non-finite force or position, a force beyond ``force_trip_N`` on an axis, a position
   outside ``position_min_m`` .. ``position_max_m``, or a position that moved farther than
   ``velocity_trip_m_per_s`` times the send-time difference (at least one period) plus
   ``jump_margin_m`` since the previous accepted message of the same sender epoch is a
   **fault**: the message is not an input (the side keeps the previous one), the fault
   latches and clears after ``clear_after_messages`` plausible messages in a row;
2. otherwise the message is accepted (a side may bound its values further:
   :meth:`PeerGuard.bound`).

The send-time difference is the one :class:`~haptic.common.wire.send_clock.SendClock`
credits: never more than this host's own elapsed time allows (plus ``jitter_allowance_s``),
so a sender that stamps its messages ahead gains no room for a jump. Pure Python floats: a
few us per message.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, ClassVar, TypeVar

from haptic.common.config import ConfigError
from haptic.common.wire.send_clock import SendClock, receive_time_ns

_Limits = TypeVar("_Limits", bound="PeerLimits")
#: a module-level name: one lookup less per call, four calls per message
_isfinite = math.isfinite


@dataclass(frozen=True)
class PeerLimits:
    """The limits both guards share: forces in N, positions in m, speeds in m/s, times in s.
    Each side's settings subclass it (the defaults here are the master's; the slave's
    settings restate theirs and add their further limits)."""

    force_trip_N: float = 200.0
    position_min_m: tuple[float, float] = (-0.5, -0.5)
    position_max_m: tuple[float, float] = (0.5, 0.5)
    velocity_trip_m_per_s: float = 2.0
    jump_margin_m: float = 0.002
    clear_after_messages: int = 20
    jitter_allowance_s: float = 0.005

    @property
    def jitter_allowance_ns(self) -> int:
        """:attr:`jitter_allowance_s` in whole ns."""
        return round(self.jitter_allowance_s * 1e9)

    @classmethod
    def from_table(cls: type[_Limits], table: dict[str, Any], prefix: str) -> _Limits:
        """From a validated table (lists read as tuples) at key ``prefix``, with the cross-key
        checks of :meth:`check` (raises :class:`ConfigError` naming the key)."""
        settings = cls(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in table.items()})
        settings.check(prefix)
        return settings

    def check(self, prefix: str) -> None:
        """The cross-key checks: the position box is not empty on either axis."""
        if not all(lo < hi for lo, hi in zip(self.position_min_m, self.position_max_m,
                                              strict=True)):
            raise ConfigError(f"{prefix}.position_max_m", "must exceed position_min_m per axis")


@dataclass(frozen=True)
class PeerSide:
    """What differs between the two sides' guards besides the limits: names and wording."""

    force_field: str
    """The message's force attribute, (x, y) in N."""
    position_field: str
    """The message's position attribute, (x, y) in m."""
    noun: str
    """What the message describes, in the events' reasons ("tool", "handle")."""
    fault_kind: str
    cleared_kind: str
    jump_bound: str
    """The words before the allowed jump in a jump's reason."""
    run_noun: str
    """What the plausible run counts, in the cleared event's reason."""
    summary_key: str
    summary_counters: tuple[str, ...]
    """The :class:`PeerGuardCounters` fields the summary reports, in order."""


@dataclass
class PeerGuardCounters:
    """What the guard did, in messages."""

    checked: int = 0
    faults: int = 0
    jumps: int = 0
    non_finite: int = 0


@dataclass
class PeerGuard:
    """Checks the received peer force (N) and position (m); see the module. A side subclasses
    it with its :attr:`side` and settings type.

    ``period_s`` is the side's tick Ts (the least time a position jump is measured over).
    ``events``: the list the events go to (the supervisor's).
    """

    side: ClassVar[PeerSide]
    settings: PeerLimits
    period_s: float
    events: list[dict[str, Any]] = field(default_factory=list)
    counters: PeerGuardCounters = field(default_factory=PeerGuardCounters)
    faulted: bool = False
    position_m: tuple[float, float] | None = None
    """The position of the latest accepted message, m (None before the first)."""
    clock: SendClock = field(init=False)
    """The credited send times of the accepted messages."""
    _plausible_run: int = 0

    def __post_init__(self) -> None:
        self.clock = SendClock(self.settings.jitter_allowance_ns)

    def _fault(self, now_s: float, reason: str) -> None:
        self.counters.faults += 1
        self._plausible_run = 0
        self.events.append({"time_s": now_s, "kind": self.side.fault_kind, "reason": reason})
        self.faulted = True

    def admit(self, message: Any, now_s: float) -> bool:
        """Check one received message at loop time ``now_s`` (s): True when it is an input
        (:attr:`position_m` then holds its position), False for a fault (:attr:`faulted` is
        then set and the previous values stay)."""
        s, side = self.settings, self.side
        self.counters.checked += 1
        fx, fy = getattr(message, side.force_field)
        px, py = getattr(message, side.position_field)
        if not (_isfinite(fx) and _isfinite(fy) and _isfinite(px) and _isfinite(py)):
            self.counters.non_finite += 1
            self._fault(now_s, f"non-finite {side.noun} force or position")
            return False
        if abs(fx) > s.force_trip_N or abs(fy) > s.force_trip_N:
            self._fault(now_s, f"{side.noun} force ({fx:.4g}, {fy:.4g}) N beyond "
                        f"+-{s.force_trip_N:g} N")
            return False
        lo, hi = s.position_min_m, s.position_max_m
        if not (lo[0] <= px <= hi[0] and lo[1] <= py <= hi[1]):
            self._fault(now_s, f"{side.noun} position ({px:.4g}, {py:.4g}) m outside the "
                        "plausible box")
            return False
        epoch, send_ns = message.epoch, message.send_time_ns
        now_ns = receive_time_ns(now_s)
        span_s = self.clock.span_s(epoch, send_ns, now_ns, self.period_s)
        previous = self.position_m
        if previous is not None and span_s is not None:
            allowed_m = s.velocity_trip_m_per_s * span_s + s.jump_margin_m
            jump_m = max(abs(px - previous[0]), abs(py - previous[1]))
            if jump_m > allowed_m:
                self.counters.jumps += 1
                self._fault(now_s, f"{side.noun} position jumped {jump_m * 1e3:.3g} mm in "
                            f"{span_s * 1e3:.3g} ms ({side.jump_bound} "
                            f"{allowed_m * 1e3:.3g} mm)")
                return False
        dt_s = self.period_s if span_s is None or previous is None else span_s
        self.bound(fx, fy, dt_s, now_s)
        self.position_m = (px, py)
        self.clock.accept(epoch, send_ns, now_ns)
        if self.faulted:  # counting towards clearing the fault
            self._count_plausible(now_s)
        return True

    def bound(self, fx: float, fy: float, dt_s: float, now_s: float) -> None:
        """A plausible message's force (N), ``dt_s`` (s) after the previous accepted one (one
        period for the first of an epoch): the side's further bounds act here (none by
        default)."""

    def _count_plausible(self, now_s: float) -> None:
        if not self.faulted:
            return
        self._plausible_run += 1
        if self._plausible_run >= self.settings.clear_after_messages:
            self.faulted = False
            self.events.append({"time_s": now_s, "kind": self.side.cleared_kind,
                                "reason": f"{self._plausible_run} plausible "
                                f"{self.side.run_noun} in a row"})

    def summary(self) -> dict[str, Any]:
        """The summary's figures under the side's key: its counters and whether a fault
        holds."""
        counters = {name: getattr(self.counters, name) for name in self.side.summary_counters}
        return {self.side.summary_key: {**counters, "faulted": self.faulted}}


__all__ = ["PeerGuard", "PeerGuardCounters", "PeerLimits", "PeerSide"]
