"""The flags of many lanes' messages at once (the lockstep's ticks), as int arrays, in place.

A message's flags are FORCES_ENABLED where its side is ready, else SAFE_STATE, plus one
disjoint bit per condition (common/wire/messages.py ``Flags``). Per tick the conditions are
mostly all off or all on across a sweep's lanes, so each costs one count, and a numpy
multiply only where the lanes differ; the bits all lanes share are added in one call.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from haptic.common.wire.messages import Flags

_FORCES_ENABLED, _SAFE_STATE = int(Flags.FORCES_ENABLED), int(Flags.SAFE_STATE)


def lane_flag_values(out: np.ndarray, ready: np.ndarray,
                     conditions: Sequence[tuple[int, np.ndarray]]) -> np.ndarray:
    """Write into ``out`` ((lanes,) int64) each lane's flags: FORCES_ENABLED where ``ready``
    ((lanes,) bool), else SAFE_STATE, plus ``bit`` where each ``(bit, mask)`` of
    ``conditions`` holds (masks (lanes,), bool or 0/1 floats; bits disjoint from each other and from
    those two). Returns ``out``."""
    lanes = out.shape[0]
    out[...] = ready  # 0 or 1 (a cast copy: a multiply of bools is several times dearer)
    if _FORCES_ENABLED - _SAFE_STATE != 1:
        out *= _FORCES_ENABLED - _SAFE_STATE
    constant = _SAFE_STATE  # the bits every lane has, added at once
    for bit, mask in conditions:
        count = np.count_nonzero(mask)
        if count == lanes:
            constant += bit
        elif count:
            out += bit * (mask if mask.dtype == bool else mask != 0)
    out += constant
    return out
