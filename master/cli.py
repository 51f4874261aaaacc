"""``haptic-master``: run the master node on the handle hardware chosen by name.

Without a slave link the received tool force is zero, so the handle moves as Ch1 makes it
under the operator's force (on the simulated rig, the scripted operator of
``[master.sim] operator``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence

from haptic.common.config import ConfigError, exit_on_config_error, load_config, override
from haptic.common.model import model_from_config
from haptic.master.hardware import HardwareError, create_hardware
from haptic.master.node import MasterNode
from haptic.master.runner import run_master
from haptic.master.settings import master_settings


def build_parser() -> argparse.ArgumentParser:
    """The command line."""
    parser = argparse.ArgumentParser(prog="haptic-master", description=__doc__.split("\n")[0])
    parser.add_argument("--config", help="TOML configuration file (defaults: the paper's)")
    parser.add_argument("--rig", help="handle hardware by name: can or sim ([master] rig)")
    parser.add_argument("--operator", help="simulated operator spec ([master.sim] operator), "
                        "e.g. constant:fx=1,fy=0,onset=0.05")
    parser.add_argument("--k", type=float, help="gain k of Ch1 ([model.ch1] gain_k)")
    parser.add_argument("--duration", type=float, default=1.0, help="run time, s (default 1)")
    parser.add_argument("--no-pace", action="store_true",
                        help="run cycles back to back instead of every Ts (simulated rig only: "
                             "real drives need SYNC at Ts)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit status (2 for a configuration error, 1 for a
    hardware error or a run that ended in the safe state)."""
    args = build_parser().parse_args(argv)
    with exit_on_config_error():
        config = load_config(args.config)
        if args.rig is not None:
            config = override(config, "master.rig", args.rig)
        if args.operator is not None:
            config = override(config, "master.sim.operator", args.operator)
        if args.k is not None:
            config = override(config, "model.ch1.gain_k", args.k)
        if not (math.isfinite(args.duration) and args.duration > 0.0):
            raise ConfigError("--duration", f"must be a finite number > 0 (got {args.duration})")
        settings = master_settings(config)
        model = model_from_config(config)
        node = MasterNode.from_model(model, settings.safety)
        hardware = create_hardware(settings.rig, config)
    cycles = max(1, round(args.duration / model.sample_period_s))
    try:
        with hardware:
            summary = run_master(hardware, node, cycles, pace=not args.no_pace)
    except HardwareError as error:
        print(f"hardware error: {error}", file=sys.stderr)
        return 1
    result = {
        "rig": settings.rig, "cycles": summary.cycles, "wall_time_s": summary.wall_time_s,
        "overruns": summary.overruns, "max_lateness_s": summary.max_lateness_s,
        "final_position_m": list(summary.final_position_m), "safe_state": summary.safe_state,
        "events": [{"step": e.step, "time_s": e.time_s, "kind": e.kind, "reason": e.reason,
                    "axis": e.axis} for e in summary.events],
        "hardware_faults": summary.hardware_faults[:20],
    }
    if args.json:
        print(json.dumps(result))
    else:
        print(f"rig {settings.rig}: {summary.cycles} cycles in {summary.wall_time_s:.3f} s, "
              f"{summary.overruns} overruns (max {summary.max_lateness_s * 1e3:.2f} ms late)")
        print(f"final handle position x {summary.final_position_m[0]:+.6f} m, "
              f"y {summary.final_position_m[1]:+.6f} m; safe state: {summary.safe_state}")
        for event in summary.events:
            axis = f" [{event.axis}]" if event.axis else ""
            print(f"  t={event.time_s:.4f} s {event.kind}{axis}: {event.reason}")
        for fault in summary.hardware_faults[:20]:
            print(f"  fault: {fault}")
    return 1 if summary.safe_state else 0


if __name__ == "__main__":
    raise SystemExit(main())
