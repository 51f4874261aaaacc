"""`haptic-analyze`: the paper's stability analysis of a configuration, with network delay."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from haptic.common.config import ConfigError, exit_on_config_error, load_config, to_toml
from haptic.common.config.control_schema import drift_parameters
from haptic.common.runtime.cli_options import add_renamed_option, add_retired_delay_option
from haptic.common.runtime.console import quiet_on_closed_stdout
from haptic.common.runtime.summary import json_safe

if TYPE_CHECKING:
    from haptic.common.analysis.report import Analysis, AnalysisSettings
    from haptic.common.model.teleop import TeleopModel

# The analysis and the model's synthesis bring python-control and scipy: imported after the
# parse, so --help and a bad flag answer at once.

#: Cells per side of the stability map written by --out.
MAP_CELLS = 28
#: What Tt is: the configuration's, or the clay of each block (--environment clay).
ENVIRONMENTS = ("config", "clay")


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface."""
    parser = argparse.ArgumentParser(
        prog="haptic-analyze", allow_abbrev=False,
        description="Stability of the teleoperation loop under a round-trip network delay: "
        "eq 30 small-gain check, exact Nyquist verdict, delay margin and largest stable gains.",
    )
    parser.add_argument("--config", type=Path, help="TOML configuration (default: the paper's)")
    parser.add_argument("--k", type=float, help="gain k of Ch1 = k num/den (default: config)")
    parser.add_argument("--round-trip-delay", dest="delay", type=float, metavar="S",
                        help="round-trip network delay tau, s (default: config)")
    add_retired_delay_option(parser)
    parser.add_argument("--sampled-analysis", dest="sampled", action="store_true",
                        help="analyse the sampled loop at Ts (ZOH, one sample of compute delay)")
    parser.add_argument("--environment", choices=ENVIRONMENTS, default="config",
                        help="config: the model's Tt; clay: each block of the scenario's "
                        "workpiece, the clay linearised about steady cutting (docs/clay.md)")
    parser.add_argument("--scenario", metavar="NAME|PATH",
                        help="the workpiece for --environment clay (default: [slave] scenario)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--out", type=Path, metavar="DIR", help="write PNG plots into DIR")
    add_renamed_option(parser, "--plot", "--out DIR")
    parser.add_argument("--print-config", action="store_true",
                        help="print the merged configuration (the defaults with --config over "
                        "them) as TOML and exit")
    return parser


def _settings(config: dict[str, Any], model: TeleopModel, sampled: bool) -> AnalysisSettings:
    from haptic.common.analysis.report import AnalysisSettings

    section = config["analysis"]
    return AnalysisSettings(
        max_frequency_rad_s=section["max_frequency_rad_s"],
        max_delay_s=section["max_delay_s"],
        max_gain_k=section["max_gain_k"],
        sample_period_s=model.sample_period_s if sampled else None,
        drift=drift_parameters(config),
    )


def _ms(value: float | None) -> str:
    return "none (stable for every delay)" if value is None else f"{value * 1e3:.3f} ms"


def _gain(value: float | None) -> str:
    return "none" if value is None else f"{value:.4g}"


def format_text(analysis: Analysis) -> str:
    """The human-readable report."""
    mode = f"sampled at Ts = {analysis.sample_period_s * 1e3:.3g} ms" if analysis.sampled else (
        "continuous, exact delay")
    lines = [
        f"haptic-analyze: k = {analysis.k:g}, round-trip delay = {analysis.delay_s * 1e3:.3f} ms"
        f" ({mode})",
        f"  closed loop at this delay:  {'STABLE' if analysis.stable else 'UNSTABLE'}",
        f"  delay margin tau*:          {_ms(analysis.delay_margin_s)}",
        f"  largest stable k here:      {_gain(analysis.k_max)}",
        f"  largest k for every delay:  {_gain(analysis.k_max_delay_independent)}",
        f"  eq 30 (paper, sufficient):  "
        f"{'satisfied' if analysis.eq30_satisfied else 'not satisfied'}, worst "
        f"|Gh Ch1| / |Sh + (Ah1 Ah2^-1 Tt + Th)^-1| = {analysis.eq30_worst_ratio:.4g}",
    ]
    for axis in analysis.axes:
        note = " (ratio unbounded as w -> 0: Ch1 integrates)" if (
            axis.eq30_unbounded_at_low_frequency) else ""
        crossing = "" if axis.crossing_frequency_rad_s is None else (
            f" at {axis.crossing_frequency_rad_s:.4g} rad/s")
        k_max = "none" if axis.k_max is None else f"{axis.k_max:.4g}" + (
            "+ (search limit)" if axis.k_max_capped else "")
        lines.append(
            f"  axis {axis.axis}: {'stable' if axis.stable else 'UNSTABLE'}, "
            f"tau* {_ms(axis.delay_margin_s)}{crossing}, k_max {k_max}, max |B/A| "
            f"{axis.max_delayed_ratio:.4g}, eq 30 worst {axis.eq30_worst_ratio:.4g} at "
            f"{axis.eq30_worst_frequency_rad_s:.3g} rad/s{note}"
        )
    return "\n".join(lines)


