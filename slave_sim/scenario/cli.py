"""``haptic-slave-sim``: run the slave alone on a scenario and save the cut workpiece.

The master is taken as ideal: the received handle force is the scenario's constant
``handle_force_N`` (the paper's experiments hold the force constant), the received handle
position is the tool's own (no tracking error). Prints a per-block summary (mean speed and
force against B v) and writes ``clay.npz`` and ``clay.png`` (height map, block outlines,
tool path) under ``--out``.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from haptic.common.config import ConfigError, exit_on_config_error, load_config, override
from haptic.common.config.scenario import load_scenario
from haptic.common.runtime.console import script_description
from haptic.common.runtime.warp_init import init_warp


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit status (2 for a configuration error)."""
    parser = argparse.ArgumentParser(prog="haptic-slave-sim",
                                     description=script_description(__doc__),
                                     allow_abbrev=False)
    parser.add_argument("--config", help="configuration TOML (default: the shipped one)")
    parser.add_argument("--scenario", help="scenario name or TOML path (default: [slave])")
    parser.add_argument("--duration", type=float, default=4.0, help="simulated time, s")
    parser.add_argument("--out", type=Path, default=Path("out/slave"), help="output folder")
    args = parser.parse_args(argv)
    from haptic.slave_sim.node import SlaveNode  # Warp's kernels: after the parse

    init_warp()  # no start-up banner in the summary
    with exit_on_config_error():
        if not (math.isfinite(args.duration) and 0.0 < args.duration <= 3600.0):
            raise ConfigError("--duration", f"must be in (0, 3600] s (got {args.duration:g})")
        config = load_config(args.config)
        if args.scenario:
            config = override(config, "slave.scenario", args.scenario)
        scenario = load_scenario(config["slave"]["scenario"])
        node = SlaveNode.from_config(config, scenario)
    state = node.initial_state(1)
    handle_force = np.array([scenario.handle_force_N])
    steps = int(round(args.duration / node.sample_period_s))
    path = np.empty((steps, 2))
    velocity = np.empty((steps, 2))
    force = np.empty((steps, 2))
    cutting = np.empty(steps, bool)
    for k in range(steps):
        out = node.step(state, handle_force, state.tool_position_m())
        path[k], velocity[k] = out.tool_position_m[0], out.tool_velocity_m_s[0]
        force[k], cutting[k] = out.tool_force_N[0], out.cutting[0]
    print(f"{scenario.name}: {args.duration:g} s, environment {node.environment_kind}, "
          f"handle force {scenario.handle_force_N} N, tool ends at "
          f"({path[-1, 0]:.4f}, {path[-1, 1]:.4f}) m")
    if node.environment_kind == "clay":
        workpiece = state.environment.workpiece
        xs, ys = workpiece.cell_centers_m()
        ix = np.clip(np.searchsorted(xs, path[:, 0]), 0, xs.size - 1)
        iy = np.clip(np.searchsorted(ys, path[:, 1]), 0, ys.size - 1)
        under = workpiece.block_id[iy, ix]
        speed = np.linalg.norm(velocity, axis=1)
        magnitude = np.linalg.norm(force, axis=1)
        print("  per block, over the steps the tool cut it (tool centre over the block):")
        for index, name in enumerate(workpiece.block_names):
            inside = (under == index) & cutting
            if inside.any():
                damping = workpiece.block_damping_N_s_per_m[index]
                seconds = inside.sum() * node.sample_period_s
                print(f"  {name:>10}: B {damping:g} N s/m, {seconds:.2f} s cutting, "
                      f"mean speed {speed[inside].mean():.4f} m/s, mean |ft| "
                      f"{magnitude[inside].mean():.3f} N, mean B |v| "
                      f"{damping * speed[inside].mean():.3f} N")
        args.out.mkdir(parents=True, exist_ok=True)
        state.environment.save_npz(args.out / "clay.npz")
        state.environment.render_png(args.out / "clay.png", path[:: max(1, steps // 4000)],
                                     title=f"{scenario.name}: slave alone, {args.duration:g} s")
        print(f"  wrote {args.out / 'clay.npz'} and {args.out / 'clay.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
