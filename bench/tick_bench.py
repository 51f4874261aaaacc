"""Benchmark of one tick's own work, in-process: the supervise and node stages of the slave
and the master, without the network, the pacing loop or the other stages.

It drives :class:`~haptic.slave_sim.tick.SlaveTick` and :class:`~haptic.master.tick.MasterTick`
through their whole-tick call ``step_lane`` as the programs do (slave_sim/program_stages.py,
master/program_stages.py), each built from the shipped configuration as its program builds
it (the slave's node with the scenario's clay grid, its input guard, supervisor, resync and
pacing; the master's node, supervisor and tool guard), and times the two stages with
:func:`time.perf_counter_ns` exactly where the tick driver does: supervise from the call to
``supervised_ns``, node from there to the call's return.

The slave's master is scripted: one ``HandleState`` per period Ts (a force that pushes the
tool into the clay and back, the handle's position with it), delivered to the ticks in
groups drawn from a fixed seed: mostly one a tick, sometimes none and then two or three in
the next tick (``--late``, ``--late2``: the fractions of ticks that start a one- or
two-tick gap), so the pacing takes 0 to 3 node steps a tick as it does over a jittery link.
The master's slave is scripted too: one ``ToolState`` a tick, in sync with the handle.

Reported per side and stage: p50, p99, max and mean (us), over the measured ticks (after
``--warmup`` ticks, which include the resync before the tool runs); for the slave's node
stage also the time per node step over the ticks with at least one step, and the
distribution of node steps per tick. The garbage collector runs as in the programs (they
freeze it at the start: common/runtime/gc_pauses.py is not applied here; ``--no-gc``
disables it while timing). ``--cpu-clock`` times with the thread's CPU time instead of the
wall clock: on a machine shared with other work it leaves out the time the thread waited for
a core (for comparing two trees there; the real-time figures are the wall clock's).

Usage: ``python bench/tick_bench.py [--ticks N] [--json] [--cpu-clock]
[--profile slave|master]``;
``--profile`` prints the top of a cProfile of that side's ticks instead.
"""

from __future__ import annotations

import argparse
import cProfile
import gc
import json
import math
import pstats
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from haptic.common.config import load_config
from haptic.common.runtime.machine import cpu_model
from haptic.common.wire.messages import Flags, HandleState, ToolState

NS = 1e-9


def delivery_groups(ticks: int, late: float, late2: float, seed: int) -> list[int]:
    """Messages delivered per tick, one master sample per tick on average: mostly 1; a
    fraction ``late`` of ticks starts a one-tick gap (0 then 2), ``late2`` a two-tick gap
    (0, 0 then 3)."""
    rng = np.random.default_rng(seed)
    groups: list[int] = []
    while len(groups) < ticks:
        draw = rng.random()
        if draw < late2:
            groups += [0, 0, 3]
        elif draw < late2 + late:
            groups += [0, 2]
        else:
            groups.append(1)
    return groups[:ticks]


def percentiles_us(values_ns: np.ndarray) -> dict[str, float]:
    """p50, p99, max and mean of durations in ns, in us (NaN where there are none)."""
    if values_ns.size == 0:
        return {"p50_us": math.nan, "p99_us": math.nan, "max_us": math.nan,
                "mean_us": math.nan, "count": 0}
    p50, p99 = np.percentile(values_ns, (50.0, 99.0)) * 1e-3
    return {"p50_us": float(p50), "p99_us": float(p99), "max_us": float(values_ns.max() * 1e-3),
            "mean_us": float(values_ns.mean() * 1e-3), "count": int(values_ns.size)}


