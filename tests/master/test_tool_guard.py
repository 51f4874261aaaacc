"""The master's bounds on what it receives (master/tool_guard.py, issue 17): a tool message
whose position jumps beyond what the tool can move in the elapsed time is a fault, not an
input, on the master's side too."""

from __future__ import annotations

import json
import math
import uuid

import numpy as np
import pytest

from haptic.common.config import ConfigError, load_config, override
from haptic.common.wire.link import Link
from haptic.common.wire.link_config import LinkConfig
from haptic.common.wire.messages import Flags, ToolState
from haptic.common.wire.ports import free_port
from haptic.master.supervisor import MasterSupervisor, Transition
from haptic.master.tool_guard import ToolGuardSettings, ToolInputGuard
from tests.helpers.attacks import steady_slave
from tests.helpers.programs import Program, python_module

TS = 0.00054


def message(seq: int, position=(0.0, 0.0), force=(1.0, 0.0), epoch: int = 7,
            flags: Flags = Flags.FORCES_ENABLED) -> ToolState:
    return ToolState(epoch, seq, int(seq * TS * 1e9), flags, force, position, (0.0, 0.0),
                     0.0, 0.0)


def guard() -> ToolInputGuard:
    return ToolInputGuard(ToolGuardSettings.from_config(load_config()), TS)


def test_defaults_validate_and_bad_keys_refused() -> None:
    config = load_config()
    assert ToolGuardSettings.from_config(config).velocity_trip_m_per_s == 2.0
    bad = override(config, "master.tool_input.position_max_m", [-0.6, 0.5])
    with pytest.raises(ConfigError, match="master.tool_input.position_max_m"):
        ToolGuardSettings.from_config(bad)
    with pytest.raises(ConfigError, match="master.tool_input.velocity_trip_m_per_s"):
        override(config, "master.tool_input.velocity_trip_m_per_s", 0.0)


def test_a_position_jump_beyond_the_tools_speed_is_a_fault() -> None:
    g = guard()
    assert g.admit(message(0), 0.0)
    # 1 ms later, 1 mm farther: 2 m/s x 1.08 ms + 2 mm allows 4.16 mm
    assert g.admit(message(2, position=(0.001, 0.0)), 2 * TS)
    # one period later, 10 mm farther: at most 2 m/s x 0.54 ms + 2 mm = 3.08 mm
    assert not g.admit(message(3, position=(0.011, 0.0)), 3 * TS)
    assert g.faulted and g.position_m == (0.001, 0.0) and g.counters.jumps == 1
    assert [e["kind"] for e in g.events] == ["tool_input_fault"]
    assert "jumped 10 mm" in g.events[0]["reason"]
    # a long silence allows a longer way: 100 ms at 2 m/s is 200 mm
    assert g.admit(message(200, position=(0.15, 0.0)), 200 * TS)
    for seq in range(201, 200 + g.settings.clear_after_messages):
        assert g.admit(message(seq, position=(0.15, 0.0)), seq * TS)
    assert not g.faulted and g.events[-1]["kind"] == "tool_input_fault_cleared"


def test_non_finite_huge_and_outside_messages_are_faults() -> None:
    g = guard()
    assert g.admit(message(0), 0.0)
    assert not g.admit(message(1, position=(math.nan, 0.0)), TS)
    assert not g.admit(message(2, force=(1e9, 0.0)), 2 * TS)
    assert not g.admit(message(3, position=(0.0, -0.7)), 3 * TS)
    assert g.counters.faults == 3 and g.counters.non_finite == 1
    assert g.admit(message(0, position=(0.3, 0.0), epoch=8), 4 * TS)  # a new epoch: no jump


def _supervisor() -> MasterSupervisor:
    return MasterSupervisor((1.0, 1.0), 0.001, 0.05, 3, guard())


