"""Re-synchronising the halted tool with the handle without carrying it through clay.

After a watchdog trip (or at start-up) the slave waits, halted, until the tool is back at
``Ah1 yh`` (the position ratio of the paper's design, eq 12). Placing the tool there at once
carries it through whatever clay lies between where it stopped and the handle: a loaded run
left a 2 cm uncut bridge in the middle of its groove that way.

The policy here: **the tool goes to the handle through the clay at a bounded speed, cutting
as it goes.** Each fresh message of the safe state :meth:`ToolResync.step` moves the halted
tool along the straight line towards ``Ah1 yh`` by at most ``speed_m_s`` times the time since
its last step (Ts when not given, at most ``MAX_STEP_PERIODS`` periods, so a late or lossy
loop keeps the speed) and steps the environment with that move, so the proxy (docs/clay.md)
cuts every cell on the way and the removed volume stays the swept volume. Where the last move
cut nothing (free air, or back along its own groove) the tool goes at ``free_speed_m_s``
(the master's handle rate limit), so a tool that ran ahead of the handle, or a handle far
away in free space, is met quickly. The tool is moved kinematically (its velocity state
stays zero: the node resumes it at rest) and no force goes back while halted. The handle is
held by the master in its safe state, so the tool arrives; the watchdog's ``in_sync`` test
(|yt - Ah1 yh| below its tolerance) then ends the resync as before.

Why this and not moving the handle's reference to the tool: the paper's loop keeps the
position ratio ``yt = Ah1 yh`` without any position feedback (the compensators act on forces
alone), so a reference offset would stay for the rest of the session and every later check of
the ratio would have to carry it; moving the tool keeps the relation, and the slow approach
through the clay costs about ``distance / speed`` (0.1 s for 2 mm at 0.02 m/s).
"""

from __future__ import annotations

import numpy as np

from haptic.slave_sim.node import SlaveNode, SlaveState
from haptic.slave_sim.tool import POSITION_COLUMNS, VELOCITY_COLUMNS

#: Speed at which a halted tool is brought to the handle through the clay, m/s: below the
#: paper's cutting speeds (0.03-0.15 m/s), so the clay's push when the tool resumes is at most
#: B_max times this (2 N for 100 N s/m).
RESYNC_SPEED_M_S = 0.02
#: Speed where the last resync move cut nothing, m/s: the master's default handle rate limit
#: ([master.safety] velocity_limit_m_per_s), so the tool can catch a handle moving at it.
RESYNC_FREE_SPEED_M_S = 0.25
#: The longest time one step may account for, in sample periods (a loop that stalled for
#: longer does not jump).
MAX_STEP_PERIODS = 20


class ToolResync:
    """Brings ``node``'s halted tool to ``Ah1 yh`` at ``speed_m_s`` at most while cutting,
    ``free_speed_m_s`` where its last move cut nothing."""

    def __init__(self, node: SlaveNode, speed_m_s: float = RESYNC_SPEED_M_S,
                 free_speed_m_s: float = RESYNC_FREE_SPEED_M_S) -> None:
        if not (speed_m_s > 0.0 and free_speed_m_s >= speed_m_s):
            raise ValueError("the resync speeds must be > 0 m/s, the free one at least the "
                             f"cutting one (got {speed_m_s}, {free_speed_m_s})")
        self.node = node
        self.speed_m_s = float(speed_m_s)
        self.free_speed_m_s = float(free_speed_m_s)
        self._cut_last: np.ndarray | None = None  # (lanes,) the last move removed clay
        self._last_s: float | None = None

    def target_m(self, handle_position_m: np.ndarray) -> np.ndarray:
        """``Ah1 yh`` for received handle positions (lanes, 2) or (2,), m."""
        return self.node.position_ratio * np.asarray(handle_position_m, float)

    def step(self, state: SlaveState, handle_position_m: np.ndarray,
             now_s: float | None = None, lanes: np.ndarray | None = None) -> np.ndarray:
        """One tick of the safe state: every lane (all must be halted) moves towards
        ``Ah1 yh`` by at most ``speed_m_s * Ts`` and the environment cuts along the move;
        returns the distance (m) left per lane. ``now_s``: the caller's clock (s); the move
        covers the time since the previous call (one period without it). ``lanes``: a bool
        mask of the lanes that move (default all; the lockstep's lanes resync one by one):
        the others are left as they are, their environment stepped without a move."""
        moving = np.ones(state.lanes, bool) if lanes is None else np.asarray(lanes, bool)
        if not state.halted[moving].all():
            raise ValueError("ToolResync.step moves halted tools only (call safe_stop first)")
        node = self.node
        count = state.lanes
        period = node.sample_period_s
        elapsed = period
        if now_s is not None:
            if self._last_s is not None:
                elapsed = min(max(now_s - self._last_s, period), MAX_STEP_PERIODS * period)
            self._last_s = float(now_s)
        if self._cut_last is None or self._cut_last.shape != (count,):
            self._cut_last = np.ones(count, bool)  # unknown: assume clay
        speed = np.where(self._cut_last, self.speed_m_s, self.free_speed_m_s)
        max_step = speed * elapsed
        previous = state.tool[:, POSITION_COLUMNS]
        target = np.broadcast_to(self.target_m(handle_position_m), (count, 2))
        if lanes is not None:
            target = np.where(moving[:, None], target, previous)
        offset = target - previous
        distance = np.sqrt((offset * offset).sum(axis=1))
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = np.where(distance > max_step, max_step / distance, 1.0)
        move = offset * scale[:, None]
        position = previous + move
        velocity = move / elapsed
        result = node.environment.step(state.environment, previous, position, velocity,
                                       np.zeros((count, 2)))
        moved = (move * move).sum(axis=1) > 0.0
        self._cut_last = np.where(moved, np.asarray(result.removed_volume_m3) > 0.0,
                                  self._cut_last)
        if lanes is None:
            state.tool[:, POSITION_COLUMNS] = position
            state.tool[:, VELOCITY_COLUMNS] = 0.0
            state.compensator[...] = 0.0
            state.actuator_force_N = np.zeros_like(state.actuator_force_N)
            state.tool_force_N = np.zeros_like(state.tool_force_N)
            state.handle_position_m = np.array(np.broadcast_to(handle_position_m,
                                                               state.handle_position_m.shape))
        else:
            rows = np.flatnonzero(moving)
            for column, value in zip(POSITION_COLUMNS, position.T, strict=True):
                state.tool[rows, column] = value[rows]
            for column in VELOCITY_COLUMNS:
                state.tool[rows, column] = 0.0
            state.compensator[rows] = 0.0
            for name in ("actuator_force_N", "tool_force_N", "handle_position_m"):
                setattr(state, name, np.array(getattr(state, name)))  # never write an alias
            state.actuator_force_N[rows] = 0.0
            state.tool_force_N[rows] = 0.0
            state.handle_position_m[rows] = np.broadcast_to(
                handle_position_m, state.handle_position_m.shape)[rows]
        left = target - position
        return np.sqrt((left * left).sum(axis=1))


__all__ = ["MAX_STEP_PERIODS", "RESYNC_FREE_SPEED_M_S", "RESYNC_SPEED_M_S", "ToolResync"]