class SlaveBench:
    """The slave's tick as slave_sim/program.py builds it, fed by a scripted master."""

    def __init__(self, config: dict[str, Any]) -> None:
        from haptic.common.model.work_area import slave_work_area_m
        from haptic.slave_sim.input_guard import InputGuard, InputGuardSettings
        from haptic.slave_sim.node import SlaveNode
        from haptic.slave_sim.pacing import MasterSamplePacing, PacingSettings
        from haptic.slave_sim.resync import ToolResync
        from haptic.slave_sim.supervisor import SlaveSupervisor
        from haptic.slave_sim.tick import SlaveLaneInputs, SlaveTick

        node = self.node = SlaveNode.from_config(config)
        self.period_s = period_s = node.sample_period_s
        link = config["link"]
        grid = node.scenario.grid
        ratio = node.position_ratio
        supervisor = SlaveSupervisor(
            (float(ratio[0]), float(ratio[1])), 0.001,
            slave_work_area_m(grid.x_range_m, grid.y_range_m),
            link["watchdog"]["max_message_age_s"], link["watchdog"]["resync_messages"],
            grid_m=(grid.x_range_m[0], grid.x_range_m[1], grid.y_range_m[0], grid.y_range_m[1]))
        guard = InputGuard(InputGuardSettings.from_config(config), period_s,
                           events=supervisor.events)
        self.tick = SlaveTick(node, node.initial_state(1), [supervisor], [guard],
                              ToolResync(node))
        self.tick.start()
        self.tick.follow_gain(node.model.ch1_gain_k, True)
        self.pacing = MasterSamplePacing(PacingSettings.from_config(config))
        self.tick.configure_lane(self.pacing)
        self.tick.first_output()
        self.inputs = SlaveLaneInputs()
        self._seq = 0
        self._last_sent_s = -math.inf
        self.start_x_m = float(node.scenario.tool.start_position_m[0])

    def message(self, seq: int) -> HandleState:
        """The scripted master's sample ``seq``: a push into the clay along x and back
        (period 2 s), a small force across; the handle's position moves with it."""
        t = seq * self.period_s
        fx = 2.0 * math.sin(2.0 * math.pi * 0.5 * t)
        fy = 0.3 * math.sin(2.0 * math.pi * 1.3 * t)
        x = self.start_x_m + 0.01 * (1.0 - math.cos(2.0 * math.pi * 0.5 * t))
        y = 0.002 * math.sin(2.0 * math.pi * 1.3 * t)
        return HandleState(1, seq, int(t * 1e9), Flags.FORCES_ENABLED, (fx, fy), (x, y),
                           gain_k=self.node.model.ch1_gain_k)

    def run(self, groups: list[int], warmup: int,
            clock: Callable[[], int] = time.perf_counter_ns) -> dict[str, np.ndarray]:
        """Step one tick per entry of ``groups`` (messages delivered); returns per measured
        tick the supervise and node times (ns) and the node steps."""
        inputs, tick = self.inputs, self.tick
        outputs = tick._lane.outputs
        measured = len(groups) - warmup
        supervise = np.zeros(measured, np.int64)
        node = np.zeros(measured, np.int64)
        steps = np.zeros(measured, np.int64)
        running = np.zeros(measured, bool)
        seq = self._seq
        last_fresh_s = -math.inf
        for index, size in enumerate(groups):
            now_s = index * self.period_s
            delivered = [self.message(seq + k) for k in range(size)]
            seq += size
            inputs.now_s = now_s
            inputs.message = delivered[-1] if delivered else None
            inputs.earlier = delivered[:-1]
            if delivered:
                last_fresh_s = now_s
            inputs.silence_s = now_s - last_fresh_s
            before_s = outputs.sample_time_s
            start_ns = clock()
            tick.step_lane(inputs, clock)
            end_ns = clock()
            if index >= warmup:
                at = index - warmup
                supervise[at] = outputs.supervised_ns - start_ns
                node[at] = end_ns - outputs.supervised_ns
                steps[at] = round((outputs.sample_time_s - before_s) / self.period_s)
                running[at] = tick.running[0]
        self._seq = seq
        return {"supervise": supervise, "node": node, "steps": steps, "running": running}


