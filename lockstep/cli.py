"""``haptic-sim``: the lockstep simulator from the command line.

- ``haptic-sim run``: one run of a scenario (traces saved as .npz and plotted);
- ``haptic-sim repro --out DIR``: the paper's section 4, report.md with figures and table;
- ``haptic-sim sweep``: the latency sweep (CSV, heat map, ``--json``), exit status 1 with
  ``--check`` when a cell disagrees with the analysis outside the band;
- ``haptic-sim compare``: every control architecture on the same tasks, network grid and
  metrics (docs/architectures.md), ``--quick`` for CI.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from haptic.common.analysis.preflight import (
    PreflightResult,
    check_stability,
    with_damper_environment,
)
from haptic.common.config import ConfigError, exit_on_config_error, load_config, override
from haptic.common.config.control_schema import (
    CONTROL_MODES,
    lane_law,
    law_settings,
    passivity_settings,
    standby_passivity_settings,
)
from haptic.common.config.scenario import load_scenario, max_block_damping
from haptic.common.model.delay_profile import DelayProfileError, parse_delay_profile
from haptic.common.runtime.cli_options import add_retired_delay_option
from haptic.common.runtime.console import quiet_on_closed_stdout, script_description
from haptic.common.runtime.warp_init import init_warp
from haptic.common.wire.injection import InjectionConfig
from haptic.lockstep.compare_grid import TASKS
from haptic.lockstep.environments import ENVIRONMENTS
from haptic.master.settings import master_settings
from haptic.master.simulated_rig.operator import parse_operator_spec

if TYPE_CHECKING:
    from haptic.lockstep.simulator import LockstepResult, LockstepSimulator

# The simulator, the model's synthesis and the governor bring Warp, python-control and scipy:
# each command imports them after the parse, so --help and a bad flag answer at once.


def _floats(text: str) -> tuple[float, ...]:
    """``"1,3,5"`` or ``"start:stop:step"`` (stop included) -> floats."""
    if ":" in text:
        start, stop, step = (float(part) for part in text.split(":"))
        count = int(math.floor((stop - start) / step + 1e-9)) + 1
        return tuple(start + step * i for i in range(count))
    return tuple(float(part) for part in text.split(",") if part.strip())


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface."""
    parser = argparse.ArgumentParser(prog="haptic-sim", description=script_description(__doc__),
                                     allow_abbrev=False)
    parser.add_argument("--config", type=Path, help="TOML configuration (default: the paper's)")
    sub = parser.add_subparsers(dest="command", required=True)

    _add_run_parser(sub)
    _add_repro_parser(sub)
    _add_sweep_parser(sub)
    _add_compare_parser(sub)
    return parser


def _add_run_parser(sub: argparse._SubParsersAction) -> None:
    """``haptic-sim run``'s options: the scenario, gain, delays, injection, governor, safety
    and control of one run."""
    run = sub.add_parser("run", help="one lockstep run: traces saved and plotted",
                         allow_abbrev=False)
    run.add_argument("--scenario", default=None, help="scenario name or .toml (default: config)")
    run.add_argument("--environment", choices=ENVIRONMENTS, default=None,
                     help="tool environment (default: the scenario's)")
    run.add_argument("--operator", default=None, help="operator spec (default: the "
                     "config's [lockstep] constant_rate_operator)")
    run.add_argument("--k", type=float, default=None, help="Ch1 gain k (default: config)")
    run.add_argument("--round-trip-delay", dest="delay", type=float, default=0.0, metavar="S",
                     help="round-trip delay tau, s (rounded to whole samples)")
    add_retired_delay_option(run)
    run.add_argument("--jitter", type=float, default=0.0, metavar="SECONDS",
                     help="jitter bound on each line, s (uniform)")
    run.add_argument("--loss", type=float, default=0.0, help="loss probability per message")
    run.add_argument("--delay-profile-to-slave", metavar="PROFILE", default="",
                     help="one-way delay over time on the handle line, on top of the round "
                     "trip, e.g. 'step 0:0.002 3:0.040' (docs/governor.md)")
    run.add_argument("--delay-profile-to-master", metavar="PROFILE", default="",
                     help="the same on the tool line")
    run.add_argument("--governor", action=argparse.BooleanOptionalAction, default=None,
                     help="run the margin governor (default: [governor] enabled)")
    run.add_argument("--duration", type=float, default=3.0, metavar="SECONDS")
    run.add_argument("--safety", choices=("config", "off"), default="config",
                     help="the shipped limits: the master's [master.safety] and the programs' "
                     "supervision (watchdog [link.watchdog], the slave's work area and "
                     "[slave.safety]), or off (transparent)")
    run.add_argument("--control", choices=CONTROL_MODES, default=None,
                     help="control scheme (default: the config's [control] mode); a lane law "
                     "runs the comparison's lane simulator on --task")
    run.add_argument("--task", choices=TASKS, default="clay-cut",
                     help="a lane law's task (the comparison's, docs/architectures.md; "
                     "default clay-cut)")
    run.add_argument("--out", type=Path, default=Path("haptic-sim-run"))
    run.add_argument("--json", action="store_true", help="print a JSON summary")


