"""A python-can interface between processes on one host: CAN frames as Unix datagrams.

``can.Bus(interface="unix_datagram", channel=DIRECTORY)`` joins the bus named by a directory
(created if missing). Every bus on the same directory hears every frame the others send, and
not its own (a real CAN controller's default). Registered with python-can through the
``can.interface`` entry point of this package, so any program that opens a python-can bus by
name can use it (``haptic-master --rig can --can-interface unix_datagram --can-channel DIR``).

Why not ``udp_multicast``: on a virtual machine a multicast datagram also leaves by the
network device (a VM exit per frame) and comes back to its own sender, so a SYNC answered by
three frames between two processes takes about twice as long over multicast sockets as over
Unix datagram sockets, before any python-can or rig code (docs/measurements/can_stack.md has
the figures).

Membership: each bus binds ``DIRECTORY/<pid>-<n>.sock`` and sends each frame to every other
socket in the directory: before each send it looks at the directory's modification time (one
``fstat``, under 1 us) and lists it again when that changed or is too recent to tell
(:data:`RESCAN_S`, the file system's clock is coarse). A member whose socket is gone or
refuses is forgotten.

A full receive queue: a Unix datagram socket queues only ``net.unix.max_dgram_qlen``
datagrams (10 by default), where a real CAN controller's FIFO and the host's socket queue hold
hundreds of frames, so a member descheduled for a few ms (a busy machine) would lose frames a
real bus delivers: a SYNC the emulated drives never answer, a heartbeat their consumer misses.
The sender therefore waits for room, at most ``full_queue_wait_s`` (default
:data:`FULL_QUEUE_WAIT_S`); a frame still not taken then is dropped (``dropped_datagrams``),
and that member is marked congested: until it takes a frame again, frames to it are dropped at
once instead of waiting (``full_queue_waits`` counts the waits), so a member that stopped
reading costs a sender one wait, not one per frame.

Wire format, one or more frames per datagram, each: arbitration id (u32 little-endian),
flags (u8: 1 extended, 2 remote, 4 error, 8 FD, 16 bit-rate switch, 32 error state
indicator), data length (u8), then the data bytes. The receive timestamp is the receiver's
``time.time()``; a frame cut short at the end of a datagram is dropped, and a datagram longer
than the largest burst (16 frames of 64 bytes) is dropped whole (each counted in
``malformed_datagrams``).

Bursts: :meth:`UnixDatagramBus.send_burst` sends frames that go out back to back (a drive's
answers to one SYNC, the master's RPDOs) as one datagram. On a virtual machine each datagram
that wakes a sleeping receiver costs a cross-CPU interrupt, so a burst of three frames costs
one wake-up instead of three; the receiver still gets the frames one by one, in order.
"""

from __future__ import annotations

import itertools
import os
import select
import socket
import struct
import time
from collections import deque
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import can

#: The interface name (the ``can.interface`` entry point).
INTERFACE = "unix_datagram"
_HEADER = struct.Struct("<IBB")
_EXTENDED, _REMOTE, _ERROR, _FD, _BRS, _ESI = 1, 2, 4, 8, 16, 32
#: The largest frame's datagram (CAN FD: 64 data bytes) and the largest burst, bytes.
_MAX_FRAME = _HEADER.size + 64
_MAX_DATAGRAM = 16 * _MAX_FRAME
_COUNTER = itertools.count()
#: A directory modified less than this long ago is listed again before each send (changes
#: within one tick of the file system's coarse clock share a modification time), s.
RESCAN_S = 0.05
#: How long a send waits for room in a member's full receive queue before it drops the frame, s.
FULL_QUEUE_WAIT_S = 0.02


#: One frame without python-can's object (:meth:`UnixDatagramBus.recv_frames`,
#: :meth:`UnixDatagramBus.send_frames`): arbitration id, the wire's flags, data.
RawFrame = tuple[int, int, bytes]
#: The wire's flags of a :data:`RawFrame`: 29-bit identifier, CAN FD, bit-rate switch.
EXTENDED_FLAG, FD_FLAG, BRS_FLAG = _EXTENDED, _FD, _BRS