class MasterBench:
    """The master's tick as master/program.py builds it (no governor: the shipped
    configuration's), fed by a scripted slave and handle."""

    def __init__(self, config: dict[str, Any]) -> None:
        from haptic.common.config.scenario import load_scenario
        from haptic.common.model.teleop import model_from_config
        from haptic.common.model.work_area import work_area_from_config
        from haptic.master.node import MasterNode
        from haptic.master.settings import master_settings, with_work_area
        from haptic.master.supervisor import MasterSupervisor
        from haptic.master.tick import MasterLaneInputs, MasterTick
        from haptic.master.tool_guard import ToolGuardSettings, ToolInputGuard

        model = model_from_config(config)
        scenario = load_scenario(config["slave"]["scenario"])
        area = work_area_from_config(config, scenario.grid.x_range_m, scenario.grid.y_range_m)
        settings = master_settings(config)
        node = MasterNode.from_model(model, with_work_area(settings.safety, area))
        self.period_s = model.sample_period_s
        ratio = [float(axis.position_ratio_ah1) for axis in model.axes]
        self.ratio = ratio
        link = config["link"]
        guard = ToolInputGuard(ToolGuardSettings.from_config(config), self.period_s)
        supervisor = MasterSupervisor((ratio[0], ratio[1]), 0.001,
                                      link["watchdog"]["max_message_age_s"],
                                      link["watchdog"]["resync_messages"], guard)
        self.tick = MasterTick(node, [supervisor])
        self.position = np.array([[0.01, 0.0]])
        self.tick.prepare(self.position)
        self.tick.start(self.position[0])
        self.tick.configure_lane(model.ch1_gain_k)
        self.inputs = MasterLaneInputs()

    def run(self, ticks: int, warmup: int,
            clock: Callable[[], int] = time.perf_counter_ns) -> dict[str, np.ndarray]:
        """Step ``ticks`` ticks, a fresh tool message each; returns per measured tick the
        supervise and node times (ns)."""
        inputs, tick = self.inputs, self.tick
        outputs = tick._lane.outputs
        measured = ticks - warmup
        supervise = np.zeros(measured, np.int64)
        node = np.zeros(measured, np.int64)
        enabled = np.zeros(measured, bool)
        for index in range(ticks):
            t = index * self.period_s
            x = 0.01 + 0.005 * math.sin(2.0 * math.pi * 0.5 * t)
            inputs.now_s = t
            inputs.handle_position_m[0] = (x, 0.0)
            push = 0.05 if index < 200 else 1.5 * math.sin(2.0 * math.pi * 0.5 * t)
            inputs.handle_force_N[0] = (push, 0.2)
            inputs.cycle = index
            inputs.message = inputs.latest = ToolState(
                1, index, int(t * 1e9), Flags.FORCES_ENABLED, (0.3 * push, 0.0),
                (self.ratio[0] * x, 0.0), (0.0, 0.0), 0.0, 0.0)
            inputs.silence_s = 0.0
            start_ns = clock()
            tick.step_lane(inputs, clock)
            end_ns = clock()
            if index >= warmup:
                at = index - warmup
                supervise[at] = outputs.supervised_ns - start_ns
                node[at] = end_ns - outputs.supervised_ns
                enabled[at] = outputs.enabled
        return {"supervise": supervise, "node": node, "enabled": enabled}


def slave_figures(times: dict[str, np.ndarray]) -> dict[str, Any]:
    """The slave's stage figures, the node stage per node step and the steps per tick."""
    steps = times["steps"]
    stepped = steps > 0
    per_step = times["node"][stepped] / steps[stepped]
    counts = np.bincount(steps)
    return {
        "stages": {"supervise": percentiles_us(times["supervise"]),
                   "node": percentiles_us(times["node"])},
        "node_per_step": percentiles_us(per_step),
        "node_by_steps": {str(k): percentiles_us(times["node"][steps == k])
                          for k in range(counts.size) if counts[k]},
        "steps_per_tick": {str(k): int(counts[k]) for k in range(counts.size) if counts[k]},
        "running_fraction": float(times["running"].mean()),
    }


def master_figures(times: dict[str, np.ndarray]) -> dict[str, Any]:
    """The master's stage figures."""
    return {"stages": {"supervise": percentiles_us(times["supervise"]),
                       "node": percentiles_us(times["node"])},
            "enabled_fraction": float(times["enabled"].mean())}