def _add_repro_parser(sub: argparse._SubParsersAction) -> None:
    """``haptic-sim repro``'s options."""
    repro = sub.add_parser("repro", help="reproduce the paper's section 4", allow_abbrev=False)
    repro.add_argument("--out", type=Path, default=Path("haptic-sim-repro"))
    repro.add_argument("--json", action="store_true", help="print the table as JSON")


def _add_sweep_parser(sub: argparse._SubParsersAction) -> None:
    """``haptic-sim sweep``'s options: the grid (gains, delays, jitter, loss), the control, the
    workers and device, the outputs."""
    sweep = sub.add_parser("sweep", help="latency sweep against the analysis",
                           allow_abbrev=False)
    sweep.add_argument("--mode", choices=("linear", "clay"), default="linear")
    sweep.add_argument("--quick", action="store_true",
                       help="the mode's quick grid (delays in 2 ms steps; linear: six gains, "
                       "2.5 s runs)")
    sweep.add_argument("--gains", type=_floats, default=None,
                       help="k values: a,b,c or start:stop:step (default: the mode's grid, "
                       "linear 1 to 30, clay 0.5 to 1.5)")
    sweep.add_argument("--delays", type=_floats, default=None,
                       help="round-trip delays, s: a,b,c or start:stop:step (default "
                       "0:0.02:0.001, --quick 0:0.02:0.002)")
    sweep.add_argument("--duration", type=float, default=None, metavar="SECONDS",
                       help="run length, s (default 3, --quick 2.5; clay: 2.25, the tool still "
                       "in the block)")
    sweep.add_argument("--jitter", type=_floats, default=(0.0,), metavar="SECONDS",
                       help="jitter bound on each line, s: one value or a list (a grid)")
    sweep.add_argument("--loss", type=_floats, default=(0.0,),
                       help="loss probability per message: one value or a list (a grid)")
    sweep.add_argument("--bursty", action="store_true",
                       help="lose messages in bursts (mean 10) at the same mean rate")
    sweep.add_argument("--control", choices=("paper", "tdpa"), default="paper",
                       help="the paper's scheme or the passivity layer (docs/control.md)")
    sweep.add_argument("--seed", type=int, default=0)
    sweep.add_argument("--workers", type=int, default=None, metavar="N",
                       help="processes to split the lanes between, whole gains each (the "
                       "same result, bit for bit; default: one per CPU, each with at least "
                       "100 lanes)")
    sweep.add_argument("--device", default="cpu",
                       help="Warp device of the clay lanes: cpu (default), cuda, cuda:N or "
                       "auto (a CUDA sweep runs in one process)")
    sweep.add_argument("--out", type=Path, default=None, help="write sweep.csv and "
                       "sweep.png here")
    sweep.add_argument("--json", action="store_true")
    sweep.add_argument("--check", action="store_true",
                       help="exit 1 when a cell disagrees outside the band")


