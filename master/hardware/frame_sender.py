"""What the CAN driver sends, and when: frames go out at once, or held for a burst
(:class:`Burst`) or for the next SYNC (:class:`UntilSync`), and then back to back as one
burst where the bus can (:func:`~haptic.master.hardware.unix_can.send_burst`).

The sender also knows the driver's own frame ids, so a bus that hands a process its own
frames back (``udp_multicast``) does not make them late frames of the drives.
"""

from __future__ import annotations

import can

from haptic.master.hardware.unix_can import send_burst


class FrameSender:
    """The driver's frames on its bus (:attr:`bus`: None while closed).

    Parameters
    ----------
    own_ids:
        The 11-bit ids the driver sends (NMT, SYNC, its RPDOs, SDO requests, its heartbeat);
        :meth:`send_frame` adds the extra frames' ids.
    """

    __slots__ = ("bus", "own_ids", "own_extended_ids", "held", "for_sync", "holding_for_sync")

    def __init__(self, own_ids: set[int]) -> None:
        self.bus: can.BusABC | None = None
        self.own_ids = own_ids
        self.own_extended_ids: set[int] = set()
        #: Frames held by a :class:`Burst` (None: frames go out as they are sent).
        self.held: list[can.Message] | None = None
        #: Frames an :class:`UntilSync` holds for the next SYNC's burst (sent before anything
        #: else that goes out first, so the frames keep their order).
        self.for_sync: list[can.Message] = []
        self.holding_for_sync = False

    def drop_held(self) -> None:
        """Forget the frames held for the next SYNC (the bus is closing)."""
        self.for_sync = []

    def send(self, frame_id: int, data: bytes, fd: bool = False) -> None:
        """One 11-bit frame (``fd``: CAN FD with bit rate switch), as :meth:`put`."""
        self.put(can.Message(arbitration_id=frame_id, data=data, is_extended_id=False,
                             is_fd=fd, bitrate_switch=fd))

    def send_frame(self, frame_id: int, data: bytes, extended: bool) -> None:
        """One extra frame as is (``extended``: a 29-bit id), remembered as the driver's own."""
        (self.own_extended_ids if extended else self.own_ids).add(frame_id)
        self.put(can.Message(arbitration_id=frame_id, data=data, is_extended_id=extended))

    def put(self, message: can.Message) -> None:
        """Send ``message`` now (after the frames held for the SYNC), or hold it for the
        burst being sent."""
        self.put_all([message])

    def put_all(self, frames: list[can.Message]) -> None:
        """:meth:`put` of ``frames``, in order, as one burst when sent now."""
        if self.held is not None:
            self.held.extend(frames)
            return
        self.send_now(frames)

    def send_now(self, frames: list[can.Message]) -> None:
        """Send ``frames`` as one burst, after the frames held for the SYNC (their place)."""
        assert self.bus is not None
        frames, self.for_sync = self.for_sync + frames, []
        if frames:
            send_burst(self.bus, frames)

    def end_burst(self) -> None:
        """The end of the outermost :class:`Burst`: its frames go out, or wait for the SYNC."""
        held, self.held = self.held, None
        if self.holding_for_sync:
            self.for_sync.extend(held)
        elif self.bus is not None:
            self.send_now(held)


class Burst:
    """Hold the frames sent inside and send them back to back at the end; nested bursts go
    out with the outermost. (A context manager of its own class: a generator's costs more,
    and the loop enters one each tick.)"""

    __slots__ = ("_sender", "_outer")

    def __init__(self, sender: FrameSender) -> None:
        self._sender = sender
        self._outer = False

    def __enter__(self) -> None:
        sender = self._sender
        self._outer = sender.held is None
        if self._outer:
            sender.held = []

    def __exit__(self, *_exc: object) -> None:
        if self._outer:
            self._sender.end_burst()


class UntilSync:
    """Hold the frames sent inside until the next SYNC, which sends them in its burst just
    before itself; anything else sent meanwhile sends them first, in order."""

    __slots__ = ("_sender", "_burst")

    def __init__(self, sender: FrameSender) -> None:
        self._sender = sender
        self._burst: Burst | None = None

    def __enter__(self) -> None:
        sender = self._sender
        if sender.holding_for_sync:
            return
        sender.holding_for_sync = True
        self._burst = Burst(sender)
        self._burst.__enter__()

    def __exit__(self, *exc: object) -> None:
        if self._burst is None:
            return
        try:
            self._burst.__exit__(*exc)
        finally:
            self._sender.holding_for_sync = False
