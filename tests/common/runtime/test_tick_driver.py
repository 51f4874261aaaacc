"""The one tick driver: its stages run in order and are timed (a boundary inside a stage
counts as a stage of its own), a side's schedule shift reaches the runner; and the two
programs, the master alone and the real-link cells all run their ticks through it (a real
short run each, the driver's step counted)."""

from __future__ import annotations

import json
import signal
import uuid
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from haptic.common.runtime.tick_driver import TickDriver
from haptic.common.wire.ports import free_port
from tests.helpers.programs import Program, python_module

WAIT_S = 60.0


class _CountingSide:
    """Three stages; the middle one returns a boundary inside it; each tick asks the runner
    for a shift of ``shift_ns``."""

    stage_names = ("first", "middle_a", "middle_b", "last")

    def __init__(self, clock: list[int], shift_ns: int) -> None:
        self.clock = clock
        self.shift_ns = shift_ns
        self.schedule_shift_ns = 0
        self.calls: list[tuple[str, int]] = []

    def stages(self) -> tuple:
        return (self.first, self.middle, self.last)

    def first(self, tick: int, _now_ns: int) -> None:
        self.calls.append(("first", tick))
        self.clock[0] += 1_000

    def middle(self, tick: int, _now_ns: int) -> int:
        self.calls.append(("middle", tick))
        self.clock[0] += 2_000
        inner = self.clock[0]
        self.clock[0] += 3_000
        self.schedule_shift_ns = self.shift_ns
        return inner

    def last(self, tick: int, _now_ns: int) -> None:
        self.calls.append(("last", tick))
        self.clock[0] += 4_000


def test_the_driver_runs_the_stages_in_order_times_each_and_hands_on_the_shift() -> None:
    clock = [0]
    side = _CountingSide(clock, shift_ns=-250)
    shifts: list[int] = []
    driver = TickDriver([side], clock_ns=lambda: clock[0])
    driver.follow(shifts.append)
    for tick in range(3):
        driver.step(tick, clock[0])
    assert [name for name, _ in side.calls] == ["first", "middle", "last"] * 3
    assert driver.ticks == 3 and shifts == [-250] * 3 and side.schedule_shift_ns == 0
    stages = driver.stage_times[0].summary()
    for name, expected_s in (("first", 1e-6), ("middle_a", 2e-6), ("middle_b", 3e-6),
                             ("last", 4e-6)):
        assert stages[name]["max_s"] == pytest.approx(expected_s, rel=0.05)


def test_two_sides_run_one_after_the_other_each_timed_from_the_end_of_the_one_before() -> None:
    clock = [0]
    first, second = _CountingSide(clock, 0), _CountingSide(clock, 0)
    driver = TickDriver([first, second], clock_ns=lambda: clock[0])
    driver.step(0, 0)
    assert first.calls and second.calls
    assert [times.summary()["first"]["max_s"] for times in driver.stage_times] == \
        pytest.approx([1e-6, 1e-6], rel=0.05)


@pytest.fixture
def counted_ticks(monkeypatch):
    """Every TickDriver.step of this process, counted per side type."""
    counts: Counter[str] = Counter()
    original = TickDriver.step

    def counting(self: TickDriver, tick: int, now_ns: int) -> None:
        for side in self.sides:
            counts[type(side).__name__] += 1
        original(self, tick, now_ns)

    monkeypatch.setattr(TickDriver, "step", counting)
    return counts


def test_the_master_alone_runs_through_the_driver(counted_ticks) -> None:
    from haptic.common.config import load_config
    from haptic.common.model.teleop import model_from_config
    from haptic.master.hardware.interface import create_hardware
    from haptic.master.node import MasterNode
    from haptic.master.settings import master_settings
    from haptic.master.standalone import run_master

    config = load_config()
    model = model_from_config(config)
    node = MasterNode.from_model(model, master_settings(config).safety)
    hardware = create_hardware("model", config)
    try:
        summary = run_master(hardware, node, 40, pace=False, record=True)
    finally:
        hardware.cleanup()
    assert summary.cycles == 40 and summary.trace is not None
    assert summary.trace.handle_command_m.shape == (40, 2)
    assert counted_ticks == {"StandaloneStages": 40}


def test_the_real_link_cells_run_through_the_driver(counted_ticks, paper_model) -> None:
    from haptic.lockstep.real_link import run_cell

    cell = run_cell(paper_model, 19.0, 0.002, duration_s=0.3)
    assert counted_ticks == {"CellMasterStages": cell.steps, "CellSlaveStages": cell.steps}
    assert np.isfinite(cell.measured_round_trip_s)


def _linear_config(tmp_path: Path) -> Path:
    path = tmp_path / "linear.toml"
    path.write_text('[slave]\nscenario = "constant-rate"\nenvironment = "linear"\n'
                    'clay_impl = "numpy"\ndevice = "cpu"\n')
    return path


@pytest.mark.parametrize("side", ["master", "slave"])
def test_both_programs_run_through_the_driver(counted_ticks, tmp_path, side) -> None:
    """The program under test runs in this process, its peer as a child."""
    from haptic.master.cli import main as master_main
    from haptic.slave_sim.cli import main as slave_main

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    common = ["--config", str(_linear_config(tmp_path)), "--key-prefix",
              f"test/{uuid.uuid4().hex[:8]}", "--no-status", "--peer-wait", "30"]
    master_args = [*common, "--listen", endpoint, "--rig", "model", "--operator",
                   "constant:fx=1.0,onset=0.05"]
    slave_args = [*common, "--connect", endpoint]
    summary_path = tmp_path / "summary.json"
    if side == "master":
        peer = Program(python_module("haptic.slave_sim.cli", *slave_args))
        run, args, stages = master_main, master_args, "LinkedMasterStages"
    else:
        peer = Program(python_module("haptic.master.cli", *master_args))
        run, args, stages = slave_main, slave_args, "SlaveStages"
    try:
        status = run([*args, "--duration", "1.0", "--json-summary", str(summary_path)])
    finally:
        peer.stop(signal.SIGTERM, grace_s=WAIT_S)
    assert status == 0
    summary = json.loads(summary_path.read_text())
    assert summary["steps"] > 0
    assert counted_ticks == {stages: summary["steps"]}
    assert summary["stages"]["node"]["p50_s"] > 0.0
