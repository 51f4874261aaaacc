"""The harness's run: the program's last work before the first tick (``before_loop``) runs
once, on the loop's thread, with the heap already frozen, and before the peer's backlog is
dropped; the first tick then finds the link empty of that backlog."""

from __future__ import annotations

import argparse
import dataclasses
import gc
import threading
import time

from haptic.common.runtime.cli_options import add_run_options, run_options_from_args
from haptic.common.runtime.program_harness import ProgramHarness
from haptic.common.runtime.runner import StopSignals
from haptic.common.runtime.tick_driver import TickDriver
from haptic.common.wire.link import Link
from tests.helpers.link_helpers import configs, wait_for_peers

PERIOD_S = 0.001


def _options():
    parser = argparse.ArgumentParser()
    add_run_options(parser)
    options = run_options_from_args(parser.parse_args([]), "master")
    return dataclasses.replace(options, max_steps=5)


class _PollingSide:
    """A side of one stage: it polls the link and keeps (tick, thread, message)."""

    stage_names = ("poll",)
    schedule_shift_ns = 0

    def __init__(self, link: Link, ticks: list[tuple[int, int, object]]) -> None:
        self.link = link
        self.ticks = ticks

    def stages(self) -> tuple:
        return (self.poll,)

    def poll(self, tick: int, _now_ns: int) -> None:
        self.ticks.append((tick, threading.get_ident(), self.link.poll()))


def test_before_loop_runs_once_on_the_loop_thread_after_the_freeze_before_the_backlog_goes():
    master_cfg, slave_cfg = configs()
    seen: dict[str, object] = {}
    ticks: list[tuple[int, int, object]] = []
    with Link(master_cfg) as master, Link(slave_cfg) as slave:
        wait_for_peers(master, slave)
        for index in range(20):  # the slave's start-up backlog
            slave.send_tool((float(index), 0.0), (0.0, 0.0), (0.0, 0.0), 0.0, 0.0)
        time.sleep(0.5)  # loopback delivery takes milliseconds: all 20 are in the ring
        harness = ProgramHarness("haptic-master", "slave", _options(), master, PERIOD_S)

        def before_loop() -> None:
            seen["calls"] = int(seen.get("calls", 0)) + 1
            seen["thread"] = threading.get_ident()
            seen["frozen"] = gc.get_freeze_count()
            seen["ticks_before"] = len(ticks)
            seen["discarded_before"] = master.discarded_before_start

        with StopSignals() as signals:
            run = harness.run(TickDriver([_PollingSide(master, ticks)]), lambda: "", signals,
                              lambda: None, before_loop=before_loop)
    assert run.steps == 5
    assert seen["calls"] == 1 and seen["ticks_before"] == 0
    assert seen["thread"] == ticks[0][1]  # the loop's thread
    assert seen["frozen"] > 0  # the heap was frozen first
    assert seen["discarded_before"] == 0  # the backlog went after it ...
    assert master.discarded_before_start == 20  # ... undecoded, and no tick got any of it
    assert all(message is None for _, _, message in ticks)
    assert master.receive.stats().delivered == 0
