"""The emulator-only frames between the master and the simulated operator: the operator
display frame (the tool force the master reflects, which the operator feels) and the ready
lamp (the master's forces enabled). Both have 29-bit (extended) identifiers, outside
CANopen's 11-bit COB-IDs, so no CiA 301/402 device sends, answers or filters for them; only
the simulated rigs read them, and the ``can`` backend never sends them.
"""

from __future__ import annotations

import struct

import numpy as np

#: COB-ID of the operator display frame. Payload: 8 bytes, x then y as little-endian IEEE
#: float32, N.
OPERATOR_DISPLAY_ID = 0x1FFFF000
_DISPLAY_PAYLOAD = struct.Struct("<ff")
#: COB-ID of the ready-lamp frame: one byte, 1 when the master's forces are enabled. The
#: simulated operator grasps the handle, and the clock of its script starts, at the first 1
#: (a real operator waits for the lamp too).
OPERATOR_READY_ID = 0x1FFFF001


def encode_operator_display(tool_force_N: np.ndarray) -> bytes:
    """The operator display frame's payload for a tool force (N, x and y)."""
    force = np.asarray(tool_force_N, float).reshape(2)
    return _DISPLAY_PAYLOAD.pack(float(force[0]), float(force[1]))


def decode_operator_display(data: bytes) -> np.ndarray:
    """The tool force (N, x and y) of an operator display payload; ``ValueError`` on a
    payload that is not 8 bytes."""
    if len(data) != _DISPLAY_PAYLOAD.size:
        raise ValueError(f"operator display payload of {len(data)} bytes, expected "
                         f"{_DISPLAY_PAYLOAD.size}")
    return np.array(_DISPLAY_PAYLOAD.unpack(data), float)
