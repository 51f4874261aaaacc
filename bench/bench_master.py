"""Benchmark of the master side: node and rig-model step costs, and the control cycle over
the simulated rig's virtual CAN bus (SYNC -> TPDOs -> node -> RPDOs).

    python bench/bench_master.py [--cycles N] [--lanes L] [--json]

Figures are wall-clock on this machine (noisy; compare ratios). Nothing is asserted.
"""

from __future__ import annotations

import argparse
import json
import time
import uuid

import numpy as np

from haptic.common.config import load_config, override
from haptic.common.model import model_from_config
from haptic.master.hardware import create_hardware
from haptic.master.node import MasterNode
from haptic.master.rig_model import RigModel
from haptic.master.runner import run_master
from haptic.master.settings import master_settings


def _percentiles_us(samples_s: np.ndarray) -> dict[str, float]:
    us = samples_s * 1e6
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
        node_state = node.activate(np.zeros((count, 2)))
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


def bench_can_cycle(config: dict, cycles: int) -> dict[str, dict[str, float]]:
    """One control cycle over the virtual bus: read (SYNC, wait for TPDOs and the sensor
    frame) + node step + write (RPDOs), back to back; then a run paced at Ts."""
    config = override(config, "master.sim.channel", f"bench-{uuid.uuid4().hex}")
    model = model_from_config(config)
    node = MasterNode.from_model(model, master_settings(config).safety)
    results = {}
    with create_hardware("sim", config) as hardware:
        hardware.configure()
        hardware.activate()
        reading = hardware.read()
        state = node.activate(reading.position_m[None])
        times = np.empty(cycles)
        zero = np.zeros((1, 2))
        for k in range(cycles):
            t0 = time.perf_counter()
            command = node.step(state, reading.force_N[None], reading.position_m[None], zero)
            hardware.write(command[0])
            reading = hardware.read()
            times[k] = time.perf_counter() - t0
        hardware.deactivate()
        results["can_cycle_unpaced"] = _percentiles_us(times)
    with create_hardware("sim", config) as hardware:
        summary = run_master(hardware, MasterNode.from_model(model, master_settings(
            config).safety), cycles, pace=True)
    results["can_cycle_paced_at_ts"] = {
        "cycles": float(summary.cycles), "overruns": float(summary.overruns),
        "overrun_fraction": summary.overruns / summary.cycles,
        "max_lateness_us": summary.max_lateness_s * 1e6,
        "achieved_period_us": summary.wall_time_s / summary.cycles * 1e6,
        "target_period_us": model.sample_period_s * 1e6,
    }
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cycles", type=int, default=5000)
    parser.add_argument("--lanes", type=int, default=64)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    config = load_config()
    results = bench_blocks(config, args.cycles, args.lanes)
    results.update(bench_can_cycle(config, args.cycles))
    if args.json:
        print(json.dumps(results))
        return
    for name, figures in results.items():
        text = ", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}"
                         for k, v in figures.items())
        print(f"{name:28s} {text}")


if __name__ == "__main__":
    main()