def _add_compare_parser(sub: argparse._SubParsersAction) -> None:
    """``haptic-sim compare``'s options."""
    compare = sub.add_parser("compare", help="every control on the same tasks, network grid "
                             "and metrics (docs/architectures.md)", allow_abbrev=False)
    compare.add_argument("--quick", action="store_true",
                         help="the CI grid: 0, 50, 200 ms x no loss and 20 %% bursty loss x "
                         "no jitter x both tasks")
    compare.add_argument("--controls", type=_names, default=None, metavar="LIST",
                         help="comma-separated controls (default: paper,tdpa,wave,"
                         "four-channel,four-channel-tdpa,mmt)")
    compare.add_argument("--seed", type=int, default=0)
    compare.add_argument("--out", type=Path, default=None,
                         help="write compare.json, cells.csv and the heat maps here")
    compare.add_argument("--json", action="store_true", help="print the result as JSON")
    compare.add_argument("--real-link", action="store_true",
                         help="also run each control's real-link cells (200 ms and 1 s round "
                         "trip, 5 %% loss, over real Zenoh links in real time; the wall and "
                         "the sine, with --quick the wall only) beside the "
                         "lockstep's (JSON key real_link); exit 1 when one measured on target "
                         "disagrees (lockstep/compare_real_link.py)")


def _names(text: str) -> tuple[str, ...]:
    """``"a,b"`` -> ("a", "b")."""
    return tuple(part.strip() for part in text.split(",") if part.strip())


def _check_seconds(name: str, value: float) -> None:
    if not (math.isfinite(value) and value >= 0.0):
        raise ConfigError(name, f"must be a finite number >= 0 s (got {value})")


def _check_run_flags(args: argparse.Namespace) -> None:
    """The run's delays, jitter and duration (s) and loss probability are in range (raises
    :class:`ConfigError` naming the flag)."""
    for name, value in (("--round-trip-delay", args.delay), ("--jitter", args.jitter)):
        _check_seconds(name, value)
    if not args.duration > 0.0:
        raise ConfigError("--duration", "must be > 0 s")
    if not 0.0 <= args.loss <= 1.0:
        raise ConfigError("--loss", "must be in [0, 1]")


def _run_injections(args: argparse.Namespace) -> list[InjectionConfig | None]:
    """The handle line's and the tool line's injection (jitter, loss, delay profile), None
    for a line with none."""
    lines = []
    for flag, text in (("--delay-profile-to-slave", args.delay_profile_to_slave),
                       ("--delay-profile-to-master", args.delay_profile_to_master)):
        try:
            profile = parse_delay_profile(text)
        except DelayProfileError as error:
            raise ConfigError(flag, str(error)) from None
        injection = None
        if args.jitter > 0.0 or args.loss > 0.0 or profile is not None:
            injection = InjectionConfig(jitter_s=args.jitter, loss_probability=args.loss,
                                        delay_profile=profile)
        lines.append(injection)
    return lines


def _save_run_traces(out: Path, result: LockstepResult, title: str) -> None:
    """Lane 0's traces (and the governed gain, when governed) as ``out``/traces.npz and
    traces.png."""
    out.mkdir(parents=True, exist_ok=True)
    traces = {name: values[:, 0] for name, values in result.traces.items()}
    if result.governed is not None:
        traces["gain_k"] = result.governed.gains_k[:, 0]
    np.savez(out / "traces.npz", time_s=result.time_s, **traces)
    _plot_run(out / "traces.png", result.time_s, traces, title)


def _warn_if_unstable(analysis: PreflightResult, gain: float, scenario: Any,
                      environment: str) -> None:
    """Say on stderr when the sampled analysis finds the run's gain and delay unstable (the
    run still goes ahead: it shows what that does)."""
    if analysis.stable:
        return
    margin = analysis.delay_margin_s
    print(f"haptic-sim run: k = {gain:g} at {analysis.round_trip_delay_s * 1e3:.2f} ms round "
          "trip is UNSTABLE in the sampled analysis ("
          + ("unstable even without delay" if margin == 0.0 else
             f"delay margin {margin * 1e3:.2f} ms")
          + ("" if environment == "linear" else
             f"; the clay as its damping, {max_block_damping(scenario):g} N s/m")
          + "); the run shows what that does", file=sys.stderr)