def benchmark(ticks: int, warmup: int, late: float, late2: float, seed: int,
              no_gc: bool, cpu_clock: bool = False) -> dict[str, Any]:
    """Both sides' figures (see the module docstring); ``cpu_clock``: timed with the thread's
    CPU time instead of the wall clock."""
    clock = time.thread_time_ns if cpu_clock else time.perf_counter_ns
    config = load_config()
    slave, master = SlaveBench(config), MasterBench(config)
    groups = delivery_groups(ticks + warmup, late, late2, seed)
    if no_gc:
        gc.collect()
        gc.disable()
    try:
        slave_times = slave.run(groups, warmup, clock)
        master_times = master.run(ticks + warmup, warmup, clock)
    finally:
        gc.enable()
    return {"cpu": cpu_model(), "ticks": ticks, "warmup": warmup, "late": late,
            "late2": late2, "seed": seed, "gc_disabled": no_gc,
            "clock": "thread CPU time" if cpu_clock else "wall",
            "slave": slave_figures(slave_times), "master": master_figures(master_times)}


def profile(side: str, ticks: int, warmup: int, late: float, late2: float, seed: int) -> None:
    """Print the top of a cProfile of ``side``'s ticks (after the warm-up)."""
    config = load_config()
    bench: Any = SlaveBench(config) if side == "slave" else MasterBench(config)
    profiler = cProfile.Profile()
    if side == "slave":
        bench.run(delivery_groups(warmup, late, late2, seed), warmup)
        groups = delivery_groups(ticks, late, late2, seed + 1)
        profiler.runcall(bench.run, groups, 0)
    else:
        profiler.runcall(bench.run, ticks, warmup)
    pstats.Stats(profiler).sort_stats("tottime").print_stats(30)


def print_table(result: dict[str, Any]) -> None:
    """The figures as text."""
    print(f"tick_bench: {result['ticks']} ticks after {result['warmup']} ({result['cpu']}, "
          f"{result['clock']} clock)")
    for side in ("master", "slave"):
        figures = result[side]
        for name, f in figures["stages"].items():
            print(f"  {side:6s} {name:9s} p50 {f['p50_us']:6.1f}  p99 {f['p99_us']:6.1f}  "
                  f"max {f['max_us']:7.1f}  mean {f['mean_us']:6.1f} us")
    slave = result["slave"]
    f = slave["node_per_step"]
    print(f"  slave  node per step (ticks with >= 1 step) p50 {f['p50_us']:.1f}  "
          f"p99 {f['p99_us']:.1f} us")
    for k, g in slave["node_by_steps"].items():
        print(f"  slave  node, ticks with {k} steps ({g['count']}): p50 {g['p50_us']:.1f}  "
              f"p99 {g['p99_us']:.1f} us")
    print(f"  slave running {slave['running_fraction']:.3f}, master enabled "
          f"{result['master']['enabled_fraction']:.3f}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    parser.add_argument("--ticks", type=int, default=20000, help="measured ticks per side")
    parser.add_argument("--warmup", type=int, default=2000, help="ticks before measuring")
    parser.add_argument("--late", type=float, default=0.05,
                        help="fraction of ticks that start a one-tick gap (0 then 2)")
    parser.add_argument("--late2", type=float, default=0.02,
                        help="fraction of ticks that start a two-tick gap (0, 0 then 3)")
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--no-gc", action="store_true", help="disable the GC while timing")
    parser.add_argument("--cpu-clock", action="store_true",
                        help="time with the thread's CPU time (time.thread_time_ns): on a shared "
                        "machine, leaves out the time other processes held the core")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    parser.add_argument("--profile", choices=("slave", "master"),
                        help="print a cProfile of that side's ticks instead")
    args = parser.parse_args(argv)
    if args.ticks < 1 or args.warmup < 0:
        parser.error("--ticks must be >= 1 and --warmup >= 0")
    if args.profile:
        profile(args.profile, args.ticks, args.warmup, args.late, args.late2, args.seed)
        return 0
    result = benchmark(args.ticks, args.warmup, args.late, args.late2, args.seed, args.no_gc,
                       args.cpu_clock)
    if args.json:
        json.dump(result, sys.stdout, indent=2, sort_keys=True)
        print()
    else:
        print_table(result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
