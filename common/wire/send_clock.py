"""The time between a peer's messages as an input guard counts it: the sender's stamps, never
more than this host's own clock allows.

The guards (slave_sim/input_guard.py, master/tool_guard.py) bound how far a position may jump
and how fast a force may change *per unit of time between two messages*. Taken from the send
stamps alone, that time is the sender's to choose: the receive path accepts a send time up to
``stale_after_s`` ahead of this host's clock, so one message stamped that far ahead would be
allowed a jump of ``velocity_trip x stale_after_s`` (about 50 mm), and a sender that stamps
each message a little further ahead gains that again and again.

:class:`SendClock` credits a message with its send time, but at most with this host's receive
time plus the sender's *lead* (send minus receive time, in the two hosts' clocks) plus
``allowance_ns``. The lead starts as the epoch's first accepted message's and rises towards a
higher one (a path that got faster, clocks that drift) by at most 1 % of the receive time
elapsed (:data:`LEAD_RISE_DIVISOR`). So over any stretch of an epoch the credited time is at
most the receiver's elapsed time x 1.01 + ``allowance_ns``, whatever the stamps say. A
legitimate sender loses nothing: its messages' delays vary by less than the allowance
(jitter), and where a credited time falls short of the stamps, it is the receiver's elapsed
time, which is what the tool or handle can really have moved in.

Integer nanoseconds throughout: slave_sim/quiet_kernel.py repeats :meth:`SendClock.credit`
and :meth:`SendClock.accept` per lane and must agree bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass

#: The lead rises by at most the receive time elapsed divided by this (1 %).
LEAD_RISE_DIVISOR = 100


def receive_time_ns(now_s: float) -> int:
    """A loop time (s) as the integer ns the clock counts in (truncated, as the quiet kernels
    convert it)."""
    return int(now_s * 1e9)


@dataclass
class SendClock:
    """The credited send times of one peer's messages (ns); see the module.

    ``allowance_ns``: how much further ahead of its usual lead a message's send time may be
    (its delay that much shorter than usual) and still be counted in full, ns.
    """

    allowance_ns: int
    epoch: int | None = None
    """The sender epoch of the latest accepted message (None before the first)."""
    credited_ns: int = 0
    """The credited send time of the latest accepted message, ns."""
    received_ns: int = 0
    """When the latest accepted message was taken, this host's loop time, ns."""
    lead_ns: int = 0
    """The sender's lead over this host's clock (send minus receive time) that is counted in
    full, ns."""

    def credit(self, send_ns: int, now_ns: int) -> int:
        """The credited send time of a message of :attr:`epoch` sent at ``send_ns`` and taken
        at ``now_ns`` (ns): the send time, or the receive time plus the lead plus the
        allowance where that is earlier."""
        return min(send_ns, now_ns + self.lead_ns + self.allowance_ns)

    def span_s(self, epoch: int, send_ns: int, now_ns: int, least_s: float) -> float | None:
        """The time (s) between the latest accepted message and this one (``epoch``, sent at
        ``send_ns``, taken at ``now_ns``), credited, at least ``least_s``; None where no
        message of this epoch was accepted before."""
        if self.epoch is None or epoch != self.epoch:
            return None
        return max((self.credit(send_ns, now_ns) - self.credited_ns) * 1e-9, least_s)

    def accept(self, epoch: int, send_ns: int, now_ns: int) -> None:
        """Take the message (``epoch``, sent at ``send_ns``, taken at ``now_ns``, ns) as the
        latest one: a new epoch starts its lead afresh; in the same one the lead rises
        towards this message's by at most 1 % of the time elapsed."""
        lead_ns = send_ns - now_ns
        if self.epoch is None or epoch != self.epoch:
            self.epoch, self.credited_ns, self.received_ns = epoch, send_ns, now_ns
            self.lead_ns = lead_ns
            return
        self.credited_ns = self.credit(send_ns, now_ns)
        # never lower (a time going back rises by nothing)
        risen_ns = self.lead_ns + (now_ns - self.received_ns) // LEAD_RISE_DIVISOR
        self.lead_ns = max(self.lead_ns, min(lead_ns, risen_ns))
        self.received_ns = now_ns


__all__ = ["LEAD_RISE_DIVISOR", "SendClock", "receive_time_ns"]
