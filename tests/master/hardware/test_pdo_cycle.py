"""The CAN driver's cyclic frames (master/hardware/pdo_cycle.py) on their own, over
python-can's virtual bus: the SYNC without data or with its counter 1..overflow (CiA 301
0x1019), each drive's RPDO1 (controlword, target counts) as sent, which received id is which
frame, and the image the cycle keeps (controlwords, targets held at the positions)."""

from __future__ import annotations

import itertools
import struct
from collections.abc import Iterator

import can
import pytest

from haptic.master.hardware import cia402
from haptic.master.hardware.canopen_setup import CyclicPdo, DrivePlan
from haptic.master.hardware.cia402 import DriveState
from haptic.master.hardware.frame_sender import FrameSender
from haptic.master.hardware.pdo_cycle import EMCY, HEARTBEAT, OTHER, SENSOR, TPDO, PdoCycle

NODES = (3, 4)
SENSOR_ID = 0x190
_CHANNELS = itertools.count()


@pytest.fixture
def buses() -> Iterator[tuple[can.BusABC, can.BusABC]]:
    """A sending and a receiving virtual bus on a channel of their own."""
    channel = f"pdo-cycle-{next(_CHANNELS)}"
    sending = can.Bus(interface="virtual", channel=channel)
    receiving = can.Bus(interface="virtual", channel=channel)
    yield sending, receiving
    sending.shutdown()
    receiving.shutdown()


def cycle_on(bus: can.BusABC | None, fd: bool = False) -> PdoCycle:
    frames = FrameSender({cia402.SYNC_COB_ID})
    frames.bus = bus
    return PdoCycle(frames, NODES, SENSOR_ID, fd)


def received(bus: can.BusABC) -> list[can.Message]:
    frames = []
    while (message := bus.recv(0)) is not None:
        frames.append(message)
    return frames


def test_a_new_cycle_knows_nothing_of_its_drives_yet() -> None:
    pdos = cycle_on(None)
    assert pdos.drive_states == [DriveState.NOT_READY_TO_SWITCH_ON] * 2
    assert pdos.position_counts.tolist() == [0, 0]
    assert pdos.target_counts.tolist() == [0, 0]
    assert pdos.last_controlword == [cia402.CW_DISABLE_VOLTAGE] * 2
    assert (pdos.sync_counter_overflow, pdos.sync_counter) == (0, 0)
    assert pdos.tpdo_names == ["TPDO1", "TPDO1"]
    assert pdos.tpdo_reversed == [False, False] and pdos.rpdo_reversed == [False, False]
    assert pdos.rpdo_ids == [0x203, 0x204]


def test_each_known_id_is_its_frame_and_axis() -> None:
    pdos = cycle_on(None)
    assert pdos.dispatch[0x183] == (TPDO, 0) and pdos.dispatch[0x184] == (TPDO, 1)
    assert pdos.dispatch[0x083] == (EMCY, 0) and pdos.dispatch[0x084] == (EMCY, 1)
    assert pdos.dispatch[0x703] == (HEARTBEAT, 0) and pdos.dispatch[0x704] == (HEARTBEAT, 1)
    assert pdos.dispatch[SENSOR_ID][0] == SENSOR
    assert len(pdos.dispatch) == 7
    assert sorted({TPDO, SENSOR, EMCY, HEARTBEAT}) == [1, 2, 3, 4]
    assert OTHER[0] == 0  # any other id: a kind the cycle does not act on


@pytest.mark.parametrize("fd", [False, True])
def test_the_sync_without_a_counter_has_no_data(fd: bool) -> None:
    pdos = cycle_on(None, fd=fd)
    for _ in range(3):
        sync = pdos.next_sync()
        assert (sync.arbitration_id, bytes(sync.data), sync.is_extended_id) == (0x080, b"",
                                                                                False)
        assert (sync.is_fd, sync.bitrate_switch) == (fd, fd)
    assert pdos.sync_counter == 0


@pytest.mark.parametrize("overflow", [2, 5, 240])
def test_the_sync_counter_runs_1_to_its_overflow_and_again(overflow: int) -> None:
    pdos = cycle_on(None, fd=True)
    pdos.sync_counter_overflow = overflow
    counts = []
    for _ in range(2 * overflow + 1):
        sync = pdos.next_sync()
        assert (sync.arbitration_id, len(sync.data), sync.is_extended_id) == (0x080, 1, False)
        assert sync.is_fd and sync.bitrate_switch
        counts.append(sync.data[0])
    assert counts == [*range(1, overflow + 1), *range(1, overflow + 1), 1]
    assert pdos.sync_counter == 1


