"""``haptic-slave --plant ros2``: the slave's compensators drive an emulated robot over ROS 2
(tests/slave_sim/robot_emulator.py, an independent ROS 2-over-Zenoh implementation) whose
tool cuts the scenario's clay; the cut reproduces the virtual tool's within 10 %."""

from __future__ import annotations

import contextlib
import json
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from haptic.common.config import load_config
from haptic.common.config.scenario import load_scenario
from haptic.common.wire.ports import free_port
from tests.common.ros2.zenoh_graph import zenoh_router
from tests.helpers.programs import Program, python_module
from tests.slave_sim.robot_emulator import EmulatedRobot

DURATION_S = 3.0
#: The cut's robot watchdog, s. The emulated robot is a Python process on the tests' machine:
#: on a loaded machine of few CPUs its callbacks were starved up to about a second, a silence the
#: default 0.05 s holds the robot for, which ends the cut that this test compares. The
#: watchdog's own contract is the other tests' (a silent robot, the default limit).
CUT_WATCHDOG_S = 2.0


def _session(out: Path, *extra: str) -> dict:
    """Run haptic-session; the slave's summary."""
    with Program(python_module(
            "haptic.common.launch.cli", "--duration", repr(DURATION_S), "--out", str(out),
            "--cpu-layout", "free", *extra)) as session:
        assert session.wait(timeout_s=500.0) == 0, session.output()[-4000:]
    return json.loads((out / "slave.json").read_text())


@pytest.mark.slow
def test_the_robot_plant_cuts_as_the_virtual_tool(tmp_path: Path) -> None:
    from haptic.slave_sim.clay.sim import make_clay

    virtual = _session(tmp_path / "virtual")
    scenario = load_scenario("constant-rate")
    period_s = load_config()["model"]["sample_period_s"]
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with zenoh_router(endpoint):
        robot = EmulatedRobot(endpoint, make_clay(scenario, period_s, "warp", "cpu"),
                              scenario.tool.start_position_m, period_s)
        try:
            plant = _session(tmp_path / "robot", "--ros2-endpoint", endpoint, "--slave-args",
                             f"--plant ros2 --plant-watchdog {CUT_WATCHDOG_S!r}")
        finally:
            robot.close()
    assert robot.commands > 1000 and robot.bad_attachments == 0
    assert plant["robot_watchdog_trips"] == 0
    print({key: (virtual.get(key), plant.get(key)) for key in (
        "cut_mean_force_N", "cut_mean_speed_m_s", "cutting_time_s", "removed_volume_m3")})
    for key in ("cut_mean_force_N", "cut_mean_speed_m_s"):
        assert plant[key] == pytest.approx(virtual[key], rel=0.10), key


@contextlib.contextmanager
def _robot_and_plant(watchdog_s: float, say: Callable[[str], None]) -> Iterator[
        tuple[EmulatedRobot, Any]]:
    """A router, the emulated robot on the scenario's clay (1 ms period) and a
    ``RobotPlant`` with ``watchdog_s`` driving it, the plant already answered 5 times; all
    closed afterwards (the robot also when the test closed it first)."""
    from haptic.common.ros2.publisher import open_client_session
    from haptic.common.ros2.settings import Ros2Settings
    from haptic.slave_sim.clay.sim import make_clay
    from haptic.slave_sim.plant_options import RobotTopics
    from haptic.slave_sim.robot_plant import RobotPlant

    scenario = load_scenario("constant-rate")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with zenoh_router(endpoint):
        robot = EmulatedRobot(endpoint, make_clay(scenario, 1e-3, "numpy"),
                              scenario.tool.start_position_m, 1e-3)
        session = open_client_session(endpoint)
        try:
            plant = RobotPlant(session, Ros2Settings(0, "/haptic", endpoint, 100.0,
                                                     frozenset()),
                               RobotTopics(watchdog_s=watchdog_s), 1e-3, say=say)
            deadline = time.monotonic() + 10.0
            while plant.force.received < 5 and time.monotonic() < deadline:
                plant.step(None, STILL, STILL, MOVING, STILL)
                time.sleep(0.005)
            assert plant.force.received >= 5 and not plant.tripped
            yield robot, plant
            plant.close()
        finally:
            robot.close()
            session.close()


#: A tool at rest and one moving at 10 mm/s along x, (1, 2) m or m/s.
STILL = np.zeros((1, 2))
MOVING = np.array([[0.01, 0.0]])


