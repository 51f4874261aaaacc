"""Both sides stop at the same place (issue 16): with the shipped limits the handle's command
and the tool meet the same wall of the work area both sides hold, so the operator pushing on
at the end of the clay leaves no gap (before, the handle stopped at its 150 mm clamp while the
tool ran on to the slave's guard at 170 mm)."""

from __future__ import annotations

import numpy as np
import pytest

from haptic.lockstep.cli import main

GAP_TARGET_M = 0.001


@pytest.mark.parametrize("control", ["paper", "tdpa"])
def test_handle_and_tool_stop_together_at_the_wall(tmp_path, control) -> None:
    out = tmp_path / control
    assert main(["run", "--safety", "config", "--control", control, "--duration", "4.5",
                 "--out", str(out)]) == 0
    traces = np.load(out / "traces.npz")
    command_x = traces["handle_command_m"][:, 0]
    tool_x = traces["tool_position_m"][:, 0]
    handle_x = traces["handle_position_m"][:, 0]
    # the handle workspace's bound (150 mm) is the tighter on x-high: both stop on it
    assert command_x.max() == 0.15 and tool_x.max() == 0.15
    at_wall = command_x == 0.15
    assert at_wall[-1] and at_wall.sum() > 0.5 / 0.00054  # pushed on the wall for 0.5 s+
    assert tool_x[-1] == 0.15
    gap = tool_x - handle_x
    assert abs(gap[-1]) <= GAP_TARGET_M
    # held there: after the handle's own lag behind its command (a few ms), no gap at all
    held = int(0.5 / 0.00054)
    assert np.all(at_wall[-held:]) and np.abs(gap[-held:]).max() <= GAP_TARGET_M
