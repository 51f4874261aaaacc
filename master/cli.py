"""``haptic-master``: the master on the rig PC: the handle hardware chosen by name, the master
node, and (by default) the Zenoh link to ``haptic-slave`` on the real-time runner.

``--no-link`` runs the master alone (the received tool force is zero, so the handle moves as
Ch1 makes it under the operator's force; on the simulated rig, the scripted operator of
``[master.sim] operator``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path

import zenoh

from haptic.common.analysis.preflight import add_preflight_options, run_preflight
from haptic.common.config import ConfigError, exit_on_config_error, load_config, override
from haptic.common.config.control_schema import (
    check_lane_law,
    lane_law,
    law_settings,
    passivity_settings,
    standby_passivity_settings,
)
from haptic.common.config.scenario import load_scenario, max_block_damping
from haptic.common.model.work_area import work_area_from_config
from haptic.common.ros2.options import add_ros2_options, apply_ros2_options
from haptic.common.runtime.cli_options import RunOptions, add_run_options, run_options_from_args
from haptic.common.runtime.console import script_description
from haptic.common.runtime.failures import exit_on_link_error
from haptic.common.runtime.program_harness import add_networked_options, check_networked_options
from haptic.common.runtime.runner_config import place_other_threads
from haptic.common.runtime.warp_init import init_warp
from haptic.common.runtime.watchdog import DEFAULT_SYNC_TOLERANCE_M
from haptic.master.hardware.interface import HardwareError, create_hardware
from haptic.master.settings import MasterSettings, master_settings, with_work_area

# The node, the loop, the governor and the model's synthesis bring Warp, python-control and
# scipy: imported in main() after the parse, so --help and a bad flag answer at once.

#: Run length of the master-only mode when --duration is not given, s.
NO_LINK_DEFAULT_DURATION_S = 1.0
#: The rigs whose time advances only when the loop steps them (``--rig-time``).
SIMULATED_RIGS = ("sim", "sim-inproc", "model")


def build_parser() -> argparse.ArgumentParser:
    """The command line."""
    parser = argparse.ArgumentParser(prog="haptic-master", description=script_description(__doc__),
                                     allow_abbrev=False)
    add_run_options(parser)
    parser.add_argument("--rig", help="handle hardware by name: can, sim, sim-inproc or model "
                        "([master] rig)")
    parser.add_argument("--can-interface", metavar="NAME",
                        help="python-can interface of the rig's bus ([master.can] interface), "
                        "e.g. socketcan; unix_datagram (haptic-rig-sim's default) or "
                        "udp_multicast to reach a haptic-rig-sim started by hand")
    parser.add_argument("--can-channel", metavar="CHANNEL",
                        help="channel on that interface ([master.can] channel), e.g. can0")
    parser.add_argument("--operator", help="simulated operator spec ([master.sim] operator), "
                        "e.g. regulate:fx=3.6,onset=0.2")
    parser.add_argument("--rig-time", dest="rig_time", type=float, metavar="S",
                        help="simulated rigs (sim, sim-inproc, model): end the run once S s of "
                        "the rig's time (ticks x Ts) have been stepped, however long that takes "
                        "(a late tick stops a simulated rig's time, so --duration, wall time, "
                        "ends a loaded run early in its scenario)")
    add_preflight_options(parser)
    add_networked_options(parser, "slave", "write master_trace.npz (every --trace-every-th "
                          "tick) here at the end", DEFAULT_SYNC_TOLERANCE_M)
    add_ros2_options(parser)
    alone = parser.add_argument_group("master alone")
    alone.add_argument("--no-link", action="store_true",
                       help="run the master alone, no slave (default duration 1 s)")
    alone.add_argument("--no-pace", action="store_true",
                       help="with --no-link: run cycles back to back instead of every Ts "
                       "(simulated rig only: real drives need SYNC at Ts)")
    alone.add_argument("--json", action="store_true", help="with --no-link: print one JSON object")
    return parser


def _config(args: argparse.Namespace) -> dict:
    config = load_config(args.config)
    if args.rig is not None:
        config = override(config, "master.rig", args.rig)
    if args.operator is not None:
        config = override(config, "master.sim.operator", args.operator)
    for flag, key, value in (("--can-interface", "master.can.interface", args.can_interface),
                             ("--can-channel", "master.can.channel", args.can_channel)):
        if value is not None:
            try:
                config = override(config, key, value)
            except ConfigError as error:
                raise ConfigError(f"{flag} ({key})", str(error).removeprefix(f"{key}: ")) from None
    if args.k is not None:
        config = override(config, "model.ch1.gain_k", args.k)
    return apply_ros2_options(config, args)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit status: 0; 1 for a hardware error or a run that ended
    with the node latched in its safe state by a fault; 2 for a configuration error (one
    line); 3 when the stability analysis refuses the loop (see ``--allow-unstable``); 4 when the
    link cannot open (a port in use, an unreachable router; one line)."""
    args = build_parser().parse_args(argv)
    if args.no_link:
        return _main_alone(args)
    from haptic.common.model.teleop import model_from_config
    from haptic.master.node import MasterNode
    from haptic.master.program import MasterLoopOptions, run_linked_master
    from haptic.master.program_governor import start_governor, tdpa_standby

    init_warp()  # the node's kernels run on Warp's CPU device
    zenoh.init_log_from_env_or("error")
    with exit_on_config_error():
        for flag, given in (("--no-pace", args.no_pace), ("--json", args.json)):
            if given:
                raise ConfigError(flag, "only with --no-link (the linked run writes "
                                  "--json-summary FILE and is always paced)")
        config = _config(args)
        options = run_options_from_args(args, "master", config=config)
        check_networked_options(args)
        settings = master_settings(options.config)
        law_run = _law_run(args, options, settings) if lane_law(config) is not None else None
    if law_run is not None:
        with exit_on_link_error("haptic-master"):
            return law_run()
    with exit_on_config_error():
        model = model_from_config(options.config)
        if args.rig_time is not None:
            options = replace(options, max_steps=rig_time_steps(args.rig_time, settings.rig,
                                                                 model.sample_period_s))
        # the handle stops where the slave's tool does: the slave's scenario grid
        # bounds the handle's workspace too, through Ah1
        scenario = load_scenario(options.config["slave"]["scenario"])
        area = work_area_from_config(options.config, scenario.grid.x_range_m,
                                     scenario.grid.y_range_m)
        # paper mode with the governor's tdpa action: the layer on standby (master/tick.py)
        standby = tdpa_standby(options.config, args)
        node = MasterNode.from_model(model, with_work_area(settings.safety, area),
                                     standby_passivity_settings(options.config) if standby
                                     else passivity_settings(options.config), standby)
    with exit_on_config_error():
        clay = None
        if args.analysis_environment == "clay":
            clay = max_block_damping(scenario)
        analysis, refused = run_preflight(options.config, args, "haptic-master", side="master",
                                          clay_damping_N_s_per_m=clay)
    if refused is not None:
        return refused
    with exit_on_config_error():
        governor, refused = start_governor(options.config, args, model)
    if refused is not None:
        return refused
    with exit_on_config_error():
        hardware = create_hardware(settings.rig, options.config)
    loop_options = MasterLoopOptions(
        peer_wait_s=args.peer_wait, sync_tolerance_m=args.sync_tolerance,
        trace_every=args.trace_every,
        trace_path=None if args.out is None else str(Path(args.out) / "master_trace.npz"),
        record_path=args.record, record_every=args.record_every, display=args.display,
        governor=governor, allow_unstable=args.allow_unstable,
    )
    with exit_on_link_error("haptic-master"):
        return run_linked_master(options, model, node, hardware, loop_options,
                                 {"rig": settings.rig, "analysis": analysis.as_dict(),
                                  "work_area": area.describe()})


