"""The master's quiet-lane kernel (master/quiet_kernel.py) against its definition, tick after
tick, with message arrays read in place, replaced by others, and not contiguous, whether the
kernel reads them in place or copies them."""

from __future__ import annotations

import numpy as np
import pytest

from haptic.common.wire.messages import Flags
from haptic.master.quiet_kernel import QuietLanes

LANES = 40
MAX_AGE_S = 0.02
FLAG_CHOICES = np.array([int(Flags.FORCES_ENABLED), int(Flags.SAFE_STATE),
                         int(Flags.FORCES_ENABLED | Flags.WORK_AREA_STOP),
                         int(Flags.FORCES_ENABLED | Flags.IN_CONTACT),
                         int(Flags.FORCES_ENABLED | Flags.STOPPING)])


def _views(rng: np.random.Generator) -> dict[str, np.ndarray]:
    return {"steady": rng.random(LANES) < 0.8, "max_age_s": np.full(LANES, MAX_AGE_S),
            "newest_flags": rng.choice(FLAG_CHOICES, LANES),
            "newest_rows": rng.standard_normal((LANES, 8)),
            "tool_force_N": rng.standard_normal((LANES, 2)), "stale": np.zeros(LANES, bool)}


def test_the_kernel_stores_fresh_messages_and_finds_the_loud_lanes() -> None:
    rng = np.random.default_rng(2)
    views = _views(rng)
    expected = {name: array.copy() for name, array in views.items()}
    quiet = QuietLanes(LANES, views)
    fresh, flags = np.zeros(LANES, bool), np.zeros(LANES, np.int64)
    rows, silence = np.zeros((LANES, 8)), np.zeros(LANES)
    force = rows[:, 0:2]  # a view, not contiguous: read in place too
    loud_ticks = 0
    in_place = []
    for tick in range(30):
        if tick == 10:  # other arrays: copied once more, then read in place
            fresh, flags = np.zeros(LANES, bool), np.zeros(LANES, np.int64)
            rows, silence = np.zeros((LANES, 8)), np.zeros(LANES)
            force = rows[:, 0:2]
        fresh[...] = rng.random(LANES) < 0.7
        flags[...] = rng.choice(FLAG_CHOICES, LANES)
        rows[...] = rng.standard_normal((LANES, 8))
        silence[...] = rng.choice([0.0, 0.01, MAX_AGE_S, 0.03], LANES)
        if tick >= 20:  # new arrays each tick, not contiguous, another dtype: copied
            fed = quiet.run(fresh.astype(np.int8) != 0, flags.astype(np.int32),
                            np.asfortranarray(rows), force, silence[::1])
        else:
            fed = quiet.run(fresh, flags, rows, force, silence)
        in_place.append(quiet.inputs.in_place)
        # the definition, in numpy
        newest_flags = np.where(fresh, flags, expected["newest_flags"])
        expected["newest_flags"] = newest_flags
        mask = int(Flags.FORCES_ENABLED | Flags.WORK_AREA_STOP | Flags.STOPPING)
        is_quiet = (expected["steady"] & ~(silence > MAX_AGE_S)
                    & ((newest_flags & mask) == int(Flags.FORCES_ENABLED)))
        expected["newest_rows"][fresh] = rows[fresh]
        expected["tool_force_N"][fresh] = rows[fresh, 0:2]
        expected["stale"] |= fresh & is_quiet
        for name in ("newest_flags", "newest_rows", "tool_force_N", "stale"):
            np.testing.assert_array_equal(views[name], expected[name], err_msg=name)
        if is_quiet.all():
            assert fed is None
        else:
            loud_ticks += 1
            np.testing.assert_array_equal(fed, ~is_quiet)
    assert loud_ticks > 20
    assert in_place == [False, False] + [True] * 8 + [False, False] + [True] * 8 + [False] * 10


def test_rows_of_another_shape_are_refused() -> None:
    quiet = QuietLanes(LANES, _views(np.random.default_rng(0)))
    with pytest.raises(ValueError, match="shape"):
        quiet.run(np.zeros(LANES, bool), np.zeros(LANES, np.int64), np.zeros((LANES, 7)),
                  np.zeros((LANES, 2)), np.zeros(LANES))
