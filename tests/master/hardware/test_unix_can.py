"""The ``unix_datagram`` python-can interface: a CAN bus between processes on Unix datagrams."""

from __future__ import annotations

import os
import sys
import threading
import time
from pathlib import Path

import can
import pytest

from haptic.master.hardware.unix_can import RESCAN_S, UnixDatagramBus
from tests.helpers.programs import Program


@pytest.fixture
def buses(tmp_path):
    opened: list[can.BusABC] = []

    def open_bus(directory: Path = tmp_path) -> can.BusABC:
        bus = can.Bus(interface="unix_datagram", channel=str(directory))
        opened.append(bus)
        return bus

    yield open_bus
    for bus in opened:
        bus.shutdown()


def _frame(frame_id: int = 0x181, data: bytes = b"\x01\x02\x03", **flags: bool) -> can.Message:
    return can.Message(arbitration_id=frame_id, data=data, **{"is_extended_id": False, **flags})


def test_python_can_opens_it_by_name_and_members_hear_each_other_not_themselves(buses) -> None:
    a, b, c = buses(), buses(), buses()
    assert isinstance(a, UnixDatagramBus)
    a.send(_frame())
    for bus in (b, c):
        received = bus.recv(1.0)
        assert received is not None
        assert (received.arbitration_id, bytes(received.data)) == (0x181, b"\x01\x02\x03")
        assert not received.is_extended_id
    assert a.recv(0.05) is None  # never its own frame
    b.send(_frame(0x1FFFF000, b"12345678", is_extended_id=True))
    got = [bus.recv(1.0) for bus in (a, c)]
    assert all(m is not None and m.is_extended_id and m.arbitration_id == 0x1FFFF000
               and bytes(m.data) == b"12345678" for m in got)


def test_flags_and_order_survive_the_trip(buses) -> None:
    a, b = buses(), buses()
    frames = [_frame(0x080, b""), _frame(0x201, b"\x0f\x00\x10\x27\x00\x00"),
              _frame(0x123, b"", is_remote_frame=True),
              can.Message(arbitration_id=0x7FF, data=bytes(range(12)), is_fd=True,
                          bitrate_switch=True, is_extended_id=False)]
    for frame in frames:
        a.send(frame)
    for sent in frames:
        received = b.recv(1.0)
        assert received is not None and received.equals(sent, timestamp_delta=None,
                                                       check_channel=False)


def test_a_member_that_joins_later_is_heard_and_hears(buses) -> None:
    first = buses()
    first.send(_frame(0x100))  # nobody there yet: lost, as on an empty bus
    late = buses()
    late.send(_frame(0x101))  # the late member found the first in the directory
    received = first.recv(1.0)
    assert received is not None and received.arbitration_id == 0x101
    first.send(_frame(0x102))  # ... and the first knows the late member from its frame
    received = late.recv(1.0)
    assert received is not None and received.arbitration_id == 0x102
    silent = buses()  # joins and never sends: found in the directory
    first.send(_frame(0x103))
    time.sleep(2 * RESCAN_S)  # a directory change older than the file system's clock tick
    also_silent = buses()
    first.send(_frame(0x104))
    assert [silent.recv(1.0).arbitration_id for _ in range(2)] == [0x103, 0x104]
    received = also_silent.recv(1.0)
    assert received is not None and received.arbitration_id == 0x104


def test_a_member_that_leaves_is_forgotten_and_its_socket_removed(buses, tmp_path) -> None:
    a, b = buses(), buses()
    a.send(_frame())
    assert b.recv(1.0) is not None
    path = b.path
    assert Path(path).exists() and path in a.members
    b.shutdown()
    assert not Path(path).exists()
    a.send(_frame())  # to a socket that is gone: no error, the member is dropped
    assert path not in a.members


def test_a_member_that_does_not_read_never_blocks_a_sender(buses) -> None:
    a, b = buses(), buses()
    started = time.monotonic()
    for _ in range(5000):  # far beyond any datagram queue
        a.send(_frame())
    assert time.monotonic() - started < 30.0  # returned: frames beyond b's queue are dropped
    assert a.full_queue_waits == 1  # one wait for room, then b is congested: no more waits
    assert 4900 < a.dropped_datagrams < 5000
    assert b.recv(1.0) is not None
    dropped = a.dropped_datagrams
    a.send(_frame())  # b took a frame (its queue has room): the next send goes through
    assert a.dropped_datagrams == dropped and a.full_queue_waits == 1


def test_buses_in_other_directories_never_hear_each_other(buses, tmp_path) -> None:
    a = buses(tmp_path / "one")
    b = buses(tmp_path / "two")
    a.send(_frame())
    assert b.recv(0.1) is None