def test_the_robot_watchdog_holds_the_robot_when_its_force_stops(tmp_path: Path) -> None:
    said: list[str] = []
    with _robot_and_plant(0.2, said.append) as (robot, plant):
        commands = robot.commands
        robot.close()  # the robot goes silent; the slave goes on commanding it
        deadline = time.monotonic() + 10.0
        result = plant.step(None, STILL, STILL, MOVING, STILL)
        while not plant.tripped and time.monotonic() < deadline:
            time.sleep(0.005)
            result = plant.step(None, STILL, STILL, MOVING, STILL)
        assert plant.tripped and plant.trips == 1 and len(said) == 1
        assert "watchdog" in said[0] and np.all(result.force_N == 0.0)
        assert plant.figures["robot_watchdog_trips"] == 1
        assert commands > 0


def test_a_stall_of_the_slave_itself_does_not_trip_the_robot_watchdog(tmp_path: Path) -> None:
    """The slave's process stalls (no steps, no commands) longer than the watchdog while the
    robot has answered every command: the robot is not silent while commanded, so its
    watchdog holds (a loaded machine's stall is the slave's lateness, not the robot's)."""
    watchdog_s = 0.5
    with _robot_and_plant(watchdog_s, print) as (robot, plant):
        # every command answered before the stall, however slow the machine
        deadline = time.monotonic() + 10.0
        while (robot.sequence < plant.figures["robot_commands"]
               or plant.force.received < robot.sequence) and time.monotonic() < deadline:
            time.sleep(0.005)
        assert plant.force.received == plant.figures["robot_commands"] >= 5
        time.sleep(1.5 * watchdog_s)  # the slave's stall
        plant.step(None, STILL, STILL, MOVING, STILL)
        assert not plant.tripped and plant.trips == 0


@pytest.mark.slow
def test_a_robot_that_stops_publishing_stops_the_tool_and_holds_the_handle(
        tmp_path: Path) -> None:
    """The robot's force stops coming mid-cut: the plant's watchdog trips, the slave's tool
    stops (its forces off, a ``tool_stopped`` event naming the robot) and the master holds
    its handle (``handle_held``): the safe state, as for any stop of the slave's tool."""
    from haptic.slave_sim.clay.sim import make_clay

    scenario = load_scenario("constant-rate")
    period_s = load_config()["model"]["sample_period_s"]
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with zenoh_router(endpoint):
        robot = EmulatedRobot(endpoint, make_clay(scenario, period_s, "warp", "cpu"),
                              scenario.tool.start_position_m, period_s, silent_after=2000)
        try:
            slave = _session(tmp_path / "robot", "--ros2-endpoint", endpoint,
                             "--slave-args", "--plant ros2")
        finally:
            robot.close()
    master = json.loads((tmp_path / "robot" / "master.json").read_text())
    assert slave["robot_watchdog_trips"] == 1 and slave["robot_forces_received"] >= 1000
    stops = [e for e in slave["events"] if e["kind"] == "tool_stopped"]
    assert any("robot plant's watchdog" in e["reason"] for e in stops), slave["events"]
    assert any(e["kind"] == "handle_held" for e in master["events"]), master["events"]


def test_a_robot_trip_while_the_tool_is_already_stopped_is_said_once() -> None:
    """The robot's watchdog trips while the tool is stopped for another cause (the master in
    its safe state, a resync after a late message on a loaded machine): the tool now stays
    stopped for the robot, and a ``tool_stopped`` event says so, once."""
    from haptic.slave_sim.supervisor import Transition
    from tests.slave_sim.test_supervisor import handle, make, start

    supervisor = make()
    start(supervisor)
    supervisor.receive(handle(0.05, enabled=False, seq=10))
    assert supervisor.update(0.01, True, (0.05, 0.0)) is Transition.STOP
    assert "robot" not in supervisor.events[-1]["reason"]
    for sequence, now_s in ((11, 0.011), (12, 0.012)):
        supervisor.receive(handle(0.05, enabled=False, seq=sequence))
        assert supervisor.update(now_s, True, (0.05, 0.0), plant_fault=True) is Transition.NONE
    robot_stops = [event for event in supervisor.events if event["kind"] == "tool_stopped"
                   and "robot plant's watchdog" in event["reason"]]
    assert len(robot_stops) == 1 and robot_stops[0]["time_s"] == 0.011
    assert supervisor.stop_reason() == "the robot plant's watchdog tripped"