def _command_run_law(args: argparse.Namespace, config: dict[str, Any]) -> dict[str, Any]:
    """``haptic-sim run`` in a lane-law mode (lockstep/law_run.py); the paper scheme's
    options (--k, --governor, delay profiles, --operator) do not apply."""
    from haptic.lockstep.law_run import run_law

    for flag, given in (("--k", args.k is not None), ("--governor", args.governor),
                        ("--operator", args.operator is not None),
                        ("--delay-profile-to-slave", bool(args.delay_profile_to_slave)),
                        ("--delay-profile-to-master", bool(args.delay_profile_to_master))):
        if given:
            raise ConfigError(flag, f"not with [control] mode = \"{lane_law(config)}\" "
                              "(the paper scheme's; the lane laws run the comparison's tasks)")
    return run_law(str(lane_law(config)), law_settings(config), args.task, args.delay,
                   args.loss, args.jitter, args.duration, int(config["lockstep"]["seed"]),
                   args.out)


def command_run(args: argparse.Namespace, config: dict[str, Any]) -> dict[str, Any]:
    """Run one scenario; write traces.npz and traces.png; return a summary."""
    from haptic.common.model.teleop import model_from_config
    from haptic.lockstep.simulator import (
        TRANSPARENT_SAFETY,
        TRANSPARENT_SUPERVISION,
        LockstepSimulator,
        LockstepSupervision,
    )
    from haptic.master.margin_governor import governor_for

    _check_run_flags(args)
    if args.control is not None:
        config["control"]["mode"] = args.control
    if lane_law(config) is not None:
        return _command_run_law(args, config)
    model = model_from_config(config)
    gain = model.ch1_gain_k if args.k is None else args.k
    model = model.with_gain(gain)
    scenario = load_scenario(args.scenario or config["slave"]["scenario"])
    environment = args.environment or scenario.environment
    operator = parse_operator_spec(args.operator or config["lockstep"]["constant_rate_operator"],
                                   "--operator")
    shipped = args.safety == "config"
    safety = master_settings(config).safety if shipped else TRANSPARENT_SAFETY
    supervision = (LockstepSupervision.from_config(config, scenario) if shipped
                   else TRANSPARENT_SUPERVISION)
    governed = config["governor"]["enabled"] if args.governor is None else args.governor
    # paper mode with the governor's tdpa action: the layer on standby (master/tick.py)
    standby = bool(governed and config["governor"]["action"] == "tdpa"
                   and config["control"]["mode"] == "paper")
    simulator = LockstepSimulator(model, scenario, operator, np.array([gain]), environment,
                                  safety, device="cpu", supervision=supervision,
                                  passivity=(standby_passivity_settings(config) if standby
                                             else passivity_settings(config)),
                                  passivity_standby=standby)
    to_slave, to_master = _run_injections(args)
    governors = [governor_for(model, config, tdpa_available=standby)] if governed else None
    delay_samples = int(round(args.delay / model.sample_period_s))
    delay_s = delay_samples * model.sample_period_s
    result = simulator.run(args.duration, delay_samples, to_slave=to_slave,
                           to_master=to_master, seed=int(config["lockstep"]["seed"]),
                           record_lanes=[0], governors=governors)
    out: Path = args.out
    _save_run_traces(out, result, f"{scenario.name}, k = {gain:g}, "
                     f"delay {delay_s * 1e3:.2f} ms")
    analysis = _analysis(config, gain, scenario, environment, delay_s)
    _warn_if_unstable(analysis, gain, scenario, environment)
    return {
        "scenario": scenario.name, "environment": environment, "k": gain,
        "round_trip_delay_s": delay_s,
        "analysis": analysis.as_dict(),
        "duration_s": result.steps * result.sample_period_s,
        "peak_handle_force_N": result.peak_handle_force_N[0].tolist(),
        "peak_tool_force_N": result.peak_tool_force_N[0].tolist(),
        "position_error_rms_m": result.position_error_rms_m[0].tolist(),
        "safety_events": result.safety_events, "out": str(out),
        "watchdog_trips": _watchdog_trips(simulator),
        **({} if governors is None else {**governors[0].summary(),
                                          "governor_events": result.governed.events}),
        "control": config["control"]["mode"],
        "final_position_gap_m": result.final_position_gap_m[0].tolist(),
    }