def test_it_crosses_processes(buses, tmp_path) -> None:
    here = buses()
    script = ("import can, sys\n"
              f"bus = can.Bus(interface='unix_datagram', channel={str(tmp_path)!r})\n"
              "print('ready', flush=True)\n"
              "message = bus.recv(10.0)\n"
              "bus.send(can.Message(arbitration_id=message.arbitration_id + 1,"
              " data=bytes(message.data), is_extended_id=False))\n"
              "bus.shutdown()\n")
    with Program([sys.executable, "-c", script]) as child:
        child.wait_for(r"^ready$", timeout_s=30.0)
        here.send(_frame(0x200, b"\xaa"))
        answer = here.recv(10.0)
        assert answer is not None and (answer.arbitration_id, bytes(answer.data)) == (
            0x201, b"\xaa")
        assert child.wait(timeout_s=10.0) == 0
    assert [p.name for p in tmp_path.iterdir()] == [os.path.basename(here.path)]


def test_bad_channels_are_initialisation_errors(tmp_path) -> None:
    with pytest.raises(can.CanInitializationError, match="needs a channel"):
        UnixDatagramBus("")
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    with pytest.raises(can.CanInitializationError, match="cannot use directory"):
        UnixDatagramBus(str(blocker / "bus"))
    with pytest.raises(can.CanInterfaceNotImplementedError):
        UnixDatagramBus(str(tmp_path), receive_own_messages=True)


def test_a_burst_arrives_as_its_frames_in_order_to_every_member(buses) -> None:
    from haptic.master.hardware.unix_can import send_burst

    a, b, c = buses(), buses(), buses()
    frames = [_frame(0x181, b"\x01\x02\x03\x04\x05\x06"), _frame(0x182, b""),
              _frame(0x190, bytes(8)),
              can.Message(arbitration_id=0x1FFFF000, data=b"\x00\x01", is_extended_id=True),
              can.Message(arbitration_id=0x7FF, data=bytes(range(64)), is_fd=True,
                          bitrate_switch=True, is_extended_id=False)]
    a.send_burst(frames)
    a.send(_frame(0x200, b"\x09"))  # after the burst, in its place
    for bus in (b, c):
        got = [bus.recv(1.0) for _ in range(len(frames) + 1)]
        assert [(m.arbitration_id, bytes(m.data), m.is_extended_id, m.is_fd) for m in got] == [
            (f.arbitration_id, bytes(f.data), f.is_extended_id, f.is_fd)
            for f in [*frames, _frame(0x200, b"\x09")]]
        assert bus.malformed_datagrams == 0
    # more frames than one datagram holds go as several, still in order
    many = [_frame(0x300 + i, bytes([i] * 8)) for i in range(40)]
    send_burst(a, many)
    assert [b.recv(1.0).arbitration_id for _ in many] == [0x300 + i for i in range(40)]


def test_send_burst_on_a_bus_without_bursts_sends_frame_by_frame() -> None:
    from haptic.master.hardware.unix_can import send_burst

    sender = can.Bus(interface="virtual", channel="burst-test")
    receiver = can.Bus(interface="virtual", channel="burst-test")
    try:
        send_burst(sender, [_frame(0x181), _frame(0x182)])
        assert [receiver.recv(1.0).arbitration_id for _ in range(2)] == [0x181, 0x182]
    finally:
        sender.shutdown()
        receiver.shutdown()


def test_raw_frames_are_the_messages_datagrams_without_the_objects(buses) -> None:
    """``send_frames``/``recv_frames`` (the rig emulator's path): the same wire as
    ``send_burst``/``recv``, a whole datagram per receive, in order, flags kept; what a
    ``recv`` left of a datagram comes first; nothing within the timeout is []."""
    from haptic.master.hardware.unix_can import BRS_FLAG, EXTENDED_FLAG, FD_FLAG

    a, b = buses(), buses()
    raw = [(0x181, 0, b"\x01\x02"), (0x1FFFF000, EXTENDED_FLAG, bytes(8)),
           (0x7FF, FD_FLAG | BRS_FLAG, bytes(range(64))), (0x80, 0, b"")]
    a.send_frames(raw)
    got = [b.recv(1.0) for _ in raw]  # read as messages: the same frames
    assert [(m.arbitration_id, m.is_extended_id, m.is_fd, m.bitrate_switch, bytes(m.data))
            for m in got] == [(i, bool(f & EXTENDED_FLAG), bool(f & FD_FLAG),
                               bool(f & BRS_FLAG), d) for i, f, d in raw]
    frames = [_frame(0x181, b"\x05"), can.Message(arbitration_id=0x1FFFF000, data=b"\x07",
                                                   is_extended_id=True)]
    a.send_burst(frames)
    assert b.recv_frames(1.0) == [(0x181, 0, b"\x05"), (0x1FFFF000, EXTENDED_FLAG, b"\x07")]
    a.send_burst([*frames, _frame(0x182, b"")])
    assert b.recv(1.0).arbitration_id == 0x181  # recv takes the first: the rest come raw
    assert b.recv_frames(0.0) == [(0x1FFFF000, EXTENDED_FLAG, b"\x07"), (0x182, 0, b"")]
    started = time.monotonic()
    assert b.recv_frames(0.05) == [] and time.monotonic() - started >= 0.04
    assert b.recv_frames(0.0) == []
    many = [(0x300 + i, 0, bytes([i])) for i in range(40)]  # several datagrams, in order
    a.send_frames(many)
    received = []
    while len(received) < len(many):
        received += b.recv_frames(1.0)
    assert received == many
    with pytest.raises(ValueError, match="64"):  # checked before anything goes out
        a.send_frames([(0x181, 0, b"\x01"), (0x181, FD_FLAG, bytes(65))])
    with pytest.raises(ValueError, match="range"):
        a.send_frames([(0x181, 0, b"\x01"), (-1, 0, b"")])
    assert b.recv_frames(0.05) == []
    assert b.malformed_datagrams == 0


