"""A python-can interface between processes on one host: CAN frames as Unix datagrams.

``can.Bus(interface="unix_datagram", channel=DIRECTORY)`` joins the bus named by a directory
(created if missing). Every bus on the same directory hears every frame the others send, and
not its own (a real CAN controller's default). Registered with python-can through the
``can.interface`` entry point of this package, so any program that opens a python-can bus by
name can use it (``haptic-master --rig can --can-interface unix_datagram --can-channel DIR``).

Why not ``udp_multicast``: on a VM a multicast datagram also leaves by the network device (a
VM exit per frame) and comes back to its own sender; measured on a 2-core AMD EPYC VM, a SYNC
answered by three frames between two processes took p50 ~70 us / p99 ~135 us with raw
multicast sockets and p50 ~31 us / p99 ~50-75 us with Unix datagram sockets, before any
python-can or rig code (docs/master.md).

Membership: each bus binds ``DIRECTORY/<pid>-<n>.sock`` and sends each frame to every other
socket in the directory: before each send it looks at the directory's modification time (one
``fstat``, under 1 us) and lists it again when that changed or is too recent to tell
(:data:`RESCAN_S`, the file system's clock is coarse). A member whose socket is gone or
refuses is forgotten; a member whose receive queue is full misses that frame (the sender never
blocks, as a CAN controller drops what nobody acknowledges in time).

Wire format, one frame per datagram: arbitration id (u32 little-endian), flags (u8: 1
extended, 2 remote, 4 error, 8 FD, 16 bit-rate switch, 32 error state indicator), data
length (u8), then the data bytes. The receive timestamp is the receiver's ``time.time()``.
"""

from __future__ import annotations

import itertools
import os
import select
import socket
import struct
import time
from pathlib import Path
from typing import Any

import can

#: The interface name (the ``can.interface`` entry point).
INTERFACE = "unix_datagram"
_HEADER = struct.Struct("<IBB")
_EXTENDED, _REMOTE, _ERROR, _FD, _BRS, _ESI = 1, 2, 4, 8, 16, 32
_MAX_DATAGRAM = _HEADER.size + 64
_COUNTER = itertools.count()
#: A directory modified less than this long ago is listed again before each send (changes
#: within one tick of the file system's coarse clock share a modification time), s.
RESCAN_S = 0.05


class UnixDatagramBus(can.BusABC):
    """One member of the Unix-datagram CAN bus in directory ``channel`` (see the module
    docstring). ``receive_own_messages`` is not supported (a member never hears itself)."""

    def __init__(self, channel: Any = None, receive_own_messages: bool = False,
                 **kwargs: Any) -> None:
        if not channel:
            raise can.CanInitializationError("unix_datagram needs a channel: a directory")
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
        self._directory_fd = os.open(self.directory, os.O_RDONLY | os.O_DIRECTORY)
        self._members: set[str] = set()
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
                pass  # its queue is full: it misses this frame

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Send ``msg`` to every other member (never blocks: a member whose queue is full
        misses it)."""
        del timeout
        flags = ((_EXTENDED if msg.is_extended_id else 0) | (_REMOTE if msg.is_remote_frame
                 else 0) | (_ERROR if msg.is_error_frame else 0) | (_FD if msg.is_fd else 0)
                 | (_BRS if msg.bitrate_switch else 0)
                 | (_ESI if msg.error_state_indicator else 0))
        data = bytes(msg.data)
        self._broadcast(_HEADER.pack(msg.arbitration_id, flags, len(data)) + data)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            try:
                datagram = self._socket.recv(_MAX_DATAGRAM)
            except BlockingIOError:
                now = time.monotonic()
                if deadline is not None and now >= deadline:
                    return None, False
                wait = None if deadline is None else deadline - now
                if not select.select([self._socket], [], [], wait)[0]:
                    return None, False
                continue
            if len(datagram) < _HEADER.size:
                continue  # not a frame
            frame_id, flags, length = _HEADER.unpack_from(datagram)
            data = datagram[_HEADER.size:_HEADER.size + length]
            return can.Message(
                timestamp=time.time(), arbitration_id=frame_id,
                is_extended_id=bool(flags & _EXTENDED), is_remote_frame=bool(flags & _REMOTE),
                is_error_frame=bool(flags & _ERROR), is_fd=bool(flags & _FD),
                bitrate_switch=bool(flags & _BRS), error_state_indicator=bool(flags & _ESI),
                dlc=length, data=data, channel=self.channel_info, check=False), False

    def fileno(self) -> int:
        return self._socket.fileno()

    def shutdown(self) -> None:
        """Leave the bus: close the socket and remove its file."""
        if getattr(self, "_closed", True):
            return
        self._closed = True
        super().shutdown()
        self._socket.close()
        os.close(self._directory_fd)
        try:
            os.unlink(self.path)
        except FileNotFoundError:
            pass
