"""A real-link cell of a lane law (wave variables, four-channel with and without its TDPA,
model-mediated): the lane simulator's devices, hand, environment and law kernels
(lockstep/compare_lanes.py) on one lane, the two delay lines replaced by two
:class:`~haptic.common.wire.law_link.LawLink` objects (master and slave side, in this process,
over TCP on loopback) that carry the law's messages (common/wire/law_messages.py) with the
cell's delay and loss injected on their receive paths, paced in real time at Ts by the
programs' runner over the tick driver.

One tick, as the lane simulator's: the master side senses (the hand's and the environment's
forces from the devices, recorded), polls the newest tool message, steps its law and sends;
the slave side polls the newest handle message, steps its law and sends, then both devices
move. As on the delay lines, a side reads the initial message (zeros) as fresh until the
first of the peer's arrives, and a tick with no new message is not fresh (a lost message
keeps the previous one). Over real Zenoh the slave cannot read a handle message in the
tick it was sent, so the real link adds at least one sample to the injected round trip: the
cell reports the round trip it measured (lockstep/compare_real_link_links.py).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from haptic.common.control.law_pairs import PAIRS, PERIOD_S, ControlPair
from haptic.common.runtime.runner import RealTimeRunner, RunStats
from haptic.common.runtime.tick_driver import Stage, TickDriver
from haptic.common.wire.law_link import LawLink
from haptic.common.wire.law_messages import LAW_CHANNELS
from haptic.common.wire.link_config import LinkConfig
from haptic.lockstep.compare_grid import CompareGrid, Lane
from haptic.lockstep.compare_lanes import (
    LaneClay,
    LaneTasks,
    hand_force_N,
    lane_devices,
    lane_steps,
    wall_force_N,
)
from haptic.lockstep.compare_real_link_links import (
    SPIN_S,
    LagRecord,
    link_figures,
    wait_for_each_other,
)
from haptic.lockstep.compare_records import LaneRecords


@dataclass(frozen=True)
class RealLinkRun:
    """What a real-link cell's run leaves: the lane's records, the lags, each side's
    receiving link's figures (``master``: the tool messages it received) and the runner's."""

    records: LaneRecords
    lags: LagRecord
    links: dict[str, dict[str, Any]]
    runner: RunStats


class LawPlant:
    """One lane's devices, hand and environment, and its records: :meth:`sense` gives the
    tick's forces (N), :meth:`move` steps both devices under the laws' commands."""

    def __init__(self, grid: CompareGrid, lane: Lane, steps: int) -> None:
        self.grid = grid
        self.tasks = LaneTasks.of([lane])
        self.clay = LaneClay(self.tasks)
        self.handle, self.tool = lane_devices(grid, 1)
        self.records = LaneRecords.create(PERIOD_S, steps, 1)
        self.fh = np.zeros((1, 2))
        self.fe = np.zeros((1, 2))
        none = np.zeros((1, 2))
        self.master_command: tuple[np.ndarray | None, np.ndarray] = (None, none)
        self.slave_command: tuple[np.ndarray | None, np.ndarray] = (None, none)

    def sense(self, tick: int) -> None:
        """The hand's force on the handle and the tool's on its environment at ``tick``,
        recorded."""
        handle, tool = self.handle, self.tool
        self.fh = hand_force_N(self.grid, self.tasks, tick * PERIOD_S, self.grid.duration_s,
                               handle.position_m, handle.velocity_m_per_s)
        self.fe = (wall_force_N(self.grid, self.tasks, tool.position_m, tool.velocity_m_per_s)
                   + self.clay.force_N(tool.position_m, tool.velocity_m_per_s))
        self.records.add(tick, handle.position_m[:, 0], tool.position_m[:, 0], self.fh[:, 0],
                         self.fe[:, 0])

    def move(self) -> None:
        """Both devices one period towards their laws' commands."""
        self.handle.step(*self.master_command, self.fh)
        self.tool.step(*self.slave_command, -self.fe)


class LawReceiver:
    """A side's newest peer message as the law reads it: ``message`` (1, channels), the
    initial one until the first arrives, and ``fresh`` (1,) as the delay line says it."""

    def __init__(self, link: LawLink, initial: np.ndarray) -> None:
        self.link = link
        self.message = initial.copy()
        self.fresh = np.ones(1, bool)

    def poll(self) -> int | None:
        """Take the newest message; returns the tick it was sent in (None: none yet)."""
        received = self.link.poll()
        if received is not None:
            self.message[0] = received.values
        latest = self.link.latest_law
        self.fresh[0] = received is not None or latest is None
        return None if latest is None else latest.seq


