"""Benchmark of the master side: node and rig-model step costs, and the control cycle over
the simulated rig's CAN bus (SYNC -> TPDOs -> node -> RPDOs), in process and across
processes.

    python bench/bench_master.py [--cycles N] [--lanes L] [--rigs NAME,...] [--spin-s S] [--json]

The simulated rigs (``--rigs``, default all of them): the same devices and the same CAN
driver on

- ``inproc``: a thread of this process on python-can's virtual bus (backend ``sim-inproc``;
  the devices compete with the loop for the interpreter);
- ``emulator_unix``: their own process, ``haptic-rig-sim``, on the ``unix_datagram`` bus
  (backend ``sim`` as shipped);
- ``emulator_udp``: their own process on python-can's ``udp_multicast`` (a private port).

For each: the CAN cycle (``hardware.read()``: SYNC sent to the last PDO received) and the
whole control cycle (read + node step + operator display + RPDOs), back to back
(``unpaced``) and paced at Ts by the programs' real-time runner (common/runtime/runner.py: sleep,
then spin the last ``[runner] spin_s``, 0.1 ms; re-anchored after a stall), and paced with
each SYNC sent ``[master.can] sync_lead_s`` ahead of its tick (``paced_sync_lead``: the read
then only collects the answers, as in the master program), with p50/p99/max, the overruns
and the runner's period error. With them, the CPU time each cycle costs, which on a small
machine says more than the wall clock (three processes share two cores in ``haptic-session``):
the loop thread's per read and per cycle (``read_cpu_mean_us``, ``cycle_cpu_mean_us``), and the
emulator process's per cycle (``emulator_cpu_per_cycle_us``, from /proc; the ``inproc`` rig's
devices are a thread of this process, in ``process_cpu_per_cycle_us``). On the emulator rigs
the cycle's RPDOs and display frame wait for the next SYNC and go out in its burst
(``CanHandleDriver.until_sync``, docs/master.md): the read that sends that SYNC (without a
lead) pays for them.
Figures are wall-clock on this machine (noisy: other programs on a small machine move them
a lot, so the 1-minute load average is printed with them). Nothing is asserted.
"""

from __future__ import annotations

import argparse
import json
import os
import time
import uuid

import numpy as np

from haptic.common.config import load_config, override
from haptic.common.model.teleop import model_from_config
from haptic.common.runtime.machine import cpu_model
from haptic.common.runtime.realtime import RealtimeSettings
from haptic.common.runtime.runner import FreeRunningClock, RealTimeRunner
from haptic.common.runtime.runner_config import runner_settings_from
from haptic.master.hardware.interface import HandleHardware, create_hardware
from haptic.master.node import MasterNode
from haptic.master.program import device_process_cpu
from haptic.master.settings import master_settings
from haptic.master.simulated_rig.rig_block import RigModel
from haptic.master.standalone import early_sync

#: The simulated rigs: name -> (backend, configuration overrides).
RIGS: dict[str, tuple[str, dict[str, object]]] = {
    "inproc": ("sim-inproc", {}),
    "emulator_unix": ("sim", {}),
    "emulator_udp": ("sim", {"master.sim.emulator.interface": "udp_multicast",
                             "master.sim.emulator.channel": "239.74.163.2"}),
}


def _percentiles_us(samples_s: np.ndarray) -> dict[str, float]:
    us = np.asarray(samples_s) * 1e6
    return {"mean_us": float(us.mean()), "p50_us": float(np.percentile(us, 50)),
            "p99_us": float(np.percentile(us, 99)), "max_us": float(us.max())}


