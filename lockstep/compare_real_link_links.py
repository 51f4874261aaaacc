"""What every real-link cell of the comparison shares: its two links' configurations (TCP on
loopback, the cell's delay and loss injected on each side's receive path), the wait for the
two sides to find each other, the lag record that measures the round trip, and the link's
figures a cell reports.

The round trip is measured as lockstep/real_link.py measures it: each side sends one
message a tick with its sequence number counting ticks from the run's tick 0 (a run-up's
messages, sent one a tick before it, count below 0), so the lag of the newest message a side
holds at tick ``k`` is ``k`` minus its tick; the round trip in samples is the mean lag to the
slave plus the mean lag to the master minus 1 (the tool line's structural sample,
lockstep/compare_links.py), over the run's last three quarters.
"""

from __future__ import annotations

import time
import uuid
from typing import Any

import numpy as np

from haptic.common.wire.injection import InjectionConfig
from haptic.common.wire.link import Link
from haptic.common.wire.link_config import LinkConfig
from haptic.common.wire.ports import free_port

#: Sleep until this long before a tick's deadline, then spin (as lockstep/real_link.py), s.
SPIN_S = 0.0003
#: How long the two sides may take to find each other, s.
MEET_TIMEOUT_S = 10.0


def cell_link_configs(round_trip_s: float, loss: float, seed: int
                      ) -> tuple[LinkConfig, LinkConfig]:
    """(master's, slave's) link configurations: half the round trip (s) injected on each
    side's receive path with independent loss ``loss`` (0..1), each side's draws seeded from
    ``seed`` and its side; a fresh port and key prefix per cell."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    prefix = f"haptic-compare/{uuid.uuid4().hex[:10]}"
    half_s = 0.5 * round_trip_s
    # stale_after_s beyond the injected delay: on a loaded machine a message may wait for a
    # late tick; it is the injection's loss that is measured, not the host's stalls
    common: dict[str, Any] = {"key_prefix": prefix, "congestion_control": "block",
                              "stale_after_s": 10.0}
    injection = InjectionConfig(delay_s=half_s, loss_probability=loss)
    master = LinkConfig(side="master", listen=(endpoint,), injection=injection,
                        seed=2 * seed, **common)
    slave = LinkConfig(side="slave", connect=(endpoint,), injection=injection,
                       seed=2 * seed + 1, **common)
    return master, slave


def wait_for_each_other(master: Link, slave: Link, timeout_s: float = MEET_TIMEOUT_S) -> None:
    """Poll both links until each sees the other's liveliness; RuntimeError after
    ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while not (master.peer_alive and slave.peer_alive):
        master.poll()
        slave.poll()
        if time.monotonic() > deadline:
            raise RuntimeError("the two links of a real-link cell did not find each other")
        time.sleep(0.001)


class LagRecord:
    """Per tick of ``steps``, how many ticks old the newest message each side held was (NaN:
    none yet)."""

    def __init__(self, steps: int) -> None:
        self.to_slave = np.full(steps, np.nan)
        self.to_master = np.full(steps, np.nan)

    @staticmethod
    def lag(tick: int, message_tick: int | None) -> float:
        """``tick`` minus the tick the message was sent in (NaN: no message)."""
        return np.nan if message_tick is None else float(tick - message_tick)

    def tick_round_trips_s(self, period_s: float) -> np.ndarray:
        """Each tick's round trip, s: the two lags it held minus 1, times Ts (NaN before
        both sides had a message)."""
        return (self.to_slave + self.to_master - 1.0) * period_s

    def share_within(self, round_trip_s: float, band: float, period_s: float) -> float:
        """The share of the ticks (from the first with a message on both sides) whose round
        trip lies within ``band`` (a share) of ``round_trip_s``: a loop that stalled, its
        skipped ticks shrinking a wall-clock delay in ticks, has a smaller one (0 when no
        tick had messages both ways)."""
        ticks = self.tick_round_trips_s(period_s)
        ticks = ticks[np.isfinite(ticks)]
        if ticks.size == 0:
            return 0.0
        return float(np.mean(np.abs(ticks - round_trip_s) <= band * round_trip_s))

    def round_trip_s(self, period_s: float) -> float:
        """The measured round trip (s) over the last three quarters of the run (NaN when a
        side never received a message there)."""
        settled = slice(self.to_slave.size // 4, None)
        slave, master = self.to_slave[settled], self.to_master[settled]
        if not (np.isfinite(slave).any() and np.isfinite(master).any()):
            return float("nan")
        return float((np.nanmean(slave) + np.nanmean(master) - 1.0) * period_s)


def link_figures(link: Link) -> dict[str, Any]:
    """What a cell reports of one side's receiving link: messages sent by this side, the
    peer's received, delivered, dropped by reason (injected loss, malformed, non-finite,
    stale, out of order, ...) and the loss ratio measured from the sequence numbers."""
    stats = link.stats()
    return {"sent": link.sent, "received": stats.received, "delivered": stats.delivered,
            "expected": stats.expected, "loss_ratio": stats.loss_ratio,
            "dropped": {reason: count for reason, count in stats.dropped.items() if count},
            "one_way_delay_p50_s": stats.one_way_delay_p50_s}


__all__ = ["SPIN_S", "LagRecord", "cell_link_configs", "link_figures",
           "wait_for_each_other"]
