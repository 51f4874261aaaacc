"""A Zenoh link that carries a lane law's messages (common/wire/law_messages.py) instead of
the programs' HandleState and ToolState.

It is :class:`~haptic.common.wire.link.Link` (the session, publisher, subscriber, liveliness,
pairing and the receive path's ordering, injection and counters) with the receive path's
decoder set to the law's schema for the peer's direction, and a send of the law's values.
The master side sends the control's "handle" messages and receives its "tool" messages; the
slave side the other way round.

Its hellos name the control (:attr:`Link.hello_control`, the hello's 8th field:
common/wire/auth.py), and it pairs only with a peer whose hellos name the same one: against
another law, or a program link of the programs' own messages ("paper" or "tdpa"), both
sides' :meth:`Link.wait_for_peer` raise :class:`~haptic.common.wire.errors.LinkOpenError`
naming the two modes, instead of pairing and dropping each other's messages as
``wrong_kind``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from haptic.common.wire.law_messages import LawMessage, LawSchema
from haptic.common.wire.link import Link
from haptic.common.wire.link_config import LinkConfig
from haptic.common.wire.messages import Flags
from haptic.common.wire.receive import ReceivePath

_NO_FLAGS = Flags(0)


class LawLink(Link):
    """One side's end of a lane law's link (use it as a context manager, as :class:`Link`).

    ``control``: the law ("wave", "four-channel", "four-channel-tdpa" or "mmt"), announced in
    this side's hellos and required in the peer's; ``rng`` drives the injected jitter and
    loss (default: seeded from ``config.seed``).
    """

    def __init__(self, config: LinkConfig, control: str,
                 rng: np.random.Generator | None = None, epoch: int | None = None,
                 clock_ns: Callable[[], int] | None = None) -> None:
        if rng is None:
            rng = np.random.default_rng(config.seed)
        extra = {} if clock_ns is None else {"clock_ns": clock_ns}
        super().__init__(config, rng=rng, epoch=epoch, **extra)
        master = config.side == "master"
        self.send_schema = LawSchema(control, "handle" if master else "tool")
        self.receive_schema = LawSchema(control, "tool" if master else "handle")
        self.hello_control = control  # before open(): every hello this side sends names it
        # the law's receive path replaces the programs' (which has drawn nothing from rng)
        self.receive = ReceivePath(self.receive_schema.kind, config.injection, rng,
                                   config.stale_after_s, decoder=self.receive_schema.decode)
        self.unsendable = 0
        """Messages not sent because a value was not finite (a diverged law): the peer
        counts them lost; the sender's records show the divergence."""

    def send_values(self, values: Sequence[float] | np.ndarray,
                    flags: Flags = _NO_FLAGS) -> LawMessage | None:
        """Stamp and publish one message of the law's values (its declared length); returns
        it as sent, or None when a value is not finite (counted in :attr:`unsendable`, its
        sequence number skipped: the peer counts it lost). A Zenoh error is counted, as
        :meth:`Link.send`. Raises ValueError for a wrong length."""
        floats = tuple(float(v) for v in values)
        schema = self.send_schema
        if len(floats) != schema.length:
            raise ValueError(f"{schema.control} {schema.direction} messages carry "
                             f"{schema.length} values (got {len(floats)})")
        epoch, seq = self.epoch, self.next_sequence()
        if not all(map(math.isfinite, floats)):
            self.unsendable += 1
            return None
        send_ns = self._publish(*schema.encode_around_send_time(epoch, seq, int(flags), floats))
        return LawMessage(schema.kind, epoch, seq, send_ns, flags, floats)

    @property
    def latest_law(self) -> LawMessage | None:
        """The newest law message delivered so far (None before the first)."""
        latest = self.receive.last_delivered
        return latest if isinstance(latest, LawMessage) else None

    def summary(self) -> dict[str, object]:
        """:meth:`Link.summary` with the unsendable messages."""
        result = super().summary()
        result["link_unsendable"] = self.unsendable
        return result


__all__ = ["LawLink"]
