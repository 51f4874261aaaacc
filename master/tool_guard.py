"""Bounds on what the master accepts from the slave: the tool's position and force.

The slave bounds each received handle message (slave_sim/input_guard.py); the master does
the same, with the same guard (common/runtime/peer_guard.py), to each received
:class:`~haptic.common.wire.messages.ToolState` before its force reaches Ct1 or its position
the resync check, so a faulty (or forged, with the session's key) slave message cannot push
the handle or fake a resync (``[master.tool_input]``):

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

from dataclasses import dataclass, field
from typing import Any

from haptic.common.runtime.peer_guard import PeerGuard, PeerGuardCounters, PeerLimits, PeerSide

#: What the master's guard reads and reports (common/runtime/peer_guard.py).
TOOL_SIDE = PeerSide(
    force_field="tool_force_N", position_field="tool_position_m", noun="tool",
    fault_kind="tool_input_fault", cleared_kind="tool_input_fault_cleared",
    jump_bound="the tool moves at most", run_noun="tool messages",
    summary_key="tool_input_guard", summary_counters=("checked", "faults", "jumps", "non_finite"))


@dataclass(frozen=True)
class ToolGuardSettings(PeerLimits):
    """``[master.tool_input]``: forces in N, positions in m, speeds in m/s, times in s."""

    @classmethod
    def from_config(cls, config: dict[str, Any]) -> ToolGuardSettings:
        """From a validated configuration's ``[master.tool_input]`` (absent: the defaults),
        with the cross-key check (raises :class:`ConfigError` naming the key)."""
        table = config.get("master", {}).get("tool_input", {})
        return cls.from_table(table, "master.tool_input")


#: What the guard did, in messages.
ToolGuardCounters = PeerGuardCounters


@dataclass
class ToolInputGuard(PeerGuard):
    """Checks the received tool position (m) and force (N); see the module.

    ``period_s`` is the master's tick Ts (the least time a position jump is measured over).
    ``events``: the list the events go to (the supervisor's).
    """

    side = TOOL_SIDE
    settings: ToolGuardSettings
    counters: ToolGuardCounters = field(default_factory=ToolGuardCounters)
