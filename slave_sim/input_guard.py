"""Bounds on what the slave accepts from the master: the handle's force and position.

The master bounds its own sensor (master/node.py: non-finite -> trip, |fh| beyond
``force_trip_N`` -> trip, saturation at ``force_limit_N``). The slave does the same to each
received :class:`~haptic.common.wire.messages.HandleState` before its force reaches Ch2, with
the peer-input guard the master puts on the tool's messages (common/runtime/peer_guard.py)
and a saturation and rate limit of its own, so a faulty or forged master message cannot push
the tool harder or faster than the limits of ``[slave.safety]`` allow:

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

from dataclasses import dataclass, field
from typing import Any

from haptic.common.config import ConfigError
from haptic.common.runtime.peer_guard import PeerGuard, PeerGuardCounters, PeerLimits, PeerSide
from haptic.common.wire.send_clock import SendClock

#: What the slave's guard reads and reports (common/runtime/peer_guard.py).
HANDLE_SIDE = PeerSide(
    force_field="handle_force_N", position_field="handle_position_m", noun="handle",
    fault_kind="input_fault", cleared_kind="input_fault_cleared", jump_bound="at most",
    run_noun="messages", summary_key="input_guard",
    summary_counters=("checked", "faults", "saturated", "rate_limited", "non_finite"))


@dataclass(frozen=True)
class InputGuardSettings(PeerLimits):
    """``[slave.safety]``: forces in N, rates in N/s, positions in m, speeds in m/s, times
    in s."""

    force_limit_N: float = 20.0
    force_trip_N: float = 60.0
    force_rate_limit_N_per_s: float = 20000.0
    position_min_m: tuple[float, float] = (-0.16, -0.16)
    position_max_m: tuple[float, float] = (0.16, 0.16)
    velocity_trip_m_per_s: float = 1.0
    jump_margin_m: float = 0.001

    @classmethod
    def from_config(cls, config: dict[str, Any]) -> InputGuardSettings:
        """From a validated configuration's ``[slave.safety]``, with the cross-key checks
        (raises :class:`ConfigError` naming the key)."""
        return cls.from_table(config["slave"]["safety"], "slave.safety")

    def check(self, prefix: str) -> None:
        """The cross-key checks: the trip at or above the saturation, then the box's."""
        if not self.force_trip_N >= self.force_limit_N:
            raise ConfigError(f"{prefix}.force_trip_N", "must be >= force_limit_N")
        super().check(prefix)


@dataclass
class InputGuardCounters(PeerGuardCounters):
    """What the guard did, in messages."""

    saturated: int = 0
    rate_limited: int = 0


@dataclass
class InputGuard(PeerGuard):
    """Checks and bounds the received handle force (N) and position (m); see the module.
    :meth:`admit` returns True when the message is an input: :attr:`force_N` and
    :attr:`position_m` then hold its bounded values; False for a fault (they keep the
    previous ones, and :attr:`faulted` is set).

    ``period_s`` is the slave's tick Ts (the least time one rate-limit step spans).
    """

    side = HANDLE_SIDE
    settings: InputGuardSettings
    counters: InputGuardCounters = field(default_factory=InputGuardCounters)
    force_N: tuple[float, float] = (0.0, 0.0)
    """The bounded force of the latest accepted message, N."""
    _saturating: bool = False
    _rate_limiting: bool = False

    def bound(self, fx: float, fy: float, dt_s: float, now_s: float) -> None:
        """Saturate the plausible force (N) at +-``force_limit_N``, then limit its change
        since the previous input to ``force_rate_limit_N_per_s`` over ``dt_s`` (s); an event
        at each onset."""
        s = self.settings
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
