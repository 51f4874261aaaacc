"""Bounds on what the master accepts from the slave: the tool's position and force.

The slave bounds each received handle message (slave_sim/input_guard.py); the master does
the same to each received :class:`~haptic.common.wire.messages.ToolState` before its force reaches
Ct1 or its position the resync check, so a faulty (or forged, with the session's key) slave
message cannot push the handle or fake a resync (``[master.tool_input]``):

1. a non-finite tool force or position, a tool force beyond ``force_trip_N`` on an axis, a
   tool position outside ``position_min_m`` .. ``position_max_m``, or a position that moved
   farther than the tool can in the time between the two messages (``velocity_trip_m_per_s``
   times the send-time difference, at least one period, plus ``jump_margin_m``; same sender
   epoch; the difference as :class:`~haptic.common.wire.send_clock.SendClock` credits it,
   never more than this host's own elapsed time plus ``jitter_allowance_s``) is a **fault**:
   the message is not an input (the master keeps the previous one), forces go off at once
   (:class:`haptic.master.supervisor.MasterSupervisor`), and the fault clears after
   ``clear_after_messages`` plausible messages in a row; forces come back only once the tool
   is again in sync with the handle (the resync check);
2. otherwise the message is an input (the node saturates the force, master/node.py).

Every fault and every cleared fault is an event (``tool_input_fault``,
``tool_input_fault_cleared``); the counters go into the summary (``tool_input_guard``).
Pure Python floats: a few us per message.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from haptic.common.config import ConfigError
from haptic.common.wire.messages import ToolState
from haptic.common.wire.send_clock import SendClock, receive_time_ns


@dataclass(frozen=True)
class ToolGuardSettings:
    """``[master.tool_input]``: forces in N, positions in m, speeds in m/s, times in s."""

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
    def from_config(cls, config: dict[str, Any]) -> ToolGuardSettings:
        """From a validated configuration's ``[master.tool_input]`` (absent: the defaults),
        with the cross-key check (raises :class:`ConfigError` naming the key)."""
        table = config.get("master", {}).get("tool_input", {})
        settings = cls(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in table.items()})
        if not all(lo < hi for lo, hi in zip(settings.position_min_m, settings.position_max_m,
                                              strict=True)):
            raise ConfigError("master.tool_input.position_max_m",
                              "must exceed position_min_m per axis")
        return settings


@dataclass
class ToolGuardCounters:
    """What the guard did, in messages."""

    checked: int = 0
    faults: int = 0
    jumps: int = 0
    non_finite: int = 0


@dataclass
class ToolInputGuard:
    """Checks the received tool position (m) and force (N); see the module.

    ``period_s`` is the master's tick Ts (the least time a position jump is measured over).
    ``events``: the list the events go to (the supervisor's).
    """

    settings: ToolGuardSettings
    period_s: float
    events: list[dict[str, Any]] = field(default_factory=list)
    counters: ToolGuardCounters = field(default_factory=ToolGuardCounters)
    faulted: bool = False
    position_m: tuple[float, float] | None = None
    """The tool position of the latest accepted message, m (None before the first)."""
    clock: SendClock = field(init=False)
    """The credited send times of the accepted messages."""
    _plausible_run: int = 0

    def __post_init__(self) -> None:
        self.clock = SendClock(self.settings.jitter_allowance_ns)

    def _fault(self, now_s: float, reason: str) -> None:
        self.counters.faults += 1
        self._plausible_run = 0
        self.events.append({"time_s": now_s, "kind": "tool_input_fault", "reason": reason})
        self.faulted = True

    def admit(self, message: ToolState, now_s: float) -> bool:
        """Check one received message at loop time ``now_s`` (s): True when it is an input,
        False for a fault (:attr:`faulted` is then set)."""
        s = self.settings
        self.counters.checked += 1
        fx, fy = message.tool_force_N
        px, py = message.tool_position_m
        if not (math.isfinite(fx) and math.isfinite(fy) and math.isfinite(px)
                and math.isfinite(py)):
            self.counters.non_finite += 1
            self._fault(now_s, "non-finite tool force or position")
            return False
        if abs(fx) > s.force_trip_N or abs(fy) > s.force_trip_N:
            self._fault(now_s, f"tool force ({fx:.4g}, {fy:.4g}) N beyond "
                        f"+-{s.force_trip_N:g} N")
            return False
        lo, hi = s.position_min_m, s.position_max_m
        if not (lo[0] <= px <= hi[0] and lo[1] <= py <= hi[1]):
            self._fault(now_s, f"tool position ({px:.4g}, {py:.4g}) m outside the plausible "
                        "box")
            return False
        epoch, send_ns = message.epoch, message.send_time_ns
        now_ns = receive_time_ns(now_s)
        previous = self.position_m
        dt_s = self.clock.span_s(epoch, send_ns, now_ns, self.period_s)
        if previous is not None and dt_s is not None:
            allowed_m = s.velocity_trip_m_per_s * dt_s + s.jump_margin_m
            jump_m = max(abs(px - previous[0]), abs(py - previous[1]))
            if jump_m > allowed_m:
                self.counters.jumps += 1
                self._fault(now_s, f"tool position jumped {jump_m * 1e3:.3g} mm in "
                            f"{dt_s * 1e3:.3g} ms (the tool moves at most "
                            f"{allowed_m * 1e3:.3g} mm)")
                return False
        self.position_m = (px, py)
        self.clock.accept(epoch, send_ns, now_ns)
        if self.faulted:
            self._plausible_run += 1
            if self._plausible_run >= s.clear_after_messages:
                self.faulted = False
                self.events.append({"time_s": now_s, "kind": "tool_input_fault_cleared",
                                    "reason": f"{self._plausible_run} plausible tool messages "
                                    "in a row"})
        return True

    def summary(self) -> dict[str, Any]:
        """The summary's ``tool_input_guard`` figures."""
        c = self.counters
        return {"tool_input_guard": {"checked": c.checked, "faults": c.faults,
                                     "jumps": c.jumps, "non_finite": c.non_finite,
                                     "faulted": self.faulted}}