class LawMasterSide:
    """The master's stages: sense, poll (the newest tool message), law, send."""

    stage_names = ("sense", "poll", "law", "send")
    schedule_shift_ns = 0

    def __init__(self, link: LawLink, pair: ControlPair, plant: LawPlant, lags: LagRecord,
                 initial: np.ndarray) -> None:
        self.link, self.pair, self.plant, self.lags = link, pair, plant, lags
        self.receiver = LawReceiver(link, initial)
        self.outgoing = np.zeros((1, pair.handle_channels))

    def stages(self) -> tuple[Stage, ...]:
        return (self.sense, self.poll, self.law, self.send)

    def sense(self, tick: int, _now_ns: int) -> None:
        self.plant.sense(tick)

    def poll(self, tick: int, _now_ns: int) -> None:
        self.lags.to_master[tick] = LagRecord.lag(tick, self.receiver.poll())

    def law(self, _tick: int, _now_ns: int) -> None:
        receiver = self.receiver
        self.plant.master_command = self.pair.master(self.plant.fh, receiver.message,
                                                     receiver.fresh, self.outgoing)

    def send(self, _tick: int, _now_ns: int) -> None:
        self.link.send_values(self.outgoing[0])


class LawSlaveSide:
    """The slave's stages: poll (the newest handle message), law, send, move (both
    devices)."""

    stage_names = ("poll", "law", "send", "move")
    schedule_shift_ns = 0

    def __init__(self, link: LawLink, pair: ControlPair, plant: LawPlant, lags: LagRecord,
                 initial: np.ndarray) -> None:
        self.link, self.pair, self.plant, self.lags = link, pair, plant, lags
        self.receiver = LawReceiver(link, initial)
        self.outgoing = np.zeros((1, pair.tool_channels))

    def stages(self) -> tuple[Stage, ...]:
        return (self.poll, self.law, self.send, self.move)

    def poll(self, tick: int, _now_ns: int) -> None:
        self.lags.to_slave[tick] = LagRecord.lag(tick, self.receiver.poll())

    def law(self, _tick: int, _now_ns: int) -> None:
        plant, receiver = self.plant, self.receiver
        plant.slave_command = self.pair.slave(plant.fe, plant.tool.position_m,
                                              plant.tool.velocity_m_per_s, receiver.message,
                                              receiver.fresh, self.outgoing)

    def send(self, _tick: int, _now_ns: int) -> None:
        self.link.send_values(self.outgoing[0])

    def move(self, _tick: int, _now_ns: int) -> None:
        self.plant.move()


def run_lane_law_cell(control: str, lane: Lane, grid: CompareGrid,
                      configs: tuple[LinkConfig, LinkConfig]) -> RealLinkRun:
    """Run ``control`` on ``lane``'s task for the grid's duration over the two links of
    ``configs`` (master's, slave's), in real time."""
    if control not in PAIRS:
        raise ValueError(f"a lane law is one of {', '.join(PAIRS)} (got {control!r})")
    steps = lane_steps(grid)
    pair: ControlPair = PAIRS[control](1)
    if (pair.handle_channels, pair.tool_channels) != LAW_CHANNELS[control]:
        raise ValueError(f"{control}'s messages do not match their wire schema")
    handle_initial, tool_initial = pair.initial_messages(1)
    plant = LawPlant(grid, lane, steps)
    lags = LagRecord(steps)
    with LawLink(configs[0], control) as master_link, \
            LawLink(configs[1], control) as slave_link:
        wait_for_each_other(master_link, slave_link)
        driver = TickDriver([
            LawMasterSide(master_link, pair, plant, lags, tool_initial),
            LawSlaveSide(slave_link, pair, plant, lags, handle_initial)])
        with np.errstate(over="ignore", invalid="ignore"):
            stats = RealTimeRunner(PERIOD_S, driver.step, max_steps=steps, spin_s=SPIN_S,
                                   show_status=False, handle_signals=False).run()
        links = {"master": link_figures(master_link), "slave": link_figures(slave_link)}
        links["master"]["unsendable"] = master_link.unsendable
        links["slave"]["unsendable"] = slave_link.unsendable
    return RealLinkRun(plant.records, lags, links, stats)


__all__ = ["LawPlant", "RealLinkRun", "run_lane_law_cell"]