def run_text(summary: dict[str, Any]) -> str:
    """``haptic-sim run``'s summary as ``name: value`` lines for the terminal: the analysis
    as the programs' stability line, a table as ``key value`` pairs, a pair of axes as
    ``x, y``, a list of events one a line."""
    lines = []
    for key, value in summary.items():
        if key == "analysis":
            value = PreflightResult(
                k=value["k"], round_trip_delay_s=value["round_trip_delay_s"],
                sampled=value["sampled"], stable=value["stable"],
                delay_margin_s=value["delay_margin_s"], axes=()).describe()
        elif isinstance(value, dict):
            value = ", ".join(f"{name} {item}" for name, item in value.items()) or "none"
        elif isinstance(value, list) and all(isinstance(item, float) for item in value):
            value = ", ".join(f"{item:.6g}" for item in value)
        elif isinstance(value, list) and all(isinstance(item, dict) for item in value):
            value = "".join("\n  " + ", ".join(f"{name} {item}" for name, item in entry.items())
                            for entry in value) or "none"
        text = str(value)
        lines.append(f"{key}:{text}" if text.startswith("\n") else f"{key}: {text}")
    return "\n".join(lines)


def _analysis(config: dict[str, Any], gain: float, scenario: Any, environment: str,
              round_trip_s: float) -> PreflightResult:
    """The sampled analysis' verdict for the run: gain ``gain``, the constant round trip (s),
    and for the clay its linearisation (the largest block damping B s as Tt, as the programs'
    pre-flight has it), so a user sees whether what the run shows is what the analysis
    predicts (a simulator runs unstable combinations; the programs refuse them)."""
    analysed = override(config, "model.ch1.gain_k", float(gain))
    damping = max_block_damping(scenario) if environment != "linear" else None
    if damping is not None:
        analysed = with_damper_environment(analysed, damping)
    return check_stability(analysed, round_trip_s, sampled=True)


def _plot_run(path: Path, time_s: np.ndarray, traces: dict[str, np.ndarray], title: str
              ) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
    axes[0].plot(time_s, traces["handle_force_N"][:, 0], lw=0.8, label="fh_x")
    axes[0].plot(time_s, traces["tool_force_N"][:, 0], lw=0.8, label="ft_x")
    axes[0].set_ylabel("force (N)")
    axes[1].plot(time_s, traces["handle_position_m"][:, 0] * 100, lw=0.8, label="yh_x")
    axes[1].plot(time_s, traces["tool_position_m"][:, 0] * 100, lw=0.8, label="yt_x")
    axes[1].set_ylabel("position (cm)")
    axes[2].plot(time_s, traces["tool_velocity_m_s"][:, 0], lw=0.8, label="tool velocity x")
    axes[2].set_ylabel("m/s")
    axes[2].set_xlabel("time (s)")
    for ax in axes:
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    axes[0].set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


@quiet_on_closed_stdout
def main(argv: list[str] | None = None) -> int:
    """Entry point: 0 on success, 1 for a failed ``sweep --check``, 2 for a config error."""
    args = build_parser().parse_args(argv)
    init_warp()  # the nodes' kernels and the clay are Warp's
    with exit_on_config_error():
        config = load_config(args.config)
        if args.command == "run":
            summary = command_run(args, config)
            print(json.dumps(summary) if args.json else run_text(summary))
            return 0
        if args.command == "repro":
            from haptic.lockstep.repro import reproduce, write_report

            repro = reproduce(config)
            write_report(repro, args.out)
            if args.json:
                print(json.dumps(repro.to_json()))
            else:
                for row in repro.rows:
                    paper = "-" if row.paper is None else f"{row.paper:g}"
                    verdict = ("-" if row.within_tolerance is None
                               else "ok" if row.within_tolerance else "OUT")
                    print(f"{row.name:36s} paper {paper:>8s}  ours {row.ours:10.4g} {row.unit:4s}"
                          f" {verdict} ({row.tolerance}) [{row.basis}]")
                print(f"wrote {args.out / 'report.md'}", file=sys.stderr)
            return 0
        if args.command == "compare":
            return command_compare(args, config)
        return command_sweep(args, config)


