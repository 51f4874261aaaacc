"""The peer-input guard's shared parts (common/runtime/peer_guard.py) that the two guards'
own tests do not reach: a side's words are fixed once made."""

from __future__ import annotations

import dataclasses

import pytest

from haptic.common.runtime.peer_guard import PeerSide


def test_a_side_cannot_be_changed_once_made() -> None:
    # Each guard keeps its side as a module constant for the program's life: its events'
    # reasons and its summary's key are read from it at every fault, so a side changed in
    # place would rename what an operator's log and the session report already show.
    side = PeerSide(force_field="tool_force_N", position_field="tool_position_m",
                    noun="tool", fault_kind="tool_input_fault",
                    cleared_kind="tool_input_cleared", jump_bound="beyond", run_noun="states",
                    summary_key="tool_guard", summary_counters=("checked",))
    with pytest.raises(dataclasses.FrozenInstanceError):
        side.noun = "handle"  # type: ignore[misc]
    assert side.noun == "tool"
