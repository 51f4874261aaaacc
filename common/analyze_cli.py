"""`haptic-analyze`: the paper's stability analysis of a configuration, with network delay."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from haptic.common.analysis.report import Analysis, AnalysisSettings, analyse
from haptic.common.cli_options import add_retired_delay_option
from haptic.common.config import ConfigError, exit_on_config_error, load_config, to_toml
from haptic.common.model import TeleopModel, model_from_config
from haptic.common.summary import json_safe
from haptic.common.synthesis import SynthesisError

#: Cells per side of the stability map written by --plot.
MAP_CELLS = 28


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface."""
    parser = argparse.ArgumentParser(
        prog="haptic-analyze",
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
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--plot", type=Path, metavar="DIR", help="write PNG plots into DIR")
    parser.add_argument("--print-config", action="store_true",
                        help="print the merged configuration (the defaults with --config over "
                        "them) as TOML and exit")
    return parser


def _settings(config: dict[str, Any], model: TeleopModel, sampled: bool) -> AnalysisSettings:
    section = config["analysis"]
    return AnalysisSettings(
        max_frequency_rad_s=section["max_frequency_rad_s"],
        max_delay_s=section["max_delay_s"],
        max_gain_k=section["max_gain_k"],
        sample_period_s=model.sample_period_s if sampled else None,
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


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit status (2 for a configuration error)."""
    args = build_parser().parse_args(argv)
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
        try:
            analysis = analyse(model, model.ch1_gain_k, delay_s, settings)
        except SynthesisError as error:
            raise ConfigError("model", str(error)) from None
    if args.json:
        print(json.dumps(json_safe(analysis.to_json())))
    else:
        print(format_text(analysis))
    if args.plot is not None:
        for path in write_plots(model, analysis, settings, args.plot):
            print(f"wrote {path}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
