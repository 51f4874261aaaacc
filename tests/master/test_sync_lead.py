"""The early SYNC (``[master.can] sync_lead_s``): the runner calls ``lead`` before each tick,
``CanHandleDriver.sync`` sends the cycle's SYNC there and ``read`` collects that cycle. The
data flow is the plain read's: the same samples, one SYNC per cycle, the command acting one
SYNC after the sample (no timing is asserted)."""

from __future__ import annotations

import time
import uuid

import numpy as np
import pytest

from haptic.common.config import ConfigError, load_config, override
from haptic.common.runtime.runner import RealTimeRunner
from haptic.master.hardware.interface import create_hardware, starts_cycles_early
from haptic.master.simulated_rig.can_devices import SimulatedRigHardware
from haptic.master.simulated_rig.model_backend import ModelRigHardware
from haptic.master.simulated_rig.rig_emulator import EmulatedRigHardware
from tests.helpers.fake_clock import FakeClock

PERIOD_NS = 540_000


def _config(**overrides):
    config = load_config()
    config = override(config, "master.sim.operator", "constant:fx=0.8,fy=-0.3,onset=0.005")
    config = override(config, "master.sim.force_noise_std_N", 0.05)
    config = override(config, "master.sim.seed", 11)
    config = override(config, "master.sim.channel", f"test-{uuid.uuid4().hex}")
    config = override(config, "master.can.heartbeat_timeout_s", 5.0)  # unpaced steps
    for key, value in overrides.items():
        config = override(config, key, value)
    return config


def _cycles(early: bool, pause_s: float = 0.0, cycles: int = 200
            ) -> list[tuple[int, tuple, tuple]]:
    """``cycles`` control cycles on a fresh simulated rig (a slow sinusoidal command), each
    SYNC sent by ``sync()`` ``pause_s`` ahead of the read when ``early``; every reading."""
    readings = []
    with create_hardware("sim-inproc", _config()) as hardware:
        hardware.configure()
        hardware.activate()
        start = hardware.read().position_m
        for k in range(cycles):
            if early:
                hardware.sync()
                time.sleep(pause_s)
            reading = hardware.read()
            assert reading.ok, reading.faults
            readings.append((reading.cycle, tuple(reading.position_m.tolist()),
                             tuple(reading.force_N.tolist())))
            hardware.write(start + 0.002 * np.array([np.sin(k / 20.0), np.cos(k / 30.0) - 1]))
    return readings


@pytest.mark.parametrize("pause_s", [0.0, 0.0005])
def test_a_sync_ahead_of_the_read_gives_the_same_cycles_as_the_plain_read(pause_s) -> None:
    """The answers waiting for the read or not: the same samples."""
    plain, early = _cycles(False), _cycles(True, pause_s)
    assert early == plain
    positions = np.array([position for _, position, _ in plain])
    assert np.ptp(positions[:, 0]) > 1e-3  # the handle followed the command


def test_one_sync_per_cycle_however_often_sync_is_called() -> None:
    with create_hardware("sim-inproc", _config()) as hardware:
        hardware.configure()
        hardware.activate()
        rig = hardware.rig
        before = hardware.read().cycle
        syncs_before = rig.sync_count
        hardware.sync()
        hardware.sync()  # pending: nothing more goes out
        reading = hardware.read()
        assert reading.ok and reading.cycle == before + 1
        deadline = time.monotonic() + 5.0
        while rig.sync_count < syncs_before + 1 and time.monotonic() < deadline:
            time.sleep(0.001)
        assert rig.sync_count == syncs_before + 1
        assert hardware.driver.late_frames == 0


def test_a_read_long_after_its_sync_collects_the_frames_already_there() -> None:
    with create_hardware("sim-inproc", _config()) as hardware:
        hardware.configure()
        hardware.activate()  # with the configured timeout: a busy machine answers late
        hardware.read()
        # the read below waits at most 1 ms: only what is already there can count
        hardware.driver.pdo_timeout_s = 0.001
        hardware.sync()
        time.sleep(0.05)  # far past the PDO timeout: the answers wait in the receive queue
        reading = hardware.read()
        assert reading.ok, reading.faults
        assert np.all(np.isfinite(reading.position_m)) and np.all(np.isfinite(reading.force_N))
        assert hardware.driver.late_frames == 0


def test_which_backends_start_their_cycles_early() -> None:
    assert starts_cycles_early(SimulatedRigHardware.__new__(SimulatedRigHardware))
    assert starts_cycles_early(EmulatedRigHardware.__new__(EmulatedRigHardware))
    assert not starts_cycles_early(ModelRigHardware.__new__(ModelRigHardware))


def _run(lead_s: float, step_cost_ns: int = 0, steps: int = 50):
    clock = FakeClock()  # 1 us per read, a sleep moves it by what was asked
    log: list[tuple[str, int, int]] = []

    def step(tick: int, now_ns: int) -> None:
        log.append(("step", tick, now_ns))
        clock.now += step_cost_ns

    runner = RealTimeRunner(PERIOD_NS * 1e-9, step, max_steps=steps, clock_ns=clock.clock,
                            sleep=clock.sleep, handle_signals=False, show_status=False,
                            lead=lambda tick: log.append(("lead", tick, clock.now)),
                            lead_s=lead_s)
    stats = runner.run()
    return log, stats


def test_the_runner_calls_lead_before_each_tick_at_its_lead_time() -> None:
    lead_ns = 300_000
    log, stats = _run(lead_ns * 1e-9)
    assert stats.steps == 50
    kinds = [(kind, tick) for kind, tick, _ in log]
    assert kinds[:100] == [(kind, k) for k in range(50) for kind in ("lead", "step")]
    starts = {tick: now for kind, tick, now in log if kind == "step"}
    for kind, tick, now in log:
        if kind == "lead" and tick > 0:
            assert starts[tick] - lead_ns - 5_000 <= now <= starts[tick] - lead_ns + 5_000


def test_a_step_longer_than_the_wait_gets_its_lead_right_after_it() -> None:
    log, stats = _run(0.0003, step_cost_ns=400_000)
    assert stats.overruns == 0
    ends = {tick: now + 400_000 for kind, tick, now in log if kind == "step"}
    for kind, tick, now in log:
        if kind == "lead" and tick > 0:
            assert ends[tick - 1] <= now <= ends[tick - 1] + 5_000  # not after the deadline


def test_a_lead_longer_than_the_period_is_one_period() -> None:
    log, _ = _run(0.01, steps=5)
    starts = {tick: now for kind, tick, now in log if kind == "step"}
    for kind, tick, now in log:
        if kind == "lead" and tick > 1:
            assert now <= starts[tick - 1] + 5_000  # right after the previous tick's step


def test_sync_lead_s_is_validated() -> None:
    with pytest.raises(ConfigError, match="master.can.sync_lead_s"):
        override(load_config(), "master.can.sync_lead_s", -0.001)
    with pytest.raises(ConfigError, match="master.can.sync_lead_s"):
        override(load_config(), "master.can.sync_lead_s", 0.5)
