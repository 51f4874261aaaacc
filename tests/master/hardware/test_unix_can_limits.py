"""The ``unix_datagram`` CAN bus at its edges (master/hardware/unix_can.py): what a member
takes from a datagram it did not expect, the bounds of its settings, python-can's filters,
congestion counted exactly and lifted when the member reads again, the directory listed
only when it may have changed, a wait that never outlasts its timeout, and a clean leave."""

from __future__ import annotations

import socket
import struct
import threading
import time
from pathlib import Path

import can
import pytest

from haptic.master.hardware import unix_can
from haptic.master.hardware.unix_can import (
    FULL_QUEUE_WAIT_S,
    RESCAN_S,
    UnixDatagramBus,
    send_burst,
    send_timeout,
)

HEADER = struct.Struct("<IBB")


@pytest.fixture
def buses(tmp_path: Path):
    opened: list[UnixDatagramBus] = []

    def open_bus(directory: Path = tmp_path, **options: object) -> UnixDatagramBus:
        bus = UnixDatagramBus(channel=str(directory), **options)
        opened.append(bus)
        return bus

    yield open_bus
    for bus in opened:
        bus.shutdown()


def raw_send(path: str, datagram: bytes) -> None:
    """One datagram to a member's socket from outside the bus (a stranger on the host)."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as sender:
        sender.sendto(datagram, path)


def test_the_shipped_timing_settings() -> None:
    assert (RESCAN_S, FULL_QUEUE_WAIT_S) == (0.05, 0.02)
    assert send_timeout(1.25) == struct.pack("ll", 1, 250_000)
    assert send_timeout(0.0) == struct.pack("ll", 0, 0)
    assert send_timeout(10.0) == struct.pack("ll", 10, 0)


def test_a_datagram_beyond_the_largest_burst_is_dropped_whole_and_counted(buses) -> None:
    """The largest burst is 16 frames of 64 bytes (1120 bytes): a datagram of exactly that
    size is read whole, a longer one is not a member's and is dropped, never read past."""
    receiver = buses()

    def frames(count: int) -> bytes:  # 14 bytes each
        return b"".join(HEADER.pack(0x100 + n, 0, 8) + bytes(8) for n in range(count))

    raw_send(receiver.path, frames(81))  # 1134 bytes
    raw_send(receiver.path, frames(80))  # 1120 bytes
    got = receiver.recv_frames(1.0)
    assert [frame_id for frame_id, _, _ in got] == [0x100 + n for n in range(80)]
    assert receiver.malformed_datagrams == 1


def test_a_frame_python_can_would_refuse_is_delivered_for_the_driver_to_judge(buses) -> None:
    """12 data bytes without the FD flag: python-can's checks would raise in the receiver's
    recv; the frame is delivered as it came and the driver judges its length."""
    receiver = buses()
    raw_send(receiver.path, HEADER.pack(0x181, 0, 12) + bytes(range(12)))
    message = receiver.recv(1.0)
    assert message is not None and bytes(message.data) == bytes(range(12))
    assert not message.is_fd and message.dlc == 12


def test_full_queue_wait_accepts_0_to_10_s(tmp_path: Path, buses) -> None:
    for wait_s in (0.0, 10.0):
        assert buses(full_queue_wait_s=wait_s).full_queue_wait_s == wait_s
    for wait_s in (-0.001, 10.001):
        with pytest.raises(can.CanInitializationError, match="full_queue_wait_s"):
            UnixDatagramBus(channel=str(tmp_path), full_queue_wait_s=wait_s)


def test_a_nested_channel_directory_is_created(tmp_path: Path, buses) -> None:
    bus = buses(tmp_path / "a" / "b")
    assert Path(bus.path).parent == tmp_path / "a" / "b"


def test_a_socket_path_too_long_to_bind_is_an_initialisation_error(tmp_path: Path) -> None:
    deep = tmp_path / ("d" * 120)
    with pytest.raises(can.CanInitializationError, match="cannot bind"):
        UnixDatagramBus(channel=str(deep))


def test_one_message_is_sent_plainly_and_two_as_a_burst() -> None:
    class Recorder:
        def __init__(self) -> None:
            self.calls: list[tuple[str, int]] = []

        def send(self, message: can.Message) -> None:
            self.calls.append(("send", 1))

        def send_burst(self, messages: list[can.Message]) -> None:
            self.calls.append(("burst", len(messages)))

    bus = Recorder()
    frame = can.Message(arbitration_id=1, data=b"", is_extended_id=False)
    send_burst(bus, [frame])  # type: ignore[arg-type]
    send_burst(bus, [frame, frame])  # type: ignore[arg-type]
    assert bus.calls == [("send", 1), ("burst", 2)]


