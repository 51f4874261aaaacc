"""What the master's and the slave's ticks share (common/runtime/lane_tick.py)."""

from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
import pytest

from haptic.common.runtime.lane_tick import (
    UNCONFIGURED_LANE,
    LaneNotConfiguredError,
    TickFlags,
    one_lane_passivity,
)
from haptic.common.wire.messages import Flags


@dataclass
class _Output(TickFlags):
    flag_values: np.ndarray


def test_flag_values_read_as_flags_per_lane() -> None:
    values = np.array([int(Flags.FORCES_ENABLED | Flags.IN_CONTACT), int(Flags.SAFE_STATE)])
    assert _Output(values).flags == [Flags.FORCES_ENABLED | Flags.IN_CONTACT, Flags.SAFE_STATE]


def test_a_lane_stepped_before_configure_lane_is_refused_by_name() -> None:
    with pytest.raises(LaneNotConfiguredError, match="configure_lane"):
        _ = UNCONFIGURED_LANE.outputs
    with pytest.raises(RuntimeError):  # what callers of step_lane caught before
        _ = UNCONFIGURED_LANE.passivity
    assert not hasattr(UNCONFIGURED_LANE, "outputs")  # an AttributeError too
    assert not hasattr(UNCONFIGURED_LANE, "__deepcopy__")


@pytest.mark.parametrize(("passivity", "standby", "mode"), [
    (None, False, "paper"), (object(), True, "paper"), (object(), False, "tdpa")])
def test_one_lane_passivity_runs_the_layer_only_where_the_node_does(passivity, standby,
                                                                     mode) -> None:
    node = SimpleNamespace(passivity=passivity, passivity_standby=standby)
    assert one_lane_passivity(1, node).mode == mode
    with pytest.raises(ValueError, match="one lane"):
        one_lane_passivity(2, node)
