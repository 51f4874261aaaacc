"""The slave's bounds on what it receives (slave_sim/input_guard.py, issue 17)."""

from __future__ import annotations

import json
import math
import uuid

import numpy as np
import pytest

from haptic.common.config import ConfigError, load_config, override
from haptic.common.wire.link import Link
from haptic.common.wire.link_config import LinkConfig
from haptic.common.wire.messages import Flags, HandleState
from haptic.common.wire.ports import free_port
from haptic.slave_sim.input_guard import InputGuard, InputGuardSettings
from tests.helpers.attacks import steady_master
from tests.helpers.programs import Program, python_module

TS = 0.00054


def message(seq: int, force=(1.0, 0.0), position=(0.0, 0.0), epoch: int = 7) -> HandleState:
    return HandleState(epoch, seq, int(seq * TS * 1e9), Flags.FORCES_ENABLED, force, position)


def guard() -> InputGuard:
    return InputGuard(InputGuardSettings.from_config(load_config()), TS)


def test_defaults_validate_and_cross_keys_refused() -> None:
    config = load_config()
    assert InputGuardSettings.from_config(config).force_limit_N == 20.0
    bad = override(config, "slave.safety.force_trip_N", 10.0)
    with pytest.raises(ConfigError, match="slave.safety.force_trip_N"):
        InputGuardSettings.from_config(bad)
    with pytest.raises(ConfigError, match="slave.safety.force_limit_N"):
        override(config, "slave.safety.force_limit_N", -1.0)


def test_a_1e9_N_message_is_a_fault_not_an_input() -> None:
    g = guard()
    assert g.admit(message(0), 0.0)
    assert not g.admit(message(1, force=(1e9, 0.0)), TS)
    assert g.faulted and g.force_N == (1.0, 0.0)
    assert [e["kind"] for e in g.events] == ["input_fault"]
    # it clears after clear_after_messages plausible ones
    for seq in range(2, 2 + g.settings.clear_after_messages):
        assert g.admit(message(seq), seq * TS)
    assert not g.faulted and g.events[-1]["kind"] == "input_fault_cleared"


def test_non_finite_and_implausible_positions_are_faults() -> None:
    g = guard()
    assert g.admit(message(0), 0.0)
    assert not g.admit(message(1, force=(math.nan, 0.0)), TS)
    assert g.counters.non_finite == 1
    assert not g.admit(message(2, position=(0.5, 0.0)), 2 * TS)  # outside the box
    assert not g.admit(message(3, position=(0.01, 0.0)), 3 * TS)  # 10 mm in 1.6 ms: a jump
    assert g.admit(message(4, position=(0.0005, 0.0)), 4 * TS)    # 0.5 mm: plausible
    assert g.counters.faults == 3


def test_force_saturates_and_rate_limits() -> None:
    g = guard()
    assert g.admit(message(0, force=(0.0, 0.0)), 0.0)
    assert g.admit(message(1, force=(50.0, -50.0)), TS)   # below the trip, above the limit
    step = g.settings.force_rate_limit_N_per_s * TS
    assert g.force_N == pytest.approx((step, -step))
    for seq in range(2, 10):
        g.admit(message(seq, force=(50.0, -50.0)), seq * TS)
    assert g.force_N == (20.0, -20.0)
    kinds = [e["kind"] for e in g.events]
    assert kinds.count("input_saturated") == 1 and kinds.count("input_rate_limited") == 1
    assert g.counters.saturated == 9 and not g.faulted


def test_a_new_epoch_is_not_a_position_jump() -> None:
    g = guard()
    assert g.admit(message(0, position=(0.0, 0.0)), 0.0)
    assert g.admit(message(0, position=(0.1, 0.0), epoch=8), TS)


@pytest.mark.slow
def test_forged_1e9_N_never_moves_the_slave_tool_beyond_the_bound(tmp_path) -> None:
    """The real haptic-slave (linear environment) driven by a steady master at 1 N that, in
    a burst, sends 1e9 N (a faulty master or a forger holding the session): the tool stops on
    the fault and never sees more than force_limit_N; it never jumps."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    prefix = f"test/{uuid.uuid4().hex[:8]}"
    config = tmp_path / "linear.toml"
    config.write_text('[slave]\nscenario = "constant-rate"\nenvironment = "linear"\n'
                      'clay_impl = "numpy"\ndevice = "cpu"\n')
    summary_path, out = tmp_path / "slave.json", tmp_path / "out"
    master_config = LinkConfig(side="master", key_prefix=prefix, listen=(endpoint,),
                               stale_after_s=10.0)
    with Link(master_config) as link:
        with Program(python_module(
                "haptic.slave_sim.cli", "--config", str(config), "--key-prefix", prefix,
                "--connect", endpoint, "--no-status", "--peer-wait", "60", "--duration", "3",
                "--json-summary", str(summary_path), "--out", str(out), "--max-message-age",
                "0.5")) as slave:
            assert link.wait_for_peer(60.0)
            forged = steady_master(link, 6.0, inject=lambda i: (1e9, 0.0)
                                   if 1500 <= i < 1510 else None)
            assert forged == 10
            assert slave.wait(timeout_s=60) == 0, slave.output()
    summary = json.loads(summary_path.read_text())
    assert summary["input_guard"]["faults"] >= 1, summary["input_guard"]
    assert any(e["kind"] == "input_fault" for e in summary["events"])
    trace = np.load(out / "slave_trace.npz")
    assert np.abs(trace["handle_force_x_N"]).max() <= 20.0
    # The trace keeps every 10th loop pass, and a pass that catches up runs several
    # simulation steps, so rows are a varying number of periods apart: the bound is on the
    # distance per simulated period (sample_time_s), 1 mm per 0.54 ms, where 1e9 N let
    # through would move the tool 25 cm in one.
    steps_m = np.hypot(np.diff(trace["tool_position_x_m"]), np.diff(trace["tool_position_y_m"]))
    periods = np.maximum(1.0, np.rint(np.diff(trace["sample_time_s"]) / TS))
    assert (steps_m / periods).max() < 0.001, (steps_m / periods).max()  # never a jump
    speeds_m_s = np.hypot(trace["tool_velocity_x_m_s"], trace["tool_velocity_y_m_s"])
    assert speeds_m_s.max() < 1.0, speeds_m_s.max()
