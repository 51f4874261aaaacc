"""The CAN driver's frame sender (master/hardware/frame_sender.py) on its own, over
python-can's virtual bus: a frame goes out at once; a :class:`Burst` holds its frames until
the outermost one ends; an :class:`UntilSync` holds them for the next frame sent (the SYNC),
which sends them first, in order; the driver's own ids are kept for each kind of id."""

from __future__ import annotations

import itertools
from collections.abc import Iterator

import can
import pytest

from haptic.master.hardware.frame_sender import Burst, FrameSender, UntilSync

_CHANNELS = itertools.count()


@pytest.fixture
def buses() -> Iterator[tuple[can.BusABC, can.BusABC]]:
    """A sending and a receiving virtual bus on a channel of their own."""
    channel = f"frame-sender-{next(_CHANNELS)}"
    sending = can.Bus(interface="virtual", channel=channel)
    receiving = can.Bus(interface="virtual", channel=channel)
    yield sending, receiving
    sending.shutdown()
    receiving.shutdown()


def received(bus: can.BusABC) -> list[tuple[int, bytes]]:
    """The frames waiting on ``bus``: (id, data) each, in order."""
    frames = []
    while (message := bus.recv(0)) is not None:
        frames.append((message.arbitration_id, bytes(message.data)))
    return frames


def sender_on(bus: can.BusABC) -> FrameSender:
    sender = FrameSender({0x000, 0x080})
    sender.bus = bus
    return sender


@pytest.mark.parametrize("fd", [False, True])
def test_a_frame_goes_out_at_once_as_given(buses: tuple[can.BusABC, can.BusABC],
                                           fd: bool) -> None:
    sending, receiving = buses
    sender = sender_on(sending)
    sender.send(0x201, b"\x01\x02", fd=fd)
    message = receiving.recv(0)
    assert message is not None
    assert (message.arbitration_id, bytes(message.data)) == (0x201, b"\x01\x02")
    assert not message.is_extended_id
    assert (message.is_fd, message.bitrate_switch) == (fd, fd)
    assert received(receiving) == []


def test_a_frame_is_classic_can_unless_asked(buses: tuple[can.BusABC, can.BusABC]) -> None:
    sending, receiving = buses
    sender_on(sending).send(0x201, b"\x01")
    message = receiving.recv(0)
    assert message is not None
    assert (message.is_fd, message.bitrate_switch) == (False, False)


def test_an_extra_frame_is_sent_as_is_and_its_id_kept_as_the_drivers_own(
        buses: tuple[can.BusABC, can.BusABC]) -> None:
    sending, receiving = buses
    sender = sender_on(sending)
    sender.send_frame(0x1ABCDE, b"\x07", extended=True)
    sender.send_frame(0x321, b"\x08", extended=False)
    first, second = receiving.recv(0), receiving.recv(0)
    assert first is not None and second is not None
    assert (first.arbitration_id, first.is_extended_id) == (0x1ABCDE, True)
    assert (second.arbitration_id, second.is_extended_id) == (0x321, False)
    assert sender.own_extended_ids == {0x1ABCDE}
    assert sender.own_ids == {0x000, 0x080, 0x321}


def test_a_burst_holds_its_frames_until_the_outermost_ends(
        buses: tuple[can.BusABC, can.BusABC]) -> None:
    sending, receiving = buses
    sender = sender_on(sending)
    with Burst(sender):
        sender.send(0x201, b"\x01")
        with Burst(sender):
            sender.send(0x202, b"\x02")
        assert received(receiving) == []  # the inner burst's end sends nothing
        sender.put_all([can.Message(arbitration_id=0x203, data=b"\x03", is_extended_id=False),
                        can.Message(arbitration_id=0x204, data=b"\x04", is_extended_id=False)])
        assert received(receiving) == []
    assert received(receiving) == [(0x201, b"\x01"), (0x202, b"\x02"), (0x203, b"\x03"),
                                   (0x204, b"\x04")]
    assert sender.held is None
    sender.send(0x205, b"\x05")  # after the burst, frames go out at once again
    assert received(receiving) == [(0x205, b"\x05")]


def test_frames_held_for_the_sync_go_out_first_with_the_next_frame(
        buses: tuple[can.BusABC, can.BusABC]) -> None:
    sending, receiving = buses
    sender = sender_on(sending)
    with UntilSync(sender):
        sender.send(0x201, b"\x01")
        with UntilSync(sender):  # nested: the outer one holds
            sender.send(0x202, b"\x02")
        assert sender.holding_for_sync
    assert not sender.holding_for_sync
    assert received(receiving) == []
    sender.send(0x080, b"")  # the SYNC
    assert received(receiving) == [(0x201, b"\x01"), (0x202, b"\x02"), (0x080, b"")]
    assert sender.for_sync == []
    sender.send(0x080, b"")
    assert received(receiving) == [(0x080, b"")]  # sent once only


def test_frames_held_for_the_sync_go_out_before_a_later_burst(
        buses: tuple[can.BusABC, can.BusABC]) -> None:
    sending, receiving = buses
    sender = sender_on(sending)
    with UntilSync(sender):
        sender.send(0x201, b"\x01")
    with Burst(sender):
        sender.send(0x080, b"")
        sender.send(0x202, b"\x02")
    assert received(receiving) == [(0x201, b"\x01"), (0x080, b""), (0x202, b"\x02")]


def test_the_hold_for_the_sync_ends_with_an_exception_too(
        buses: tuple[can.BusABC, can.BusABC]) -> None:
    sending, receiving = buses
    sender = sender_on(sending)
    with pytest.raises(RuntimeError), UntilSync(sender):
        sender.send(0x201, b"\x01")
        raise RuntimeError("the drive answered nonsense")
    assert not sender.holding_for_sync
    assert sender.held is None
    assert sender.for_sync == [sender.for_sync[0]]
    sender.send(0x202, b"\x02")
    assert received(receiving) == [(0x201, b"\x01"), (0x202, b"\x02")]


def test_dropped_held_frames_are_never_sent(buses: tuple[can.BusABC, can.BusABC]) -> None:
    sending, receiving = buses
    sender = sender_on(sending)
    with UntilSync(sender):
        sender.send(0x201, b"\x01")
    sender.drop_held()
    assert sender.for_sync == []
    sender.send(0x080, b"")
    assert received(receiving) == [(0x080, b"")]


def test_a_burst_ending_on_a_closed_bus_sends_nothing_and_holds_nothing() -> None:
    sender = FrameSender({0x080})
    with Burst(sender):
        sender.send(0x201, b"\x01")
    assert sender.held is None
    assert sender.for_sync == []