def write_plots(model: TeleopModel, analysis: Analysis, settings: AnalysisSettings,
                directory: Path) -> list[Path]:
    """Nyquist, compensator Bode and stability-map PNGs into ``directory``."""
    from haptic.common.analysis.plots import (
        plot_compensator_bode,
        plot_nyquist,
        plot_stability_map,
    )
    from haptic.common.analysis.stability_map import stability_map

    directory.mkdir(parents=True, exist_ok=True)
    top_delay = max(3.0 * analysis.delay_s, 0.05)
    if analysis.delay_margin_s is not None:
        top_delay = max(top_delay, 2.0 * analysis.delay_margin_s)
    gains = np.geomspace(max(analysis.k / 20.0, 0.1), max(analysis.k * 5.0, 40.0), MAP_CELLS)
    delays = np.linspace(0.0, min(top_delay, settings.max_delay_s), MAP_CELLS)
    result = stability_map(model, gains, delays, settings)
    return [
        plot_nyquist(model, analysis, settings, directory / "nyquist.png"),
        plot_compensator_bode(model, analysis.k, directory / "compensators_bode.png"),
        plot_stability_map(result, analysis, directory / "stability_map.png"),
    ]


@quiet_on_closed_stdout
def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit status (2 for a configuration error)."""
    args = build_parser().parse_args(argv)
    from haptic.common.analysis.report import analyse
    from haptic.common.model.synthesis import SynthesisError
    from haptic.common.model.teleop import model_from_config

    with exit_on_config_error():
        config = load_config(args.config)
        if args.print_config:
            print(to_toml(config), end="")
            return 0
        model = model_from_config(config)
        if args.k is not None:
            model = model.with_gain(args.k)
        delay_s = config["analysis"]["round_trip_delay_s"] if args.delay is None else args.delay
        if not (math.isfinite(delay_s) and delay_s >= 0.0):
            raise ConfigError("--round-trip-delay",
                              f"must be a finite number >= 0 s (got {delay_s})")
        settings = _settings(config, model, args.sampled)
        if args.environment == "clay":
            return _clay(args, config, model, delay_s, settings)
        if args.scenario is not None:
            raise ConfigError("--scenario", "only with --environment clay")
        try:
            analysis = analyse(model, model.ch1_gain_k, delay_s, settings)
        except SynthesisError as error:
            raise ConfigError("model", str(error)) from None
    if args.json:
        report = analysis.to_json()
        report["drift_coupling"] = settings.drift  # (kp N/m, wc rad/s) or None: not in loop
        print(json.dumps(json_safe(report)))
    else:
        print(format_text(analysis))
        if settings.drift is not None:
            print(f"with the paper mode's drift coupling kp = {settings.drift[0]:g} N/m, "
                  f"wc = {settings.drift[1]:g} rad/s in the loop")
    if args.out is not None:
        for path in write_plots(model, analysis, settings, args.out):
            print(f"wrote {path}", file=sys.stderr)
    return 0


def _clay(args: argparse.Namespace, config: dict[str, Any], model: TeleopModel,
          delay_s: float, settings: AnalysisSettings) -> int:
    """--environment clay: the loop cutting each block of the workpiece."""
    from haptic.common.analysis.clay import clay_block_stability, to_json, workpiece_bounds
    from haptic.common.config.scenario import load_scenario
    from haptic.common.model.clay_contact import (
        COUPLING_DAMPING_N_S_PER_M,
        COUPLING_STIFFNESS_N_PER_M,
    )
    from haptic.common.model.synthesis import SynthesisError

    if args.out is not None:
        raise ConfigError("--out", "not with --environment clay")
    scenario = load_scenario(args.scenario or config["slave"]["scenario"])
    blocks = [(block.name, block.damping_N_s_per_m) for block in scenario.blocks]
    try:
        result = clay_block_stability(model, blocks, model.ch1_gain_k, delay_s, settings)
    except SynthesisError as error:
        raise ConfigError("model", str(error)) from None
    bounds = workpiece_bounds(result)
    if args.json:
        print(json.dumps(json_safe({
            "environment": "clay", "scenario": scenario.name, "k": model.ch1_gain_k,
            "delay_s": delay_s, "sampled": settings.sample_period_s is not None,
            "coupling_stiffness_N_per_m": COUPLING_STIFFNESS_N_PER_M,
            "coupling_damping_N_s_per_m": COUPLING_DAMPING_N_S_PER_M,
            "blocks": to_json(result), "workpiece": bounds})))
        return 0
    mode = (f"sampled at Ts = {model.sample_period_s * 1e3:.3g} ms"
            if settings.sample_period_s is not None else "continuous, exact delay")
    def k_max(value: float | None) -> str:
        capped = value is not None and value >= settings.max_gain_k
        return _gain(value) + ("+" if capped else "")

    lines = [f"haptic-analyze: clay of {scenario.name!r}, each block linearised about steady "
             f"cutting (Tt = B s (K + b s)/(K + (B + b) s), K = {COUPLING_STIFFNESS_N_PER_M:g} "
             f"N/m, b = {COUPLING_DAMPING_N_S_PER_M:g} N s/m); k = {model.ch1_gain_k:g}, "
             f"round-trip delay {delay_s * 1e3:.3f} ms ({mode})",
             f"  {'block':>8} {'B N s/m':>8} {'here':>9} {'delay margin':>30} "
             f"{'k_max here':>10} {'k_max all delays':>16}"]
    for block in result:
        lines.append(f"  {block.block:>8} {block.damping_N_s_per_m:8.1f} "
                     f"{'stable' if block.stable else 'UNSTABLE':>9} "
                     f"{_ms(block.delay_margin_s):>30} {k_max(block.k_max):>10} "
                     f"{_gain(block.k_max_delay_independent):>16}")
    lines.append(f"  workpiece: {'STABLE' if bounds['stable'] else 'UNSTABLE'} at this k and "
                 f"delay; delay margin {_ms(bounds['delay_margin_s'])}; largest stable k here "
                 f"{k_max(bounds['k_max'])}, for every delay "
                 f"{_gain(bounds['k_max_delay_independent'])}")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
