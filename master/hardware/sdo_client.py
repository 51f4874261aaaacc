"""The CAN driver's SDO client (CiA 301 expedited transfers): one request, its reply, sent
again when lost, with a deadline; used only while configuring and activating, never in the
cycle.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import can

from haptic.master.hardware import cia402
from haptic.master.hardware.frame_sender import FrameSender
from haptic.master.hardware.interface import HardwareError

#: An SDO request without a reply is sent again after this long, s (until the deadline).
SDO_RESEND_S = 0.25

_ABORT_TEXT = {
    0x05040001: "command specifier not valid", 0x06010000: "unsupported access",
    0x06010001: "write-only object", 0x06010002: "read-only object",
    0x06020000: "object does not exist", 0x06040041: "object cannot be mapped to the PDO",
    0x06040042: "mapping exceeds the PDO length", 0x06040043: "parameter incompatibility",
    0x06070010: "data type length mismatch", 0x06090011: "sub-index does not exist",
    0x06090030: "value out of range", 0x08000000: "general error",
    0x08000020: "cannot be stored or used now", 0x08000022: "not in the present device state",
}


def abort_text(code: int) -> str:
    """What an SDO abort code (CiA 301) means."""
    return _ABORT_TEXT.get(code, "see CiA 301")


class SdoClient:
    """Expedited SDO reads and writes of the drives' objects on ``frames``' bus.

    Parameters
    ----------
    frames:
        The driver's sender (its bus, and its place in the frames' order).
    deadline_s:
        How long an exchange waits for its reply, s, resending every :data:`SDO_RESEND_S`.
    on_other_frame:
        Called with every other frame that arrives meanwhile (the driver acts on EMCYs and
        heartbeats among them).
    """

    def __init__(self, frames: FrameSender, deadline_s: float,
                 on_other_frame: Callable[[can.Message], None]) -> None:
        self.frames = frames
        self.deadline_s = deadline_s
        self.on_other_frame = on_other_frame
        #: SDO requests sent again because no reply came within SDO_RESEND_S
        self.resends = 0

    def exchange(self, node: int, request: bytes, variable: Any,
                 label: str) -> cia402.SdoFrame:
        """Send an SDO request and wait for the reply of the same object (a reply for another
        index/subindex is stale and skipped). An abort raises with the object and its code."""
        bus = self.frames.bus
        assert bus is not None
        self.frames.send(cia402.SDO_RX_BASE + node, request)
        now = time.monotonic()
        deadline = now + self.deadline_s
        # a request or its reply lost on the way is asked again (an SDO read or an expedited
        # write is idempotent), every SDO_RESEND_S until the deadline
        resend_at = now + SDO_RESEND_S
        obj = f"0x{variable.index:04X}:{variable.subindex:02X} ({variable.name})"
        while (remaining := deadline - time.monotonic()) > 0.0:
            message = bus.recv(timeout=min(remaining, max(resend_at - time.monotonic(), 0.0)))
            if message is None:
                now = time.monotonic()
                if now >= deadline:
                    break
                if now >= resend_at:
                    self.resends += 1
                    self.frames.send(cia402.SDO_RX_BASE + node, request)
                    resend_at = now + SDO_RESEND_S
                continue
            if message.arbitration_id != cia402.SDO_TX_BASE + node:
                self.on_other_frame(message)
                continue
            try:
                reply = cia402.decode_sdo(bytes(message.data))
            except ValueError:
                continue
            if (reply.index, reply.subindex) != (variable.index, variable.subindex):
                continue  # a stale reply to an earlier request
            if reply.command == 0x80:
                code = int.from_bytes(reply.data, "little")
                raise HardwareError(f"{label}: SDO abort 0x{code:08X} "
                                    f"({abort_text(code)}) on {obj}")
            return reply
        raise HardwareError(f"{label}: no SDO reply from node {node} for {obj}")

    def write(self, node: int, variable: Any, value: int, label: str) -> None:
        """Write ``value`` to ``variable`` of ``node`` (an expedited download)."""
        reply = self.exchange(node, cia402.sdo_download_request(variable, value),
                              variable, f"{label} write")
        if reply.command != 0x60:
            raise HardwareError(f"{label}: unexpected SDO reply 0x{reply.command:02X} to the "
                                f"write of 0x{variable.index:04X}:{variable.subindex:02X}")

    def read(self, node: int, variable: Any, label: str) -> int:
        """``variable`` of ``node`` (an expedited upload), as an int."""
        reply = self.exchange(node, cia402.sdo_upload_request(variable), variable,
                              f"{label} read")
        if reply.command & 0xE0 != 0x40 or not reply.command & 0x02:
            raise HardwareError(f"{label}: 0x{variable.index:04X}:{variable.subindex:02X} "
                                f"answered with SDO command 0x{reply.command:02X}, not an "
                                "expedited upload")
        size = len(variable) // 8
        return int(variable.decode_raw(reply.data[:size]))
