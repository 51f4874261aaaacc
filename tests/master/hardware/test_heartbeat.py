"""The CAN driver's heartbeats (master/hardware/heartbeat.py) on their own, over python-can's
virtual bus: the master's heartbeat when due (with the guarded drives' node guarding
requests), a drive's heartbeat and the NMT state it reports, its loss reported once, and the
background heartbeat while the cycle does not run."""

from __future__ import annotations

import itertools
import time
from collections.abc import Iterator

import can
import pytest

from haptic.master.hardware.frame_sender import FrameSender
from haptic.master.hardware.heartbeat import NMT_OPERATIONAL, Heartbeats

PERIOD_S = 0.1
TIMEOUT_S = 0.25
_CHANNELS = itertools.count()


@pytest.fixture
def buses() -> Iterator[tuple[can.BusABC, can.BusABC]]:
    """A sending and a receiving virtual bus on a channel of their own."""
    channel = f"heartbeat-{next(_CHANNELS)}"
    sending = can.Bus(interface="virtual", channel=channel)
    receiving = can.Bus(interface="virtual", channel=channel)
    yield sending, receiving
    sending.shutdown()
    receiving.shutdown()


def heartbeats_on(bus: can.BusABC | None) -> Heartbeats:
    frames = FrameSender(set())
    frames.bus = bus
    return Heartbeats(frames, 1, PERIOD_S, TIMEOUT_S)


def received(bus: can.BusABC) -> list[can.Message]:
    frames = []
    while (message := bus.recv(0)) is not None:
        frames.append(message)
    return frames


def test_new_heartbeats_watch_both_drives_and_guard_none() -> None:
    beats = heartbeats_on(None)
    assert (beats.master_id, beats.payload, NMT_OPERATIONAL) == (0x701, b"\x05", 0x05)
    assert (beats.due_s, beats.seen_s, beats.lost) == (0.0, [0.0, 0.0], [False, False])
    assert (beats.supervised, beats.guarded, beats.guard_requests) == ([True, True],
                                                                      [False, False], [])
    assert (beats.idle_task, beats.idle_guards, beats.idle_errors) == (None, [], [])


def test_expecting_counts_both_drives_heard_and_the_masters_due() -> None:
    beats = heartbeats_on(None)
    beats.lost = [True, True]
    beats.expect(12.5)
    assert (beats.due_s, beats.seen_s, beats.lost) == (12.5, [12.5, 12.5], [False, False])


def test_the_masters_heartbeat_goes_out_when_due_with_the_guarding_requests(
        buses: tuple[can.BusABC, can.BusABC]) -> None:
    sending, receiving = buses
    beats = heartbeats_on(sending)
    beats.watch(0, 3, supervised=True, guarded=False)
    beats.watch(1, 4, supervised=True, guarded=True)
    assert beats.guarded == [False, True] and beats.supervised == [True, True]
    beats.expect(10.0)
    beats.send_if_due(10.0)
    heartbeat, request = received(receiving)
    assert (heartbeat.arbitration_id, bytes(heartbeat.data)) == (0x701, b"\x05")
    assert not heartbeat.is_remote_frame
    assert (request.arbitration_id, request.is_remote_frame, request.dlc) == (0x704, True, 1)
    assert not heartbeat.is_extended_id and not request.is_extended_id
    assert beats.due_s == pytest.approx(10.1)
    beats.send_if_due(10.05)  # not due
    assert received(receiving) == []
    beats.send_if_due(10.1)
    assert len(received(receiving)) == 2
    assert beats.due_s == pytest.approx(10.2)
    beats.send_if_due(11.0)  # late: the next is due a period after the one due, or now
    assert len(received(receiving)) == 2
    assert beats.due_s == pytest.approx(11.0)


def test_a_watched_drive_without_guarding_sends_no_request(
        buses: tuple[can.BusABC, can.BusABC]) -> None:
    sending, receiving = buses
    beats = heartbeats_on(sending)
    beats.watch(0, 3, supervised=False, guarded=False)
    assert beats.supervised == [False, True] and beats.guard_requests == []
    beats.send_if_due(0.0)
    assert [m.arbitration_id for m in received(receiving)] == [0x701]


def test_a_heartbeat_heard_is_its_time_and_ends_a_loss() -> None:
    beats = heartbeats_on(None)
    beats.lost = [True, True]
    faults: list[str] = []
    drive_fault = [False, False]
    before = time.monotonic()
    beats.heard(1, b"\x05", True, faults, drive_fault)
    assert beats.seen_s[0] == 0.0 and beats.seen_s[1] >= before
    assert beats.lost == [True, False]
    assert faults == [] and drive_fault == [False, False]


