"""The supervision core both sides' supervisors share (master/supervisor.py,
slave_sim/supervisor.py): what a tick's decision can be (:class:`Transition`), the peer
watchdog, the resync check's geometry and the events list.

Each side's supervisor adds its own rules (the master's fault latch and handle hold, the
slave's work-area guard and resync policy); the core holds only what is the same on both:

- the watchdog (common/runtime/watchdog.py) over the peer's messages, ``max_message_age_s``
  and ``resync_messages`` its limits;
- ``in_sync``: the tool at Ah1 times the handle's position, |yt - Ah1 yh| below
  ``sync_tolerance_m`` on both axes (strictly);
- the flag bits read from the peer's messages, as ints (IntFlag arithmetic costs about 1 us).
"""

from __future__ import annotations

import enum
from typing import Any

from haptic.common.runtime.watchdog import PeerWatchdog
from haptic.common.wire.messages import Flags

FORCES_ENABLED = int(Flags.FORCES_ENABLED)
STOPPING = int(Flags.STOPPING)
WORK_AREA_STOP = int(Flags.WORK_AREA_STOP)


class Transition(enum.Enum):
    """What changed this tick (the program acts on it); each side returns its own subset."""

    NONE = "none"
    ACTIVATE = "activate"  # master: forces on for the first time: MasterNode.activate
    RESUME = "resume"  # master: forces on again (MasterNode.resume); slave: SlaveNode.resume
    HOLD = "hold"  # master: forces off, hold the handle at hold_m
    STOP = "stop"  # slave: the tool stops: SlaveNode.safe_stop


class SupervisionCore:
    """The watchdog and the resync check of one side (see the module).

    ``position_ratio``: Ah1 per axis (x, y), dimensionless; ``sync_tolerance_m``: the resync
    position tolerance per axis, m (> 0, else :class:`ValueError`);
    ``max_message_age_s``/``resync_messages``: the watchdog's.
    """

    def __init__(self, position_ratio: tuple[float, float], sync_tolerance_m: float,
                 max_message_age_s: float, resync_messages: int) -> None:
        if not sync_tolerance_m > 0.0:
            raise ValueError(f"sync_tolerance_m must be > 0 (got {sync_tolerance_m})")
        self.ratio_x, self.ratio_y = (float(v) for v in position_ratio)
        self.sync_tolerance_m = float(sync_tolerance_m)
        self.watchdog = PeerWatchdog(max_message_age_s, resync_messages)
        self.events: list[dict[str, Any]] = []

    def positions_in_sync(self, tool_x_m: float, tool_y_m: float, handle_x_m: float,
                          handle_y_m: float) -> bool:
        """|yt - Ah1 yh| below the tolerance on both axes (positions in m)."""
        tolerance = self.sync_tolerance_m
        return (abs(tool_x_m - self.ratio_x * handle_x_m) < tolerance
                and abs(tool_y_m - self.ratio_y * handle_y_m) < tolerance)

    @property
    def trips(self) -> int:
        """Watchdog trips so far."""
        return self.watchdog.trips


__all__ = ["FORCES_ENABLED", "STOPPING", "WORK_AREA_STOP", "SupervisionCore", "Transition"]