def command_sweep(args: argparse.Namespace, config: dict[str, Any]) -> int:
    """Run the sweep, write its files, print its figures; 1 when --check fails."""
    from haptic.common.model.teleop import model_from_config
    from haptic.lockstep.sweep import (
        SweepSettings,
        auto_workers,
        default_settings,
        device_problem,
        plot_heatmap,
        run_sweep_grid,
        write_csv,
    )

    grid = default_settings(args.mode, args.quick)  # the grid shared with the benchmark
    gains = args.gains or grid.gains_k
    delays = args.delays or grid.delays_s
    for value in delays:
        _check_seconds("--delays", value)
    if any(not (math.isfinite(g) and g > 0.0) for g in gains):
        raise ConfigError("--gains", "every k must be a finite number > 0")
    if args.duration is None:
        args.duration = grid.duration_s
    if not args.duration >= 1.0:
        raise ConfigError("--duration", "must be >= 1 s (the verdict compares windows)")
    for value in args.jitter:
        _check_seconds("--jitter", value)
    if any(not 0.0 <= value < 1.0 for value in args.loss):
        raise ConfigError("--loss", "every loss probability must be in [0, 1)")
    if args.workers is not None and args.workers < 1:
        raise ConfigError("--workers", "must be >= 1")
    problem = device_problem(args.device, args.mode)
    if problem is not None:
        raise ConfigError("--device", problem)
    model = model_from_config(config)
    settings = SweepSettings(gains_k=tuple(gains), delays_s=tuple(delays), mode=args.mode,
                             duration_s=args.duration, reference_start_s=grid.reference_start_s,
                             seed=args.seed, control=args.control, bursty=args.bursty,
                             device=args.device)
    workers = args.workers or auto_workers(len(gains) * len(delays))
    summary, results = run_sweep_grid(model, settings, tuple(args.jitter), tuple(args.loss),
                                      workers)
    result = results[0]
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        write_csv(result, str(args.out / "sweep.csv"))
        plot_heatmap(result, str(args.out / "sweep.png"), model)
    if args.out is not None:
        (args.out / "per_cell.json").write_text(json.dumps(summary["per_cell"]))
    if args.json:
        print(json.dumps(summary))
    else:
        print("\n".join(f"{key}: {value}" for key, value in summary.items()
                        if key != "per_cell"))
    if args.check and args.control == "tdpa":
        if summary["unbounded"] > 0:
            print("sweep check failed: tdpa cells unbounded", file=sys.stderr)
            return 1
        return 0
    if args.check and summary["disagree_outside_band"] > 0:
        print("sweep check failed: cells disagree with the analysis outside the band",
              file=sys.stderr)
        return 1
    return 0


def command_compare(args: argparse.Namespace, config: dict[str, Any]) -> int:
    """Run the comparison, write its files, print its summary or its JSON."""
    from dataclasses import replace

    from haptic.common.model.teleop import model_from_config
    from haptic.lockstep.compare import run_compare, summary_text
    from haptic.lockstep.compare_grid import CONTROLS, CompareGrid
    from haptic.lockstep.compare_paper import PAPER_CONTROLS

    controls = args.controls or CONTROLS
    unknown = [name for name in controls if name not in CONTROLS]
    if unknown:
        raise ConfigError("--controls", f"unknown {', '.join(unknown)}; expected some of "
                          f"{', '.join(CONTROLS)}")
    grid = CompareGrid.quick(controls) if args.quick else CompareGrid(controls)
    grid = replace(grid, seed=args.seed)
    model = model_from_config(config) if set(controls) & set(PAPER_CONTROLS) else None
    result = run_compare(grid, model)
    data = result.to_json()
    real_link = None
    if args.real_link:
        from haptic.lockstep.compare_real_link import RealLinkSet, run_real_link_cells

        cells = (RealLinkSet.quick(controls, args.seed) if args.quick
                 else RealLinkSet(controls, seed=args.seed))
        real_link = data["real_link"] = run_real_link_cells(cells, model)
    if args.out is not None:
        from haptic.lockstep.compare_files import write_compare_files

        write_compare_files(data, args.out)
    print(json.dumps(data) if args.json else summary_text(result))
    if real_link is None:
        return 0
    if not args.json:
        from haptic.lockstep.compare_real_link import real_link_text

        print(real_link_text(real_link))
    return 1 if real_link["disagreements_on_target"] else 0


def _watchdog_trips(simulator: LockstepSimulator) -> dict[str, int]:
    """The run's watchdog trips on each side (0 without link outages)."""
    master, slave = simulator.last_ticks
    return {"master": master.supervisors[0].trips, "slave": slave.supervisors[0].trips}


if __name__ == "__main__":
    raise SystemExit(main())

