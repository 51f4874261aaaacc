"""``haptic-slave``: the slave on the remote host: the slave node (Ch2/Ct2, the virtual tool,
the Warp clay) driven by the handle's messages over the Zenoh link, on the real-time runner
(the loop: slave_sim/program.py; its tick: slave_sim/tick.py).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import zenoh

from haptic.common.analysis.preflight import add_preflight_options, run_preflight
from haptic.common.config import ConfigError, exit_on_config_error, load_config, override
from haptic.common.config.control_schema import check_lane_law, lane_law, law_settings
from haptic.common.config.scenario import Scenario, load_scenario, max_block_damping
from haptic.common.ros2.options import (
    add_ros2_options,
    apply_ros2_options,
    require_ros2_protection,
)
from haptic.common.ros2.settings import Ros2Settings
from haptic.common.runtime.cli_options import add_run_options, run_options_from_args
from haptic.common.runtime.console import script_description
from haptic.common.runtime.failures import exit_on_link_error
from haptic.common.runtime.program_harness import add_networked_options, check_networked_options
from haptic.common.runtime.runner_config import place_other_threads
from haptic.common.runtime.warp_init import init_warp
from haptic.common.runtime.watchdog import DEFAULT_SYNC_TOLERANCE_M
from haptic.slave_sim.input_guard import InputGuardSettings
from haptic.slave_sim.plant_options import add_plant_options


def build_parser() -> argparse.ArgumentParser:
    """The command line."""
    parser = argparse.ArgumentParser(prog="haptic-slave", description=script_description(__doc__),
                                     allow_abbrev=False)
    add_run_options(parser)
    parser.add_argument("--scenario", help="scenario name or TOML path ([slave] scenario)")
    add_preflight_options(parser)
    group = add_networked_options(
        parser, "master", "write clay.npz, clay.png and slave_trace.npz here at the end",
        DEFAULT_SYNC_TOLERANCE_M)
    group.add_argument("--phase-margin", metavar="S", type=float,
                       help="start the spin before the tick this long after the master's "
                       "message arrives, s (slave.phase_lock.margin_s)")
    group.add_argument("--no-phase-lock", action="store_true",
                       help="let the loop tick free-running (slave.phase_lock.enabled = false)")
    add_ros2_options(parser)
    add_plant_options(parser)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit status: 0; 1 when no master came within --peer-wait;
    2 for a configuration error (one line); 3 when the stability analysis refuses the loop;
    4 when the link cannot open (a port in use, an unreachable router; one line)."""
    args = build_parser().parse_args(argv)
    # the node and the loop bring Warp, python-control and scipy: after the parse, so --help
    # and a bad flag answer at once
    from haptic.slave_sim.node import SlaveNode
    from haptic.slave_sim.program import phase_lock_from, run_slave

    zenoh.init_log_from_env_or("error")
    with exit_on_config_error():
        config = load_config(args.config)
        if args.scenario is not None:
            config = override(config, "slave.scenario", args.scenario)
        if args.k is not None:
            config = override(config, "model.ch1.gain_k", args.k)
        if args.phase_margin is not None:
            config = override(config, "slave.phase_lock.margin_s", args.phase_margin)
        if args.no_phase_lock:
            config = override(config, "slave.phase_lock.enabled", False)
        config = apply_ros2_options(config, args)
        options = run_options_from_args(args, "slave", config=config)
        check_networked_options(args)
        scenario = load_scenario(options.config["slave"]["scenario"])
        law_run = _law_run(args, options, scenario) if lane_law(config) is not None else None
    if law_run is not None:
        with exit_on_link_error("haptic-slave"):
            return law_run()
    with exit_on_config_error():
        phase_lock_from(options.config, options.config["model"]["sample_period_s"])
        InputGuardSettings.from_config(options.config)  # [slave.safety]'s cross-key checks
        if getattr(args, "plant", "virtual") == "ros2":
            require_ros2_protection(Ros2Settings.from_config(options.config).endpoint,
                                    options.config["link"]["security"]["insecure"])
    # before Warp's, the recorder's and Zenoh's threads start: they inherit these CPUs
    placement = place_other_threads(options.runner)
    with exit_on_config_error():
        analysis, refused = run_preflight(options.config, args, "haptic-slave", side="slave",
                                          clay_damping_N_s_per_m=max_block_damping(scenario))
    if refused is not None:
        return refused
    init_warp()  # after the placement: Warp's threads inherit it
    with exit_on_config_error():
        node = SlaveNode.from_config(options.config, scenario)
    from haptic.slave_sim.robot_plant import plant_for

    with exit_on_link_error("haptic-slave"), plant_for(args, options.config, node):
        return run_slave(node, options, args, {"scenario": scenario.name,
                                               "analysis": analysis.as_dict(), **placement})


def _law_run(args: argparse.Namespace, options: Any, scenario: Scenario) -> Callable[[], int]:
    """The networked slave in a lane-law mode (slave_sim/law_program.py), checked and built
    (raises ConfigError): the run, to call outside the configuration's error handling. The
    stability pre-flight is the paper scheme's and does not run."""
    from haptic.common.model.teleop import model_from_config
    from haptic.common.model.work_area import work_area_from_config
    from haptic.slave_sim.environment import make_environment
    from haptic.slave_sim.law_program import LawSlaveWorld, run_law_slave

    config = options.config
    check_lane_law(config, getattr(args, "record", None))
    if getattr(args, "plant", "virtual") != "virtual":
        raise ConfigError("--plant", f"only the virtual tool runs with [control] mode = "
                          f"\"{config['control']['mode']}\"")
    control = str(lane_law(config))
    law = law_settings(config)
    placement = place_other_threads(options.runner)  # before Warp's threads start
    init_warp()
    section = config["slave"]
    kind = scenario.environment if section["environment"] == "scenario" else (
        section["environment"])
    environment = make_environment(kind, model_from_config(config), scenario,
                                   section["clay_impl"], section["device"])
    area = work_area_from_config(config, scenario.grid.x_range_m, scenario.grid.y_range_m)
    world = LawSlaveWorld(environment, np.asarray(scenario.tool.start_position_m, float),
                          law.period_s,
                          (np.asarray(area.tool_low_m), np.asarray(area.tool_high_m)))
    extra = {"scenario": scenario.name, "work_area": area.describe(), **placement}
    return lambda: run_law_slave(options, control, law, world, args.peer_wait,
                                 args.trace_every, args.out, extra)


if __name__ == "__main__":
    sys.exit(main())