def bench_blocks(config: dict, cycles: int, lanes: int) -> dict[str, dict[str, float]]:
    """Cost of MasterNode.step and RigModel.step in lockstep, for 1 and ``lanes`` lanes."""
    model = model_from_config(config)
    settings = master_settings(config)
    node = MasterNode.from_model(model, settings.safety)
    rig = RigModel.from_model(model, settings.sim.operator, 0.01)
    results = {}
    for count in (1, lanes):
        rig_state = rig.initial_state(np.zeros((count, 2)), np.random.default_rng(0))
        node_state = node.initial_state(np.zeros((count, 2)))
        command = np.zeros((count, 2))
        zero = np.zeros((count, 2))
        node_times = np.empty(cycles)
        rig_times = np.empty(cycles)
        for k in range(cycles):
            t0 = time.perf_counter()
            sample = rig.step(rig_state, command, zero)
            t1 = time.perf_counter()
            command = node.step(node_state, sample.handle_force_measured_N,
                                sample.handle_position_m, zero)
            t2 = time.perf_counter()
            rig_times[k], node_times[k] = t1 - t0, t2 - t1
        results[f"node_step_{count}_lanes"] = _percentiles_us(node_times)
        results[f"rig_step_{count}_lanes"] = _percentiles_us(rig_times)
    return results


def _run_cycles(hardware: HandleHardware, node: MasterNode, cycles: int, pace: bool,
                spin_s: float, lead_s: float = 0.0,
                realtime: RealtimeSettings | None = None) -> dict[str, float]:
    """``cycles`` control cycles on configured-active ``hardware``: read, node step, present
    the (zero) tool force, write; paced at the node's Ts when ``pace`` (sleep, then spin the
    last ``spin_s``), with each SYNC sent ``lead_s`` before its tick when > 0 (the master
    program's ``[master.can] sync_lead_s``: ``hardware.sync()`` in the runner's wait; the
    read then only collects). Figures of the read (the
    CAN cycle as the tick sees it) and of the whole cycle, the overruns and the faulted
    cycles."""
    period_s = node.period_s
    reading = hardware.read()
    state = node.initial_state(reading.position_m[None])
    hardware.present_forces_enabled(True)  # the master alone: forces on from the start
    zero = np.zeros((1, 2))
    reads = np.empty(cycles)
    totals = np.empty(cycles)
    reads_cpu = np.empty(cycles)
    totals_cpu = np.empty(cycles)
    faulted = 0
    thread_time = time.thread_time

    def step(k: int, _now_ns: int) -> None:
        nonlocal faulted
        c0, t0 = thread_time(), time.perf_counter()
        reading = hardware.read()
        c1, t1 = thread_time(), time.perf_counter()
        faulted += bool(reading.faults)
        command = node.step(state, reading.force_N[None], reading.position_m[None], zero)
        hardware.present_tool_force(zero[0])
        hardware.write(command[0])
        c2, t2 = thread_time(), time.perf_counter()
        reads[k], totals[k] = t1 - t0, t2 - t0
        reads_cpu[k], totals_cpu[k] = c1 - c0, c2 - c0
        if k + 1 >= cycles:
            runner.request_stop("cycles")

    # the programs' runner (common/runtime/runner.py); unpaced, its ticks run back to back
    free = None if pace else FreeRunningClock()
    runner = RealTimeRunner(period_s, step, spin_s=spin_s if pace else 0.0, show_status=False,
                            realtime=realtime,
                            lead=early_sync(hardware, 0) if lead_s > 0.0 else None,
                            lead_s=lead_s,
                            **({} if free is None else {"clock_ns": free.clock_ns,
                                                        "sleep": free.sleep}))
    emulator_start_s = hardware.device_process_cpu_s()
    stats = runner.run()
    emulator = device_process_cpu(emulator_start_s, hardware.device_process_cpu_s(),
                                  stats.elapsed_s)
    figures = {f"read_{k}": v for k, v in _percentiles_us(reads).items()}
    figures.update({f"cycle_{k}": v for k, v in _percentiles_us(totals).items()})
    figures["read_cpu_mean_us"] = float(reads_cpu.mean() * 1e6)
    figures["cycle_cpu_mean_us"] = float(totals_cpu.mean() * 1e6)
    figures["process_cpu_per_cycle_us"] = stats.process_cpu_s / cycles * 1e6
    if emulator:
        figures["emulator_cpu_per_cycle_us"] = emulator["rig_emulator_cpu_s"] / cycles * 1e6
    figures["cycles"] = float(cycles)
    figures["faulted_cycles"] = float(faulted)
    if stats.scheduling is not None:
        held = stats.scheduling.cpu_latency_limit_us
        figures["cpu_latency_limit_us"] = float("nan") if held is None else float(held)
    if pace:
        figures.update({"overruns": float(stats.overruns),
                        "overrun_fraction": stats.overruns / cycles,
                        "period_error_p99_us": stats.period_error_p99_s * 1e6,
                        "period_error_max_us": stats.period_error_max_s * 1e6,
                        "stalls": float(stats.stalls), "target_period_us": period_s * 1e6})
    return figures