def test_send_raw_burst_on_another_bus_sends_messages() -> None:
    from haptic.master.hardware.unix_can import BRS_FLAG, EXTENDED_FLAG, FD_FLAG, send_raw_burst

    sender = can.Bus(interface="virtual", channel="raw-burst-test")
    receiver = can.Bus(interface="virtual", channel="raw-burst-test")
    try:
        send_raw_burst(sender, [(0x181, 0, b"\x01"), (0x1FFFF000, EXTENDED_FLAG, b""),
                                (0x7FF, FD_FLAG | BRS_FLAG | 32, bytes(12)), (0x182, 2, b""),
                                (0x183, 4, b"")])
        got = [receiver.recv(1.0) for _ in range(5)]
        assert [(m.arbitration_id, m.is_extended_id, m.is_fd, m.bitrate_switch,
                 m.error_state_indicator, m.is_remote_frame, m.is_error_frame, bytes(m.data))
                for m in got] == [
            (0x181, False, False, False, False, False, False, b"\x01"),
            (0x1FFFF000, True, False, False, False, False, False, b""),
            (0x7FF, False, True, True, True, False, False, bytes(12)),
            (0x182, False, False, False, False, True, False, b""),
            (0x183, False, False, False, False, False, True, b"")]
    finally:
        sender.shutdown()
        receiver.shutdown()


def test_partial_and_junk_datagrams_are_counted_and_never_delivered(buses) -> None:
    import socket as socket_module

    b = buses()
    junk = socket_module.socket(socket_module.AF_UNIX, socket_module.SOCK_DGRAM)
    try:
        whole = b"\x81\x01\x00\x00\x00\x02\xaa\xbb"  # 0x181, 2 bytes
        junk.sendto(b"\x01\x02", b.path)  # shorter than a header
        junk.sendto(whole + b"\x82\x01\x00\x00\x00\x08\x01", b.path)  # then a cut frame
        junk.sendto(b"\x83\x01\x00\x00\x00\x41" + bytes(65), b.path)  # 65 data bytes
        got = b.recv(1.0)
        assert (got.arbitration_id, bytes(got.data)) == (0x181, b"\xaa\xbb")
        assert b.recv(0.1) is None
        assert b.malformed_datagrams == 3
        junk.sendto(b"\x01\x02", b.path)  # the raw receive counts them the same way
        junk.sendto(whole + b"\x82\x01", b.path)
        assert b.recv_frames(1.0) == [(0x181, 0, b"\xaa\xbb")]
        assert b.recv_frames(0.1) == []
        assert b.malformed_datagrams == 5
    finally:
        junk.close()


def test_a_full_queue_makes_the_sender_wait_for_room_instead_of_losing_frames(tmp_path) -> None:
    """A receiver descheduled for a moment (here: it reads 50 ms late) gets every frame,
    in order: the sender waits for room in its queue (10 datagrams by default on Linux)."""
    a = can.Bus(interface="unix_datagram", channel=str(tmp_path), full_queue_wait_s=5.0)
    b = can.Bus(interface="unix_datagram", channel=str(tmp_path))
    received: list[int] = []

    def late_reader() -> None:
        time.sleep(0.05)
        while len(received) < 40:
            message = b.recv(5.0)
            if message is None:
                return
            received.append(message.data[0])

    reader = threading.Thread(target=late_reader)
    try:
        reader.start()
        for index in range(40):
            a.send(_frame(data=bytes([index])))
        reader.join(10.0)
        assert received == list(range(40))
        assert a.dropped_datagrams == 0 and a.full_queue_waits > 0
    finally:
        reader.join(10.0)
        a.shutdown()
        b.shutdown()


def test_full_queue_wait_is_bounded_and_checked(tmp_path) -> None:
    with pytest.raises(can.CanInitializationError, match="full_queue_wait_s"):
        can.Bus(interface="unix_datagram", channel=str(tmp_path), full_queue_wait_s=-1.0)
    a = can.Bus(interface="unix_datagram", channel=str(tmp_path), full_queue_wait_s=0.0)
    b = can.Bus(interface="unix_datagram", channel=str(tmp_path))
    try:
        for _ in range(50):
            a.send(_frame())
        assert a.full_queue_waits == 0 and a.dropped_datagrams > 0  # no wait: dropped at once
    finally:
        a.shutdown()
        b.shutdown()