def _parse(datagram: bytes) -> tuple[list[RawFrame], bool]:
    """The whole frames of a datagram, in order, and whether it held nothing else (a partial
    last frame is dropped)."""
    frames: list[RawFrame] = []
    offset, size = 0, len(datagram)
    while offset + _HEADER.size <= size:
        frame_id, flags, length = _HEADER.unpack_from(datagram, offset)
        start = offset + _HEADER.size
        if length > 64 or start + length > size:
            break
        offset = start + length
        frames.append((frame_id, flags, datagram[start:offset]))
    return frames, offset == size and bool(frames)


def send_timeout(seconds: float) -> bytes:
    """``SO_SNDTIMEO``'s ``struct timeval`` for ``seconds`` (s), rounded to whole us."""
    whole_us = int(round(seconds * 1e6))
    return struct.pack("ll", whole_us // 1_000_000, whole_us % 1_000_000)


def wire_flags(msg: can.Message) -> int:
    """The wire's flags of ``msg`` (a :data:`RawFrame`'s second item)."""
    return ((_EXTENDED if msg.is_extended_id else 0) | (_REMOTE if msg.is_remote_frame
            else 0) | (_ERROR if msg.is_error_frame else 0) | (_FD if msg.is_fd else 0)
            | (_BRS if msg.bitrate_switch else 0)
            | (_ESI if msg.error_state_indicator else 0))


def _encode(msg: can.Message) -> bytes:
    """One frame's bytes on the wire (header, then the data)."""
    data = bytes(msg.data)
    return _HEADER.pack(msg.arbitration_id, wire_flags(msg), len(data)) + data


def send_burst(bus: can.BusABC, messages: Sequence[can.Message]) -> None:
    """Send ``messages`` back to back on ``bus``: as one burst where the bus has
    ``send_burst`` (this module's), else one ``send`` each."""
    burst = getattr(bus, "send_burst", None)
    if burst is not None and len(messages) > 1:
        burst(messages)
        return
    for message in messages:
        bus.send(message)


def send_raw_burst(bus: can.BusABC, frames: Sequence[RawFrame]) -> None:
    """Send ``frames`` back to back on ``bus``: straight from the tuples where the bus has
    ``send_frames`` (this module's), else as python-can messages (:func:`send_burst`)."""
    send_frames = getattr(bus, "send_frames", None)
    if send_frames is not None:
        send_frames(frames)
        return
    send_burst(bus, [_message(frame_id, flags, data) for frame_id, flags, data in frames])


def _message(frame_id: int, flags: int, data: bytes, timestamp: float = 0.0,
             channel: Any = None) -> can.Message:
    """The python-can message of a raw frame (every flag of the wire kept)."""
    return can.Message(
        timestamp=timestamp, arbitration_id=frame_id, is_extended_id=bool(flags & _EXTENDED),
        is_remote_frame=bool(flags & _REMOTE), is_error_frame=bool(flags & _ERROR),
        is_fd=bool(flags & _FD), bitrate_switch=bool(flags & _BRS),
        error_state_indicator=bool(flags & _ESI), dlc=len(data), data=data, channel=channel,
        check=False)


class UnixDatagramBus(can.BusABC):
    """One member of the Unix-datagram CAN bus in directory ``channel`` (see the module
    docstring). ``receive_own_messages`` is not supported (a member never hears itself)."""

    def __init__(self, channel: Any = None, receive_own_messages: bool = False,
                 full_queue_wait_s: float = FULL_QUEUE_WAIT_S, **kwargs: Any) -> None:
        if not channel:
            raise can.CanInitializationError("unix_datagram needs a channel: a directory")
        if not 0.0 <= float(full_queue_wait_s) <= 10.0:
            raise can.CanInitializationError(
                f"unix_datagram: full_queue_wait_s must be 0..10 s (got {full_queue_wait_s})")
        if receive_own_messages:
            raise can.CanInterfaceNotImplementedError(
                "unix_datagram: receiving own messages is not supported")
        self.directory = Path(str(channel))
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            raise can.CanInitializationError(
                f"unix_datagram: cannot use directory {self.directory}: {error}") from error
        self.path = str(self.directory / f"{os.getpid()}-{next(_COUNTER)}.sock")
        self._socket = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        try:
            self._socket.bind(self.path)
        except OSError as error:
            self._socket.close()
            raise can.CanInitializationError(
                f"unix_datagram: cannot bind {self.path}: {error}") from error
        self._socket.setblocking(False)
        # sends that wait for room in a full queue: blocking, bounded by SO_SNDTIMEO
        self._waiting_socket = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self._waiting_socket.setsockopt(socket.SOL_SOCKET, socket.SO_SNDTIMEO,
                                        send_timeout(float(full_queue_wait_s)))
        self.full_queue_wait_s = float(full_queue_wait_s)
        #: Members whose queue stayed full for a whole wait: no waiting until they take one.
        self._congested: set[str] = set()
        #: Sends that found a member's queue full and waited for room.
        self.full_queue_waits = 0
        #: Datagrams (a frame or a burst) a member never got: its queue stayed full.
        self.dropped_datagrams = 0
        self._directory_fd = os.open(self.directory, os.O_RDONLY | os.O_DIRECTORY)
        self._members: set[str] = set()
        #: Frames of the last datagram not yet returned by recv (a burst), in order.
        self._received: deque[can.Message] = deque()
        #: Datagrams that held no whole frame, or ended in a partial one.
        self.malformed_datagrams = 0
        self._directory_mtime_ns = -1
        self._closed = False
        self.channel_info = f"unix_datagram {self.directory}"
        super().__init__(channel=str(channel), **kwargs)

    @property
    def members(self) -> frozenset[str]:
        """Socket paths of the other members this bus sends to."""
        return frozenset(self._members)

    def _scan(self) -> None:
        """Take the sockets in the directory as the members when it may have changed."""
        mtime_ns = os.fstat(self._directory_fd).st_mtime_ns
        if mtime_ns == self._directory_mtime_ns and (
                time.time_ns() - mtime_ns > RESCAN_S * 1e9):
            return
        self._directory_mtime_ns = mtime_ns
        own = os.path.basename(self.path)
        self._members = {os.path.join(self.directory, name)
                         for name in os.listdir(self._directory_fd)
                         if name.endswith(".sock") and name != own}

    def _broadcast(self, datagram: bytes) -> None:
        self._scan()
        for member in tuple(self._members):
            try:
                self._socket.sendto(datagram, member)
            except (FileNotFoundError, ConnectionRefusedError):
                self._members.discard(member)  # it left (its file may stay: a stale one)
            except BlockingIOError:
                self._send_to_full_queue(datagram, member)
            else:
                if self._congested:
                    self._congested.discard(member)

    def _send_to_full_queue(self, datagram: bytes, member: str) -> None:
        """``member``'s queue is full: wait for room (at most ``full_queue_wait_s``) unless it
        is congested, else drop the datagram (module docstring)."""
        if member in self._congested or self.full_queue_wait_s == 0.0:
            self.dropped_datagrams += 1
            return
        self.full_queue_waits += 1
        try:
            self._waiting_socket.sendto(datagram, member)
        except (FileNotFoundError, ConnectionRefusedError):
            self._members.discard(member)
        except (BlockingIOError, TimeoutError):
            self.dropped_datagrams += 1
            self._congested.add(member)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Send ``msg`` to every other member; a member whose queue is full makes it wait
        at most ``full_queue_wait_s`` (once per congestion, module docstring), then misses
        it. ``timeout`` is not used."""
        del timeout
        self._broadcast(_encode(msg))

    def send_burst(self, messages: Sequence[can.Message]) -> None:
        """Send ``messages`` to every other member as one datagram (up to 16 frames; more
        go as further datagrams): they arrive together, in order, each a frame of its own
        to the receiver's :meth:`recv`."""
        self._broadcast_frames([_encode(msg) for msg in messages])

    def send_frames(self, frames: Sequence[RawFrame]) -> None:
        """:meth:`send_burst` of raw frames (id, flags, data): the same datagrams, without
        python-can's message objects (the rig emulator's answers)."""
        try:  # every frame checked before any goes out
            encoded = [_HEADER.pack(frame_id, flags, len(data)) + data
                       for frame_id, flags, data in frames if len(data) <= 64]
        except struct.error as error:
            raise ValueError(f"unix_datagram: a frame's id or flags out of range ({error})"
                             ) from None
        if len(encoded) != len(frames):
            raise ValueError("unix_datagram: a frame carries at most 64 data bytes")
        self._broadcast_frames(encoded)

    def _broadcast_frames(self, encoded: list[bytes]) -> None:
        """Frames already encoded, back to back: up to 16 a datagram, in order."""
        per_datagram = _MAX_DATAGRAM // _MAX_FRAME
        for first in range(0, len(encoded), per_datagram):
            self._broadcast(b"".join(encoded[first:first + per_datagram]))

    def _next_datagram(self, timeout: float | None) -> bytes | None:
        """The next datagram, waiting at most ``timeout`` s (None: for ever); None if none."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            try:
                return self._socket.recv(_MAX_DATAGRAM + 1)  # one more: a longer one shows
            except BlockingIOError:
                now = time.monotonic()
                if deadline is not None and now >= deadline:
                    return None
                wait = None if deadline is None else deadline - now
                if not select.select([self._socket], [], [], wait)[0]:
                    return None

    def _next_frames(self, timeout: float | None) -> list[RawFrame]:
        """The whole frames of the next datagram that has any, waiting at most ``timeout`` s
        in all (None: for ever); [] if none came. A datagram with anything but whole frames
        counts in ``malformed_datagrams``."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            datagram = self._next_datagram(
                None if deadline is None else max(0.0, deadline - time.monotonic()))
            if datagram is None:
                return []
            # longer than the largest burst: not a member's, dropped whole
            frames, whole = _parse(datagram) if len(datagram) <= _MAX_DATAGRAM else ([], False)
            if not whole:
                self.malformed_datagrams += 1
            if frames:
                return frames

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if self._received:
            return self._received.popleft(), False
        frames = self._next_frames(timeout)
        if not frames:
            return None, False
        now = time.time()
        messages = [_message(frame_id, flags, data, now, self.channel_info)
                    for frame_id, flags, data in frames]
        self._received.extend(messages[1:])
        return messages[0], False

    def recv_frames(self, timeout: float | None = None) -> list[RawFrame]:
        """The frames of the next datagram with any (or those a :meth:`recv` left of the last
        one), in order, as raw frames (id, flags, data), without python-can's message objects
        (the rig emulator's serving loop: one call a datagram instead of one ``recv`` and one
        message object a frame); [] when none came within ``timeout`` s
        (0: only what is here; None: wait for ever). The bus's filters are not applied."""
        if self._received:
            messages, self._received = self._received, deque()
            return [(message.arbitration_id, wire_flags(message), bytes(message.data))
                    for message in messages]
        return self._next_frames(timeout)

    def fileno(self) -> int:
        return self._socket.fileno()

    def shutdown(self) -> None:
        """Leave the bus: close the socket and remove its file."""
        if getattr(self, "_closed", True):
            return
        self._closed = True
        super().shutdown()
        self._socket.close()
        self._waiting_socket.close()
        os.close(self._directory_fd)
        try:
            os.unlink(self.path)
        except FileNotFoundError:
            pass