def test_python_cans_filters_apply_to_every_frame_of_a_burst(buses) -> None:
    sender = buses()
    receiver = buses(can_filters=[{"can_id": 0x181, "can_mask": 0x7FF, "extended": False}])
    frames = [can.Message(arbitration_id=frame_id, data=b"\x01", is_extended_id=False)
              for frame_id in (0x080, 0x181, 0x182, 0x181)]
    sender.send_burst(frames)
    got = [receiver.recv(1.0), receiver.recv(1.0)]
    assert [m.arbitration_id for m in got if m is not None] == [0x181, 0x181]
    assert receiver.recv(0.0) is None


def test_a_full_queue_drops_one_datagram_each_and_a_reading_member_is_waited_for_again(
        buses) -> None:
    sender = buses(full_queue_wait_s=0.005)
    silent = buses()
    frame = can.Message(arbitration_id=0x181, data=b"\x01", is_extended_id=False)
    for _ in range(1000):  # until the silent member's queue is full and one is dropped
        sender.send(frame)
        if sender.dropped_datagrams:
            break
    assert sender.dropped_datagrams == 1 and sender.full_queue_waits == 1
    sender.send(frame)
    sender.send(frame)  # congested: dropped at once, no more waits
    assert (sender.dropped_datagrams, sender.full_queue_waits) == (3, 1)
    while silent.recv_frames(0.0):  # it reads again
        pass
    sender.send(frame)  # taken: the member is no longer congested
    for _ in range(1000):
        sender.send(frame)
        if sender.dropped_datagrams > 3:
            break
    assert (sender.dropped_datagrams, sender.full_queue_waits) == (4, 2)  # waited again


def test_the_directory_is_listed_only_when_it_may_have_changed(buses, monkeypatch) -> None:
    """Listed again when its modification time changed, or while that time is within
    RESCAN_S of now (changes in the same tick of the file system's clock share it)."""
    sender = buses()
    buses()
    listings: list[int] = []
    listdir = unix_can.os.listdir
    monkeypatch.setattr(unix_can.os, "listdir",
                        lambda *a: listings.append(1) or listdir(*a))
    frame = can.Message(arbitration_id=1, data=b"", is_extended_id=False)
    changed_ns = time.time_ns() - 10 ** 9
    unix_can.os.utime(sender.directory, ns=(changed_ns, changed_ns))
    now_ns = [changed_ns + 10 ** 6]  # 1 ms after the change: too recent to tell
    monkeypatch.setattr(unix_can.time, "time_ns", lambda: now_ns[0])
    sender.send(frame)
    sender.send(frame)
    assert len(listings) == 2  # listed before each send
    now_ns[0] = changed_ns + int(RESCAN_S * 1e9) + 1  # settled
    sender.send(frame)
    sender.send(frame)
    assert len(listings) == 2  # unchanged: not listed
    unix_can.os.utime(sender.directory, ns=(changed_ns + 1, changed_ns + 1))
    sender.send(frame)
    assert len(listings) == 3  # changed: listed


def test_a_wait_for_a_frame_is_woken_by_its_arrival(buses) -> None:
    sender, receiver = buses(), buses()
    frame = can.Message(arbitration_id=0x181, data=b"\x07", is_extended_id=False)
    timer = threading.Timer(0.2, sender.send, (frame,))
    timer.start()
    try:  # recv_frames: python-can's recv would retry after a wait that ended empty
        frames = receiver.recv_frames(10.0)
    finally:
        timer.join()
    assert frames == [(0x181, 0, b"\x07")]


def test_after_a_malformed_datagram_the_wait_is_what_is_left_of_the_timeout(
        buses, monkeypatch) -> None:
    receiver = buses()
    waits: list[float | None] = []
    select = unix_can.select.select
    monkeypatch.setattr(unix_can.select, "select",
                        lambda r, w, x, wait=None: waits.append(wait) or select(r, w, x, wait))
    raw_send(receiver.path, b"\x01\x02")  # no whole frame
    assert receiver.recv_frames(0.0) == []
    assert receiver.malformed_datagrams == 1
    assert all(wait is not None and wait <= 0.0 for wait in waits)


def test_leaving_twice_or_after_the_socket_file_went_is_quiet(buses) -> None:
    bus = buses()
    Path(bus.path).unlink()
    bus.shutdown()
    bus.shutdown()
    unbuilt = UnixDatagramBus.__new__(UnixDatagramBus)  # a bus whose start failed early
    unbuilt.shutdown()
