"""Many lanes' message flags at once (common/wire/lane_flags.py) against the one-lane law of
each program's tick."""

from __future__ import annotations

import numpy as np

from haptic.common.wire.lane_flags import lane_flag_values
from haptic.common.wire.messages import Flags
from haptic.master.tick import _flag_value as master_flags
from haptic.slave_sim.tick import _flag_value as slave_flags

LANES = 7


def _masks(rng: np.random.Generator) -> list[np.ndarray]:
    """All off, all on and mixed lanes, in every combination over four conditions."""
    return [np.zeros(LANES, bool), np.ones(LANES, bool), rng.random(LANES) < 0.5]


def test_lanes_match_the_slave_tick_one_lane_law() -> None:
    rng = np.random.default_rng(3)
    out = np.full(LANES, -1, np.int64)
    for ready in _masks(rng):
        for cutting in _masks(rng):
            for outside in _masks(rng):
                for switched in _masks(rng):
                    # the Warp clay gives ``cutting`` as 0/1 floats
                    cutting_column = cutting.astype(float)
                    lane_flag_values(out, ready, ((int(Flags.IN_CONTACT), cutting_column),
                                                  (int(Flags.WORK_AREA_STOP), outside),
                                                  (int(Flags.TDPA_SWITCHED), switched)))
                    expected = [slave_flags(bool(r), bool(c), bool(o), bool(s)) for r, c, o, s
                                in zip(ready, cutting, outside, switched, strict=True)]
                    assert out.tolist() == expected


def test_lanes_match_the_master_tick_one_lane_law() -> None:
    rng = np.random.default_rng(4)
    out = np.zeros(LANES, np.int64)
    for enabled in _masks(rng):
        for switched in _masks(rng):
            lane_flag_values(out, enabled, ((int(Flags.TDPA_SWITCHED), switched),))
            assert out.tolist() == [master_flags(bool(e), bool(s))
                                    for e, s in zip(enabled, switched, strict=True)]
            assert {int(v) for v in out} <= {int(f) for f in (
                Flags.SAFE_STATE, Flags.FORCES_ENABLED,
                Flags.SAFE_STATE | Flags.TDPA_SWITCHED, Flags.FORCES_ENABLED | Flags.TDPA_SWITCHED)}