def test_supervisor_turns_forces_off_on_a_jump_and_back_after_the_resync() -> None:
    s = _supervisor()
    seq, t = 0, 0.0
    transitions = []
    for _ in range(5):
        transitions.append(s.update(t, message(seq), (0.0, 0.0)))
        seq, t = seq + 1, t + TS
    assert transitions[-1] is Transition.NONE and s.enabled
    # the jumped message: not an input (the tool stays where it was), forces off at once
    assert s.update(t, message(seq, position=(0.05, 0.0), force=(5.0, 0.0)),
                    (0.0, 0.0)) is Transition.HOLD
    assert s.tool is not None and s.tool.tool_position_m == (0.0, 0.0)
    assert s.tool.tool_force_N == (1.0, 0.0)
    assert any(e["kind"] == "tool_input_fault" for e in s.events)
    # plausible messages again: forces come back only after clear_after_messages of them
    # (the tool at the handle)
    count = 0
    while not s.enabled:
        seq, t = seq + 1, t + TS
        s.update(t, message(seq), (0.0, 0.0))
        count += 1
        assert count < 100
    assert count == s.tool_guard.settings.clear_after_messages


def test_supervisor_waits_for_the_tool_at_the_handle_after_a_fault() -> None:
    s = _supervisor()
    for seq in range(5):
        s.update(seq * TS, message(seq), (0.0, 0.0))
    s.update(5 * TS, message(5, force=(1e9, 0.0)), (0.0, 0.0))
    assert not s.enabled
    # plausible messages, but the tool 5 mm away from the handle: forces stay off
    for seq in range(6, 60):
        s.update(seq * TS, message(seq, position=(0.0, 0.0)), (0.005, 0.0))
    assert not s.enabled and not s.tool_guard.faulted
    assert s.update(60 * TS, message(60), (0.0, 0.0)) is Transition.RESUME


@pytest.mark.slow
def test_a_jumping_tool_never_reaches_the_masters_loop(tmp_path) -> None:
    """The real haptic-master (model rig) paired with a steady slave (tests/helpers/attacks.py)
    whose tool, in a burst of 10 messages, jumps 80 mm (a faulty slave, or a forger holding
    the session): the master counts and reports the fault, turns its forces off, never uses
    the jumped position, and runs again once the tool is plausible and at the handle."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    prefix = f"test/{uuid.uuid4().hex[:8]}"
    summary_path, out = tmp_path / "master.json", tmp_path / "out"
    slave_config = LinkConfig(side="slave", key_prefix=prefix, connect=(endpoint,),
                              stale_after_s=10.0)
    with Program(python_module(
            "haptic.master.cli", "--rig", "model", "--key-prefix", prefix, "--listen", endpoint,
            "--no-status", "--peer-wait", "60", "--duration", "4", "--json-summary",
            str(summary_path), "--out", str(out), "--trace-every", "1", "--max-message-age",
            "0.5")) as master:
        with Link(slave_config) as link:
            assert link.wait_for_peer(60.0)
            forged = steady_slave(link, 7.0, inject=lambda i: (0.08, 0.0)
                                  if 1500 <= i < 1510 else None)
            assert forged == 10
            assert master.wait(timeout_s=60) == 0, master.output()
    summary = json.loads(summary_path.read_text())
    guard_figures = summary["tool_input_guard"]
    assert guard_figures["jumps"] >= 1 and guard_figures["faults"] >= 1, guard_figures
    kinds = [e["kind"] for e in summary["events"]]
    assert "tool_input_fault" in kinds and "tool_input_fault_cleared" in kinds, kinds
    trace = np.load(out / "master_trace.npz")
    tool_x = trace["tool_position_x_m"]
    handle_x = trace["handle_position_x_m"]
    seen = np.isfinite(tool_x)
    # the jumped position never reached the loop: the tool it used stays at the handle
    assert np.abs(tool_x[seen] - handle_x[seen]).max() < 0.02
    enabled = trace["forces_enabled"]
    fault_time = next(e["time_s"] for e in summary["events"] if e["kind"] == "tool_input_fault")
    at_fault = np.searchsorted(trace["time_s"], fault_time)
    assert enabled[at_fault + 1] == 0.0  # forces off at once
    assert enabled[-50:].max() == 1.0  # and back after the fault cleared