def bench_can_cycle(config: dict, cycles: int, rig: str,
                    spin_s: float | None = None) -> dict[str, dict[str, float]]:
    """The CAN cycle and the control cycle on the simulated rig ``rig`` (a :data:`RIGS`
    name), back to back and paced at Ts (spinning the last ``spin_s``, default the
    configuration's ``[runner] spin_s``)."""
    backend, overrides = RIGS[rig]
    config = override(config, "master.sim.channel", f"bench-{uuid.uuid4().hex}")
    for key, value in overrides.items():
        config = override(config, key, value)
    model = model_from_config(config)
    safety = master_settings(config).safety
    spin_s = config["runner"]["spin_s"] if spin_s is None else spin_s
    # the loop thread as the master program schedules it: tight timers, the GIL interval, the
    # CPU latency request (without it every wake-up of a halted virtual CPU costs far more)
    realtime = runner_settings_from(config).realtime
    results = {}
    with create_hardware(backend, config) as hardware:
        hardware.configure()
        hardware.activate()
        warm_up = min(cycles, 500)
        _run_cycles(hardware, MasterNode.from_model(model, safety), warm_up, False, spin_s,
                    realtime=realtime)
        results[f"can_{rig}_unpaced"] = _run_cycles(
            hardware, MasterNode.from_model(model, safety), cycles, False, spin_s,
            realtime=realtime)
        results[f"can_{rig}_paced_at_ts"] = _run_cycles(
            hardware, MasterNode.from_model(model, safety), cycles, True, spin_s,
            realtime=realtime)
        lead_s = config["master"]["can"]["sync_lead_s"]
        if lead_s > 0.0:
            results[f"can_{rig}_paced_sync_lead"] = _run_cycles(
                hardware, MasterNode.from_model(model, safety), cycles, True, spin_s, lead_s,
                realtime=realtime)
            results[f"can_{rig}_paced_sync_lead"]["sync_lead_us"] = lead_s * 1e6
        hardware.read()  # the last lead's SYNC
        hardware.deactivate()
    return results


def main() -> None:
    parser = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.split("\n")[0])
    parser.add_argument("--cycles", type=int, default=5000)
    parser.add_argument("--lanes", type=int, default=64)
    parser.add_argument("--rigs", default=",".join(RIGS),
                        help="simulated rigs to run the CAN cycle on, comma-separated, of "
                        f"{', '.join(RIGS)} (default all)")
    parser.add_argument("--spin-s", type=float, metavar="S",
                        help="paced runs spin this long before each tick, s (default [runner] "
                        "spin_s, 0.0001)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    config = load_config()
    results: dict[str, dict[str, float | str]] = {"machine": {
        "cpu_model": cpu_model(), "cpus": float(os.cpu_count() or 0),
        "load_average_1min_at_start": os.getloadavg()[0]}}
    results.update(bench_blocks(config, args.cycles, args.lanes))
    rigs = [name.strip() for name in args.rigs.split(",") if name.strip()]
    unknown = [name for name in rigs if name not in RIGS]
    if unknown:
        parser.error(f"unknown rig {', '.join(unknown)}; known: {', '.join(RIGS)}")
    for rig in rigs:
        results.update(bench_can_cycle(config, args.cycles, rig, args.spin_s))
    results["machine"]["load_average_1min_at_end"] = os.getloadavg()[0]
    if args.json:
        print(json.dumps(results))
        return
    for name, figures in results.items():
        text = ", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}"
                         for k, v in figures.items())
        print(f"{name:38s} {text}")


if __name__ == "__main__":
    main()
