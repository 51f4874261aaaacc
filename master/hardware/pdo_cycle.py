"""The cyclic frames of the CAN driver: SYNC (with its counter, CiA 301 0x1019), each drive's
RPDO (controlword, target position) and TPDO (statusword, position actual value) as its plan
maps them, which received frame is which, and the drives' image the cycle keeps (states,
positions, targets and controlwords, in encoder counts).
"""

from __future__ import annotations

import struct

import can
import numpy as np

from haptic.master.hardware import cia402
from haptic.master.hardware.canopen_setup import RPDO1_OBJECTS, TPDO1_OBJECTS, DrivePlan
from haptic.master.hardware.cia402 import DriveState
from haptic.master.hardware.frame_sender import FrameSender
from haptic.master.hardware.interface import AXES

#: What the cycle does with a received frame, by id: kinds 1-4 (0 for any other frame) and
#: the axis.
TPDO, SENSOR, EMCY, HEARTBEAT = range(1, 5)
OTHER = (0, 0)
_TPDO1 = struct.Struct("<Hi")  # statusword, position actual value (counts)
_RPDO1 = struct.Struct("<Hi")  # controlword, target position (counts)
#: The largest SYNC counter overflow value (CiA 301 0x1019: 2..240).
_COUNTER_MAX = 240


class PdoCycle:
    """The drives' cyclic frames and image, for ``node_ids`` (x then y).

    Parameters
    ----------
    frames:
        The driver's sender.
    node_ids:
        The drives' node ids, x then y.
    sensor_frame_id:
        The force sensor frame's id.
    fd:
        CAN FD: SYNC and RPDOs as FD frames with bit rate switch.
    """

    def __init__(self, frames: FrameSender, node_ids: tuple[int, ...], sensor_frame_id: int,
                 fd: bool) -> None:
        self.frames = frames
        self.node_ids = node_ids
        self.fd = fd
        #: per axis: the CiA 402 state of the last statusword, the last position and the
        #: target sent (counts), the last controlword sent
        self.drive_states = [DriveState.NOT_READY_TO_SWITCH_ON] * len(AXES)
        self.position_counts = np.zeros(len(AXES), np.int64)
        self.target_counts = np.zeros(len(AXES), np.int64)
        self.last_controlword = [cia402.CW_DISABLE_VOLTAGE] * len(AXES)
        #: per axis: the PDOs' names, COB-IDs and payload codecs (TPDO: the statusword and
        #: the position, in the reverse order where the flag says so; RPDO: packs them),
        #: RPDO1 and TPDO1 as the driver maps them until a plan says otherwise
        self.tpdo_names = ["TPDO1", "TPDO1"]
        self.tpdo_codecs = [_TPDO1, _TPDO1]
        self.tpdo_reversed = [False, False]
        self.rpdo_ids = [cia402.RPDO1_BASE + node for node in node_ids]
        self.rpdo_codecs = [_RPDO1, _RPDO1]
        self.rpdo_reversed = [False, False]
        #: frame id -> (kind, axis) of every frame the cycle acts on
        self.dispatch: dict[int, tuple[int, int]] = {}
        for axis, node in enumerate(node_ids):
            self.dispatch[cia402.TPDO1_BASE + node] = (TPDO, axis)
            self.dispatch[cia402.EMCY_BASE + node] = (EMCY, axis)
            self.dispatch[cia402.HEARTBEAT_BASE + node] = (HEARTBEAT, axis)
        self.dispatch[sensor_frame_id] = (SENSOR, 0)
        #: The SYNC counter's overflow value (0x1019) in use, 0 off, and the last SYNC's
        #: counter, 1..overflow.
        self.sync_counter_overflow = 0
        self.sync_counter = 0
        self._sync = can.Message(arbitration_id=cia402.SYNC_COB_ID, data=b"",
                                 is_extended_id=False, is_fd=fd, bitrate_switch=fd)
        self._counted_syncs = [
            can.Message(arbitration_id=cia402.SYNC_COB_ID, data=bytes([count]),
                        is_extended_id=False, is_fd=fd, bitrate_switch=fd)
            for count in range(1, _COUNTER_MAX + 1)]

    def use_plan(self, axis: int, plan: DrivePlan) -> None:
        """``axis``'s PDOs as ``plan`` maps them (ids, layouts; the PDOs it leaves on unused
        count as the driver's own frames)."""
        own_ids = self.frames.own_ids
        old_tpdo = next(i for i, v in self.dispatch.items() if v == (TPDO, axis))
        del self.dispatch[old_tpdo]
        self.dispatch[plan.tpdo.cob_id] = (TPDO, axis)
        own_ids.discard(self.rpdo_ids[axis])
        self.rpdo_ids[axis] = plan.rpdo.cob_id
        own_ids.add(plan.rpdo.cob_id)
        own_ids.update(plan.ignored_cob_ids)
        self.tpdo_names[axis] = plan.tpdo.name
        self.tpdo_codecs[axis], self.tpdo_reversed[axis] = plan.tpdo.codec(
            plan.dictionary, TPDO1_OBJECTS)
        self.rpdo_codecs[axis], self.rpdo_reversed[axis] = plan.rpdo.codec(
            plan.dictionary, RPDO1_OBJECTS)

    def hold_targets(self) -> None:
        """The targets at the drives' actual positions."""
        self.target_counts = self.position_counts.copy()

    def next_sync(self) -> can.Message:
        """This cycle's SYNC: without data, or with the counter 1..overflow (CiA 301)."""
        overflow = self.sync_counter_overflow
        if not overflow:
            return self._sync
        self.sync_counter = self.sync_counter % overflow + 1
        return self._counted_syncs[self.sync_counter - 1]

    def rpdo_frame(self, axis: int, controlword: int, count: int) -> can.Message:
        """``axis``'s drive RPDO: ``controlword`` and the target position ``count``."""
        fd = self.fd
        data = (self.rpdo_codecs[axis].pack(count, controlword) if self.rpdo_reversed[axis]
                else self.rpdo_codecs[axis].pack(controlword, count))
        return can.Message(arbitration_id=self.rpdo_ids[axis], data=data,
                           is_extended_id=False, is_fd=fd, bitrate_switch=fd)

    def send_rpdos(self, controlword: int, counts: list[int]) -> None:
        """Both drives' RPDO (``controlword`` and the target ``counts``, per axis) as one
        burst."""
        self.frames.put_all([self.rpdo_frame(0, controlword, counts[0]),
                             self.rpdo_frame(1, controlword, counts[1])])
        self.last_controlword[0] = self.last_controlword[1] = controlword

    def send_rpdo(self, axis: int, controlword: int) -> None:
        """One drive's RPDO with its target (the enable sequence's per-axis steps)."""
        self.frames.put(self.rpdo_frame(axis, controlword, int(self.target_counts[axis])))
        self.last_controlword[axis] = controlword

    def send_both(self, controlword: int) -> None:
        """Both drives' RPDO with ``controlword`` and the targets they have."""
        self.send_rpdos(controlword, self.target_counts.tolist())
