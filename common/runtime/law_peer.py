"""One networked program's end of a lane law (``[control] mode`` = ``wave``,
``four-channel``, ``four-channel-tdpa`` or ``mmt``): the newest peer message as the law reads
it, the watchdog over the peer's messages, and this side's message out. Both programs' law
stages hold one (master/law_program.py, slave_sim/law_program.py).

The contract with the law (common/control/law_pairs.py), as on the comparison's delay lines:
``message`` (1, channels) holds the newest peer message's values, ``fresh`` (1,) says one
arrived this tick; a lost or late message leaves the previous values (the law holds them).
The watchdog (common/runtime/watchdog.py) counts a delivered message as fresh unless it is the
peer's last (``Flags.STOPPING``): forces are on only in ``ok``, after ``resync_messages``
fresh messages in a row, and go off after ``max_message_age_s`` of silence or when the peer's
liveliness goes. The laws align the two sides themselves (their position channels, or the wave
integrals' drift correction), so the resync needs no position test. A side in its safe state
keeps sending its last values with ``Flags.SAFE_STATE``: the peer's watchdog sees it alive.
"""

from __future__ import annotations

import numpy as np

from haptic.common.control.law_pairs import ControlPair, make_pair
from haptic.common.control.law_settings import LawSettings
from haptic.common.runtime.program_harness import ProgramHarness
from haptic.common.runtime.runner import StopSignals
from haptic.common.runtime.watchdog import PeerWatchdog, WatchdogState
from haptic.common.wire.law_link import LawLink
from haptic.common.wire.messages import Flags

_STOPPING = int(Flags.STOPPING)


class LawPeer:
    """The peer's messages in, this side's out, and the watchdog (see the module).

    ``link``: this side's law link (open); ``initial``: the peer message the law reads before
    the first arrives, (1, channels); ``outgoing_channels``: the length of this side's
    message; ``max_age_s`` and ``resync_messages``: the watchdog's.
    """

    def __init__(self, link: LawLink, initial: np.ndarray, outgoing_channels: int,
                 max_age_s: float, resync_messages: int) -> None:
        self.link = link
        self.message = np.array(initial, dtype=float, copy=True)
        self.fresh = np.zeros(1, bool)
        self.outgoing = np.zeros((1, outgoing_channels))
        self.watchdog = PeerWatchdog(max_age_s, resync_messages)
        #: the newest message's tick on the peer's side (its sequence number; None: none yet)
        self.latest_seq: int | None = None

    def poll(self, now_s: float) -> bool:
        """Take the newest peer message, step the watchdog at ``now_s`` (s since the run's
        start); returns whether forces are enabled (the watchdog is ``ok``)."""
        link = self.link
        received = link.poll()
        stopping = False
        if received is not None:
            self.message[0] = received.values
            self.latest_seq = received.seq
            stopping = bool(int(received.flags) & _STOPPING)
        fresh = received is not None and not stopping
        self.fresh[0] = fresh
        state = self.watchdog.update(now_s, fresh, link.silence_s(), True, link.peer_alive,
                                     stopping)
        return state is WatchdogState.OK

    def send(self, enabled: bool) -> None:
        """This side's message (:attr:`outgoing`, as the law last wrote it), flagged
        FORCES_ENABLED or SAFE_STATE."""
        self.link.send_values(self.outgoing[0],
                              Flags.FORCES_ENABLED if enabled else Flags.SAFE_STATE)

    def send_stop(self) -> None:
        """The last message of the run (SAFE_STATE | STOPPING): the peer goes to its safe
        state at once and counts no trip."""
        self.link.send_values(self.outgoing[0], Flags.SAFE_STATE | Flags.STOPPING)


def meet_law_peer(harness: ProgramHarness, link: LawLink, control: str, settings: LawSettings,
                  peer_wait_s: float | None, signals: StopSignals
                  ) -> tuple[ControlPair, LawPeer] | int:
    """Wait for the peer (``peer_wait_s``: at most this long, s; None: until stopped), then
    build ``control``'s pair on one lane and this side's :class:`LawPeer` (the master's
    reads tool messages and sends handle messages, the slave's the other way round).
    Returns the exit status instead when the peer did not come (ProgramHarness.wait_for_peer);
    raises LinkOpenError for a peer in another control mode."""
    came = harness.wait_for_peer(peer_wait_s, signals, preface=f"[control] mode = {control}: ")
    if came is not None:
        return came
    pair = make_pair(control, 1, settings)
    handle_initial, tool_initial = pair.initial_messages(1)
    master = link.config.side == "master"
    config = link.config
    peer = LawPeer(link, tool_initial if master else handle_initial,
                   pair.handle_channels if master else pair.tool_channels,
                   config.max_message_age_s, config.resync_messages)
    return pair, peer


__all__ = ["LawPeer", "meet_law_peer"]