@pytest.mark.parametrize("fd", [False, True])
def test_both_rpdos_go_out_as_one_burst_and_are_remembered(
        buses: tuple[can.BusABC, can.BusABC], fd: bool) -> None:
    sending, receiving = buses
    pdos = cycle_on(sending, fd=fd)
    pdos.send_rpdos(cia402.CW_ENABLE_OPERATION, [1000, -2000])
    x, y = received(receiving)
    assert (x.arbitration_id, bytes(x.data)) == (0x203, struct.pack("<Hi", 0x000F, 1000))
    assert (y.arbitration_id, bytes(y.data)) == (0x204, struct.pack("<Hi", 0x000F, -2000))
    assert all((m.is_fd, m.bitrate_switch, m.is_extended_id) == (fd, fd, False)
               for m in (x, y))
    assert pdos.last_controlword == [0x000F, 0x000F]


def test_one_rpdo_carries_its_axis_target(buses: tuple[can.BusABC, can.BusABC]) -> None:
    sending, receiving = buses
    pdos = cycle_on(sending)
    pdos.target_counts[:] = (11, -22)
    pdos.send_rpdo(1, cia402.CW_SWITCH_ON)
    (frame,) = received(receiving)
    assert (frame.arbitration_id, bytes(frame.data)) == (0x204, struct.pack("<Hi", 7, -22))
    assert pdos.last_controlword == [cia402.CW_DISABLE_VOLTAGE, cia402.CW_SWITCH_ON]
    pdos.send_both(cia402.CW_QUICK_STOP)
    assert [bytes(m.data) for m in received(receiving)] == [struct.pack("<Hi", 2, 11),
                                                           struct.pack("<Hi", 2, -22)]
    assert pdos.last_controlword == [cia402.CW_QUICK_STOP] * 2


def test_a_reversed_rpdo_packs_the_target_first() -> None:
    pdos = cycle_on(None)
    pdos.rpdo_codecs[0] = struct.Struct("<iH")
    pdos.rpdo_reversed[0] = True
    frame = pdos.rpdo_frame(0, cia402.CW_SHUTDOWN, 123456)
    assert bytes(frame.data) == struct.pack("<iH", 123456, 6)
    assert bytes(pdos.rpdo_frame(1, 6, 5).data) == struct.pack("<Hi", 6, 5)


def test_holding_the_targets_takes_the_positions_as_they_are() -> None:
    pdos = cycle_on(None)
    pdos.position_counts[:] = (500, -700)
    pdos.hold_targets()
    assert pdos.target_counts.tolist() == [500, -700]
    pdos.position_counts[0] = 9
    assert pdos.target_counts.tolist() == [500, -700]  # a copy, not the positions


def test_a_plan_maps_an_axis_pdos_and_leaves_the_other_frames() -> None:
    pdos = cycle_on(None)
    pdos.frames.own_ids.update(pdos.rpdo_ids)
    plan = DrivePlan(
        cia402.build_object_dictionary(), (),
        rpdo=CyclicPdo("RPDO2", 0x1401, 0x303, ((0x607A, 0, 32), (0x6040, 0, 16))),
        tpdo=CyclicPdo("TPDO2", 0x1801, 0x283, ((0x6041, 0, 16), (0x6064, 0, 32))),
        ignored_cob_ids=frozenset({0x383}))
    pdos.use_plan(0, plan)
    assert pdos.dispatch[0x283] == (TPDO, 0) and 0x183 not in pdos.dispatch
    assert pdos.dispatch[0x083] == (EMCY, 0) and pdos.dispatch[0x184] == (TPDO, 1)
    assert len(pdos.dispatch) == 7
    assert pdos.rpdo_ids == [0x303, 0x204]
    assert pdos.frames.own_ids == {cia402.SYNC_COB_ID, 0x204, 0x303, 0x383}
    assert pdos.tpdo_names == ["TPDO2", "TPDO1"]
    assert (pdos.rpdo_reversed, pdos.tpdo_reversed) == ([True, False], [False, False])
    assert bytes(pdos.rpdo_frame(0, 6, -5).data) == struct.pack("<iH", -5, 6)
