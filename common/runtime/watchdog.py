"""The application watchdog on the peer's messages, and the re-synchronisation protocol.

Zenoh's liveliness reports a killed peer within milliseconds but a frozen one only after the
lease; :class:`PeerWatchdog` also watches the stream itself. States:

``waiting``
    no peer yet (start-up): safe state, forces off.
``ok``
    fresh messages; forces enabled.
``tripped``
    no fresh message for longer than ``max_age_s`` (or the peer's liveliness token went away):
    the node goes to its safe state (master: hold the handle, no reflected force; slave: stop
    the tool). One ``trip`` event, ``trips`` += 1. The same safe state, with a
    ``peer_ended`` event and ``peer_ends`` += 1 instead, when the peer's last message says
    it ends its run (``Flags.STOPPING``): an orderly end is not a fault.
``resyncing``
    the peer is back: fresh messages are counted, ``resync_messages`` of them in a row (none
    further apart than ``max_age_s``) are needed, and then the node must report its positions
    in sync (``in_sync``, the node's own test, e.g. the tool within a tolerance of the handle
    position after the slave has moved the tool there). Only then ``ok`` again, with an event.

The watchdog decides, the node acts: it reads :attr:`PeerWatchdog.forces_enabled` and
:attr:`PeerWatchdog.state` every tick. It holds no clock; times come in as arguments (s).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

#: Default tolerance of the resync position check |yt - Ah1 yh|, m per axis (both programs'
#: ``--sync-tolerance``; here, in a light module, so their parsers need nothing heavy).
DEFAULT_SYNC_TOLERANCE_M = 0.001


class WatchdogState(enum.StrEnum):
    WAITING = "waiting"
    OK = "ok"
    TRIPPED = "tripped"
    RESYNCING = "resyncing"


@dataclass(frozen=True)
class WatchdogEvent:
    """A state change at ``time_s`` (the caller's clock, s) with a human-readable reason."""

    time_s: float
    kind: str
    reason: str

    def as_dict(self) -> dict[str, object]:
        return {"time_s": self.time_s, "kind": self.kind, "reason": self.reason}


class PeerWatchdog:
    """Message-age watchdog with re-synchronisation before forces are enabled again.

    ``max_age_s``: the longest silence (s) tolerated between fresh messages;
    ``resync_messages``: fresh messages in a row needed after start-up or a trip.
    """

    def __init__(self, max_age_s: float, resync_messages: int) -> None:
        if not max_age_s > 0.0:
            raise ValueError(f"max_age_s must be > 0 (got {max_age_s})")
        if resync_messages < 1:
            raise ValueError(f"resync_messages must be >= 1 (got {resync_messages})")
        self.max_age_s = max_age_s
        self.resync_messages = resync_messages
        self.state = WatchdogState.WAITING
        self.trips = 0
        #: orderly ends of the peer's run (its last message had ``Flags.STOPPING``)
        self.peer_ends = 0
        #: in ``tripped`` because the peer ended its run (until it returns)
        self.peer_ended = False
        self.fresh_in_row = 0
        self.events: list[WatchdogEvent] = []

    @property
    def forces_enabled(self) -> bool:
        """Whether the node may apply forces (only in ``ok``)."""
        return self.state is WatchdogState.OK

    @property
    def safe_state(self) -> bool:
        return self.state is not WatchdogState.OK

    def state_text(self) -> str:
        """Why forces are off or on, for stop reasons: ``watchdog <state>``, or that the
        peer ended its run."""
        if self.peer_ended:
            return "the peer ended its run"
        return f"watchdog {self.state.value}"

    def _event(self, now_s: float, kind: str, reason: str) -> None:
        self.events.append(WatchdogEvent(now_s, kind, reason))

    def update(
        self,
        now_s: float,
        fresh: bool,
        silence_s: float,
        in_sync: bool = True,
        peer_alive: bool = True,
        peer_stopping: bool = False,
    ) -> WatchdogState:
        """One tick: ``fresh`` says a new peer message was delivered this tick, ``silence_s``
        is the time since the last one (s), ``in_sync`` the node's position check,
        ``peer_alive`` the peer's liveliness and ``peer_stopping`` that the delivered message
        is the peer's last (``Flags.STOPPING``: it is not counted as fresh, whatever ``fresh``
        says). Returns the new state."""
        state = self.state
        if peer_stopping:
            if state is not WatchdogState.TRIPPED:  # the safe state, until the peer returns
                self.state = WatchdogState.TRIPPED
                self.peer_ends += 1
                self.peer_ended = True
                self.fresh_in_row = 0
                self._event(now_s, "peer_ended", "the peer ended its run (its last message "
                            "said so): safe state until it returns")
            return self.state
        silent = silence_s > self.max_age_s
        if state is WatchdogState.OK:
            if silent or not peer_alive:
                reason = (
                    "peer liveliness token gone" if not peer_alive
                    else f"no fresh message for {silence_s * 1e3:.1f} ms "
                    f"(max {self.max_age_s * 1e3:.1f} ms)"
                )
                self.state = WatchdogState.TRIPPED
                self.trips += 1
                self.fresh_in_row = 0
                self._event(now_s, "trip", reason)
            return self.state
        if state is WatchdogState.TRIPPED:
            if fresh and peer_alive:
                self.state = WatchdogState.RESYNCING
                self.peer_ended = False
                self.fresh_in_row = 1
                self._event(now_s, "peer_returned", "fresh message after a trip; resyncing")
            return self.state
        # waiting or resyncing: count fresh messages in a row, then require positions in sync
        if silent or not peer_alive:
            self.fresh_in_row = 0
            if fresh and peer_alive:
                self.fresh_in_row = 1
        elif fresh:
            self.fresh_in_row += 1
        if self.fresh_in_row >= self.resync_messages and in_sync:
            previous = self.state
            self.state = WatchdogState.OK
            self._event(
                now_s,
                "forces_enabled",
                f"{self.fresh_in_row} fresh messages and positions in sync "
                f"(after {previous.value})",
            )
        return self.state