def _law_run(args: argparse.Namespace, options: RunOptions,
             settings: MasterSettings) -> Callable[[], int]:
    """The networked master in a lane-law mode (master/law_program.py), checked and built
    (raises ConfigError): the run, to call outside the configuration's error handling. The
    stability pre-flight is the paper scheme's and does not run (docs/architectures.md gives
    each law's theory)."""
    from haptic.master.law_program import LawMasterGuard, run_law_master
    from haptic.master.program import MasterLoopOptions

    config = options.config
    check_lane_law(config, args.record)
    control = str(lane_law(config))
    law = law_settings(config)
    if args.rig_time is not None:
        options = replace(options, max_steps=rig_time_steps(args.rig_time, settings.rig,
                                                             law.period_s))
    scenario = load_scenario(config["slave"]["scenario"])
    area = work_area_from_config(config, scenario.grid.x_range_m, scenario.grid.y_range_m)
    hardware = create_hardware(settings.rig, config)
    loop_options = MasterLoopOptions(
        peer_wait_s=args.peer_wait, trace_every=args.trace_every,
        trace_path=None if args.out is None else str(Path(args.out) / "master_trace.npz"))
    guard = LawMasterGuard(settings.safety, area)
    extra = {"rig": settings.rig, "work_area": area.describe(),
             **place_other_threads(options.runner)}
    return lambda: run_law_master(options, control, law, hardware, guard, loop_options, extra)