@pytest.mark.parametrize(("data", "name"), [(b"\x7f", "pre-operational"), (b"\x04", "stopped"),
                                            (b"\x00", "boot-up"), (b"\x85", "0x85"),
                                            (b"", "-0x1")])
def test_a_configured_drive_not_operational_is_a_fault(data: bytes, name: str) -> None:
    beats = heartbeats_on(None)
    faults: list[str] = []
    drive_fault = [False, False]
    beats.heard(0, data, True, faults, drive_fault)
    assert faults == [f"x drive heartbeat reports NMT state {name}, not operational"]
    assert drive_fault == [True, False]
    beats.heard(0, data, False, faults, drive_fault)  # not configured yet: no fault
    assert len(faults) == 1


@pytest.mark.parametrize(("data", "faulted"), [(b"\x85", False), (b"\x05", False),
                                               (b"\xff", True)])
def test_a_guarded_drives_toggle_bit_is_not_its_state(data: bytes, faulted: bool) -> None:
    beats = heartbeats_on(None)
    beats.watch(1, 4, supervised=True, guarded=True)
    faults: list[str] = []
    drive_fault = [False, False]
    beats.heard(1, data, True, faults, drive_fault)
    assert drive_fault == [False, faulted]
    assert faults == (["y drive heartbeat reports NMT state pre-operational, not operational"]
                      if faulted else [])


def test_a_lost_heartbeat_is_a_fault_once() -> None:
    beats = heartbeats_on(None)
    beats.expect(100.0)
    faults: list[str] = []
    drive_fault = [False, False]
    beats.check_lost(1, 4, 100.0 + TIMEOUT_S * 0.9, faults, drive_fault)
    assert faults == [] and beats.lost == [False, False]
    beats.check_lost(1, 4, 100.5, faults, drive_fault)
    beats.check_lost(1, 4, 100.7, faults, drive_fault)
    assert faults == ["no heartbeat from the y drive (node 4) for 0.500 s (timeout 0.25 s)"]
    assert drive_fault == [False, True] and beats.lost == [False, True]


def test_an_unwatched_drive_is_never_lost() -> None:
    beats = heartbeats_on(None)
    beats.watch(0, 3, supervised=False, guarded=False)
    beats.expect(0.0)
    faults: list[str] = []
    drive_fault = [False, False]
    beats.check_lost(0, 3, 5.0, faults, drive_fault)
    assert faults == [] and drive_fault == [False, False] and beats.lost == [False, False]


def wait_for(bus: can.BusABC, frame_ids: set[int], deadline_s: float = 20.0) -> set[int]:
    """The ids of ``frame_ids`` seen on ``bus`` (each in a standard frame) before all were
    seen or the deadline."""
    seen: set[int] = set()
    end = time.monotonic() + deadline_s
    while seen != frame_ids and time.monotonic() < end:
        message = bus.recv(0.05)
        if message is not None and message.arbitration_id in frame_ids:
            assert not message.is_extended_id
            seen.add(message.arbitration_id)
    return seen


def test_the_idle_heartbeat_runs_in_the_background_until_stopped(
        buses: tuple[can.BusABC, can.BusABC]) -> None:
    sending, receiving = buses
    beats = heartbeats_on(sending)
    beats.watch(1, 4, supervised=True, guarded=True)
    beats.start_idle()
    task = beats.idle_task
    assert task is not None and len(beats.idle_guards) == 1
    beats.start_idle()  # running already: the same task
    assert beats.idle_task is task
    assert wait_for(receiving, {0x701, 0x704}) == {0x701, 0x704}
    beats.stop_idle()
    assert beats.idle_task is None and beats.idle_guards == []
    assert not task.thread.is_alive()
    beats.stop_idle()  # stopped already: nothing to do
    assert beats.idle_errors == []


def test_no_idle_heartbeat_on_a_closed_bus() -> None:
    beats = heartbeats_on(None)
    beats.start_idle()
    assert beats.idle_task is None and beats.idle_guards == []


def test_the_idle_heartbeat_stops_itself_when_its_bus_goes(
        buses: tuple[can.BusABC, can.BusABC]) -> None:
    sending, receiving = buses
    beats = heartbeats_on(sending)
    beats.start_idle()
    task = beats.idle_task
    assert wait_for(receiving, {0x701}) == {0x701}
    sending.shutdown()  # its peer ended: the next send fails
    task.thread.join(timeout=20.0)
    assert not task.thread.is_alive()  # stopped by its error, not by stop_idle
    assert beats.idle_errors[0] == "CanOperationError: Cannot operate on a closed bus"
    beats.stop_idle()
