"""Bounds on what the slave accepts from the master: the handle's force and position.

The master bounds its own sensor (master/node.py: non-finite -> trip, |fh| beyond
``force_trip_N`` -> trip, saturation at ``force_limit_N``). The slave does the same to each
received :class:`~haptic.common.wire.messages.HandleState` before its force reaches Ch2, so a
faulty or forged master message cannot push the tool harder or faster than the limits of
``[slave.safety]`` allow:

1. a non-finite force or position, a force beyond ``force_trip_N`` on an axis, a position
   outside ``position_min_m`` .. ``position_max_m``, or a position that jumped faster than
   ``velocity_trip_m_per_s`` (plus ``jump_margin_m``) since the previous message of the same
   sender epoch is a **fault**: the message is not an input (the tool keeps the last bounded
   input), the fault latches (the program stops the tool) and clears after
   ``clear_after_messages`` plausible messages in a row; the tool then follows the handle as
   in any resync before it runs again;
2. the force saturates at +-``force_limit_N`` per axis;
3. the force's rate of change is limited to ``force_rate_limit_N_per_s`` per axis (over the
   time since the previous message, at least one tick).

The time since the previous message is the send-time difference as
:class:`~haptic.common.wire.send_clock.SendClock` credits it: never more than this host's own
elapsed time allows (plus ``jitter_allowance_s``), so a sender that stamps its messages ahead
gains no room for a jump.

Every fault, every onset of a saturation or rate limit, and a cleared fault is an event
(``input_fault``, ``input_saturated``, ``input_rate_limited``, ``input_fault_cleared``); the
counters go into the summary (``input_guard``). Pure Python floats: a few us per message.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from haptic.common.config import ConfigError
from haptic.common.wire.messages import HandleState
from haptic.common.wire.send_clock import SendClock, receive_time_ns


@dataclass(frozen=True)
class InputGuardSettings:
    """``[slave.safety]``: forces in N, rates in N/s, positions in m, speeds in m/s, times
    in s."""

    force_limit_N: float = 20.0
    force_trip_N: float = 60.0
    force_rate_limit_N_per_s: float = 20000.0
    position_min_m: tuple[float, float] = (-0.16, -0.16)
    position_max_m: tuple[float, float] = (0.16, 0.16)
    velocity_trip_m_per_s: float = 1.0
    jump_margin_m: float = 0.001
    clear_after_messages: int = 20
    jitter_allowance_s: float = 0.005

    @property
    def jitter_allowance_ns(self) -> int:
        """:attr:`jitter_allowance_s` in whole ns."""
        return round(self.jitter_allowance_s * 1e9)

    @classmethod
    def from_config(cls, config: dict[str, Any]) -> InputGuardSettings:
        """From a validated configuration's ``[slave.safety]``, with the cross-key checks
        (raises :class:`ConfigError` naming the key)."""
        table = config["slave"]["safety"]
        settings = cls(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in table.items()})
        prefix = "slave.safety"
        if not settings.force_trip_N >= settings.force_limit_N:
            raise ConfigError(f"{prefix}.force_trip_N", "must be >= force_limit_N")
        if not all(lo < hi for lo, hi in zip(settings.position_min_m, settings.position_max_m,
                                              strict=True)):
            raise ConfigError(f"{prefix}.position_max_m", "must exceed position_min_m per axis")
        return settings


@dataclass
class InputGuardCounters:
    """What the guard did, in messages."""

    checked: int = 0
    faults: int = 0
    saturated: int = 0
    rate_limited: int = 0
    non_finite: int = 0


@dataclass
class InputGuard:
    """Checks and bounds the received handle force (N) and position (m); see the module.

    ``period_s`` is the slave's tick Ts (the least time one rate-limit step spans).
    """

    settings: InputGuardSettings
    period_s: float
    counters: InputGuardCounters = field(default_factory=InputGuardCounters)
    events: list[dict[str, Any]] = field(default_factory=list)
    faulted: bool = False
    force_N: tuple[float, float] = (0.0, 0.0)
    """The bounded force of the latest accepted message, N."""
    position_m: tuple[float, float] | None = None
    """The position of the latest accepted message, m (None before the first)."""
    clock: SendClock = field(init=False)
    """The credited send times of the accepted messages."""
    _plausible_run: int = 0
    _saturating: bool = False
    _rate_limiting: bool = False

    def __post_init__(self) -> None:
        self.clock = SendClock(self.settings.jitter_allowance_ns)

    def _fault(self, now_s: float, reason: str) -> None:
        self.counters.faults += 1
        self._plausible_run = 0
        self.events.append({"time_s": now_s, "kind": "input_fault", "reason": reason})
        self.faulted = True

    def admit(self, message: HandleState, now_s: float) -> bool:
        """Check one received message at loop time ``now_s`` (s). Returns True when it is an
        input: :attr:`force_N` and :attr:`position_m` then hold its bounded values; False for
        a fault (they keep the previous ones, and :attr:`faulted` is set)."""
        s = self.settings
        self.counters.checked += 1
        fx, fy = message.handle_force_N
        px, py = message.handle_position_m
        if not (math.isfinite(fx) and math.isfinite(fy) and math.isfinite(px)
                and math.isfinite(py)):
            self.counters.non_finite += 1
            self._fault(now_s, "non-finite handle force or position")
            return False
        if abs(fx) > s.force_trip_N or abs(fy) > s.force_trip_N:
            self._fault(now_s, f"handle force ({fx:.4g}, {fy:.4g}) N beyond "
                        f"+-{s.force_trip_N:g} N")
            return False
        lo, hi = s.position_min_m, s.position_max_m
        if not (lo[0] <= px <= hi[0] and lo[1] <= py <= hi[1]):
            self._fault(now_s, f"handle position ({px:.4g}, {py:.4g}) m outside the "
                        "plausible box")
            return False
        epoch, send_time_ns = message.epoch, message.send_time_ns
        now_ns = receive_time_ns(now_s)
        span_s = self.clock.span_s(epoch, send_time_ns, now_ns, self.period_s)
        dt_s = self.period_s if span_s is None or self.position_m is None else span_s
        if span_s is not None and self.position_m is not None:
            allowed_m = s.velocity_trip_m_per_s * dt_s + s.jump_margin_m
            jump_m = max(abs(px - self.position_m[0]), abs(py - self.position_m[1]))
            if jump_m > allowed_m:
                self._fault(now_s, f"handle position jumped {jump_m * 1e3:.3g} mm in "
                            f"{dt_s * 1e3:.3g} ms (at most {allowed_m * 1e3:.3g} mm)")
                return False
        # plausible: saturate, then limit the rate
        limit = s.force_limit_N
        sx, sy = min(max(fx, -limit), limit), min(max(fy, -limit), limit)
        saturated = sx != fx or sy != fy
        step = s.force_rate_limit_N_per_s * dt_s
        px0, py0 = self.force_N
        rx, ry = min(max(sx, px0 - step), px0 + step), min(max(sy, py0 - step), py0 + step)
        rate_limited = rx != sx or ry != sy
        if saturated:
            self.counters.saturated += 1
            if not self._saturating:
                self.events.append({"time_s": now_s, "kind": "input_saturated",
                                    "reason": f"handle force ({fx:.4g}, {fy:.4g}) N held at "
                                    f"+-{limit:g} N"})
        if rate_limited:
            self.counters.rate_limited += 1
            if not self._rate_limiting:
                self.events.append({"time_s": now_s, "kind": "input_rate_limited",
                                    "reason": f"handle force changes faster than "
                                    f"{s.force_rate_limit_N_per_s:g} N/s"})
        self._saturating, self._rate_limiting = saturated, rate_limited
        self.force_N = (rx, ry)
        self.position_m = (px, py)
        self.clock.accept(epoch, send_time_ns, now_ns)
        if self.faulted:
            self._plausible_run += 1
            if self._plausible_run >= s.clear_after_messages:
                self.faulted = False
                self.events.append({"time_s": now_s, "kind": "input_fault_cleared",
                                    "reason": f"{self._plausible_run} plausible messages in "
                                    "a row"})
        return True

    def take_plain(self, count: int, force_N: tuple[float, float],
                   position_m: tuple[float, float], clock: SendClock) -> None:
        """Record ``count`` messages that :meth:`admit` takes as they are (the lockstep's
        quiet lanes, slave_sim/quiet_kernel.py; the guard not faulted), the last of them with
        these values (N, m) and leaving ``clock`` (its epoch, credited send time, receive time
        and lead): the state those :meth:`admit` calls would have left."""
        self.counters.checked += count
        self.force_N = force_N
        self.position_m = position_m
        self.clock = clock
        self._saturating = self._rate_limiting = False

    def summary(self) -> dict[str, Any]:
        """The summary's ``input_guard`` figures."""
        c = self.counters
        return {"input_guard": {"checked": c.checked, "faults": c.faults,
                                "saturated": c.saturated, "rate_limited": c.rate_limited,
                                "non_finite": c.non_finite, "faulted": self.faulted}}