def rig_time_steps(rig_time_s: float, rig: str, period_s: float) -> int:
    """The ticks of ``--rig-time``: ``rig_time_s`` (s) stepped at ``period_s`` (s); only a
    simulated rig has a time of its own (ConfigError otherwise)."""
    if rig not in SIMULATED_RIGS:
        raise ConfigError("--rig-time", f"only with a simulated rig ({', '.join(SIMULATED_RIGS)}); "
                          f"rig {rig!r} runs on the wall clock: use --duration")
    if not (math.isfinite(rig_time_s) and rig_time_s > 0.0):
        raise ConfigError("--rig-time", f"must be a finite number > 0 s (got {rig_time_s:g})")
    return max(1, round(rig_time_s / period_s))


def _main_alone(args: argparse.Namespace) -> int:
    from haptic.common.model.teleop import model_from_config
    from haptic.master.node import MasterNode
    from haptic.master.standalone import run_master

    init_warp()
    duration = NO_LINK_DEFAULT_DURATION_S if args.duration is None else args.duration
    with exit_on_config_error():
        if args.rig_time is not None:
            raise ConfigError("--rig-time", "not with --no-link (use --duration)")
        config = _config(args)
        if not (duration > 0.0 and duration < float("inf")):
            raise ConfigError("--duration", f"must be a finite number > 0 (got {duration})")
        settings = master_settings(config)
        model = model_from_config(config)
        node = MasterNode.from_model(model, settings.safety, passivity_settings(config))
        hardware = create_hardware(settings.rig, config)
    cycles = max(1, round(duration / model.sample_period_s))
    try:
        with hardware:
            summary = run_master(hardware, node, cycles, pace=not args.no_pace)
    except HardwareError as error:
        print(f"hardware error: {error}", file=sys.stderr)
        return 1
    result = {
        "rig": settings.rig, "cycles": summary.cycles, "wall_time_s": summary.wall_time_s,
        "overruns": summary.overruns, "period_error_max_s": summary.period_error_max_s,
        "final_position_m": list(summary.final_position_m), "safe_state": summary.safe_state,
        "events": [{"step": e.step, "time_s": e.time_s, "kind": e.kind, "reason": e.reason,
                    "axis": e.axis} for e in summary.events],
        "hardware_faults": summary.hardware_faults[:20],
    }
    if args.json:
        print(json.dumps(result))
    else:
        print(f"rig {settings.rig}: {summary.cycles} cycles in {summary.wall_time_s:.3f} s, "
              f"{summary.overruns} overruns (period error max "
              f"{summary.period_error_max_s * 1e3:.2f} ms)")
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
