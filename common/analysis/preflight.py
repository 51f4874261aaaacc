"""Pre-flight stability check of ``haptic-master`` and ``haptic-slave``.

Before a program starts its loop it analyses the configured loop (gain k of Ch1, the model)
at the round-trip delay the link will impose, prints the verdict and the delay margin, and
refuses to start a loop the analysis calls unstable (exit status 3) unless
``--allow-unstable`` is given (the paper's k = 13 and 19 experiments at 20 ms need it).

The round-trip delay analysed is

    tau = master injection (delay_s + jitter_s) + slave injection (delay_s + jitter_s)
          + 2 x assumed network one-way delay (``--assumed-link-delay``, default 0.5 ms)

with this side's injection from its flags and the other side's from the configuration (the
two programs should share one configuration file), or from ``--peer-one-way-delay S`` when
given (the one-way delay plus jitter the peer's receiving link injects, for the analysis
only). 0.5 ms one way is above the loopback p99 measured in docs/link.md (tens to a few
hundred us); on two hosts pass the measured figure. Only the verdict and the delay margin
are computed (the continuous model by default, ``--sampled-analysis`` for the sampled-data
loop at Ts): no gain searches, so it takes tens of milliseconds; ``haptic-analyze`` gives the
full report.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass
from typing import Any, TextIO

from haptic.common.config import ConfigError, override
from haptic.common.model.delay_profile import parse_delay_profile

#: Exit status of a program that refuses to start an unstable loop.
EXIT_UNSTABLE = 3
#: Network one-way delay assumed on top of the injected delays, s.
DEFAULT_ASSUMED_LINK_DELAY_S = 0.0005


@dataclass(frozen=True)
class PreflightResult:
    """The verdict at ``round_trip_delay_s`` (s) for gain ``k``: ``stable``, the smallest
    per-axis delay margin (s; ``None`` = stable for every delay searched) and the margin left
    (margin - tau, s)."""

    k: float
    round_trip_delay_s: float
    sampled: bool
    stable: bool
    delay_margin_s: float | None
    axes: tuple[tuple[str, bool, float | None], ...]

    @property
    def margin_left_s(self) -> float | None:
        if self.delay_margin_s is None:
            return None
        return self.delay_margin_s - self.round_trip_delay_s

    def describe(self) -> str:
        """One line: model, k, tau, verdict, margin."""
        kind = "sampled-data loop at Ts" if self.sampled else "continuous model"
        if self.delay_margin_s is None:
            margin = "delay margin: none (stable for every delay searched)"
        elif self.delay_margin_s == 0.0:
            margin = "unstable even without delay"
        else:
            margin = (f"delay margin {self.delay_margin_s * 1e3:.2f} ms "
                      f"({self.margin_left_s * 1e3:+.2f} ms left)")
        verdict = "stable" if self.stable else "UNSTABLE"
        return (f"stability ({kind}): k = {self.k:g}, round-trip delay "
                f"{self.round_trip_delay_s * 1e3:.2f} ms: {verdict}; {margin}")

    def as_dict(self) -> dict[str, Any]:
        return {
            "k": self.k, "round_trip_delay_s": self.round_trip_delay_s, "sampled": self.sampled,
            "stable": self.stable, "delay_margin_s": self.delay_margin_s,
            "margin_left_s": self.margin_left_s,
        }


def add_preflight_options(parser: argparse.ArgumentParser) -> None:
    """``--k``, ``--allow-unstable``, ``--sampled-analysis``, ``--assumed-link-delay``."""
    group = parser.add_argument_group("pre-flight stability analysis")
    group.add_argument("--k", type=float, help="gain k of Ch1 ([model.ch1] gain_k); both "
                       "programs must use the same")
    group.add_argument("--allow-unstable", action="store_true",
                       help="start even when the analysis calls the loop unstable")
    group.add_argument("--analysis-environment", choices=("config", "clay"), default="config",
                       help="environment impedance Tt of the analysis: the configuration's "
                       "(default; the paper's 0.25 s^2 + 2 s + 6) or the clay's linearisation "
                       "B s with the scenario's largest block damping")
    group.add_argument("--sampled-analysis", action="store_true",
                       help="analyse the sampled-data loop at Ts instead of the continuous model")
    group.add_argument("--peer-one-way-delay", dest="peer_delay", metavar="S", type=float,
                       help="the one-way delay (plus jitter) the peer injects on this side's "
                       "messages, s, for the analysis (default: the peer's [link.<peer>."
                       "injection] in the configuration)")
    group.add_argument("--governor", action=argparse.BooleanOptionalAction, default=None,
                       help="the margin governor on the master ([governor] enabled; "
                       "docs/governor.md): the analysis then takes a delay profile's start, "
                       "the governor its peak")
    group.add_argument("--assumed-link-delay", metavar="S", type=float,
                       default=DEFAULT_ASSUMED_LINK_DELAY_S,
                       help="network one-way delay added to the injected delays, s "
                       f"(default {DEFAULT_ASSUMED_LINK_DELAY_S:g})")


def round_trip_delay_s(config: dict[str, Any], assumed_link_delay_s: float,
                       side: str | None = None, peer_delay_s: float | None = None,
                       profile: str = "max") -> float:
    """The injected delays (plus jitter bounds) of both directions plus twice the assumed
    network one-way delay, s. ``peer_delay_s`` (with ``side``, this program's side) replaces
    the other side's configured delay plus jitter. A side's delay profile
    (common/model/delay_profile.py) adds its largest delay (``profile="max"``) or its delay at the
    start (``"initial"``: a governed run, whose governor answers for the rest)."""
    total = 2.0 * assumed_link_delay_s
    for name in ("master", "slave"):
        if peer_delay_s is not None and side is not None and name != side:
            total += peer_delay_s
            continue
        injection = config["link"][name]["injection"]
        total += injection["delay_s"] + injection["jitter_s"]
        shape = parse_delay_profile(injection.get("delay_profile", ""))
        if shape is not None:
            total += shape.max_delay_s if profile == "max" else shape.initial_delay_s
    return total


def governor_enabled(config: dict[str, Any], args: argparse.Namespace) -> bool:
    """``--governor``/``--no-governor``, else ``[governor] enabled``."""
    flag = getattr(args, "governor", None)
    return bool(config["governor"]["enabled"] if flag is None else flag)


def with_damper_environment(config: dict[str, Any], damping_N_s_per_m: float
                            ) -> dict[str, Any]:
    """``config`` with Tt = B s on every axis (the clay's linearisation, B in N s/m)."""
    for axis in ("x", "y"):
        config = override(config, f"model.{axis}.environment_impedance_tt",
                           [float(damping_N_s_per_m), 0.0])
    return config


def check_stability(config: dict[str, Any], round_trip_s: float,
                    sampled: bool = False) -> PreflightResult:
    """The verdict and delay margin of every axis of the configured loop at ``round_trip_s``."""
    # here, not at the top: the programs add this module's options to their parsers, and a
    # --help should not wait for python-control and scipy
    from haptic.common.analysis.report import AnalysisSettings, axis_loop
    from haptic.common.analysis.stability import delay_margin, is_stable
    from haptic.common.config.control_schema import drift_parameters
    from haptic.common.model.synthesis import SynthesisError
    from haptic.common.model.teleop import model_from_config

    model = model_from_config(config)
    section = config["analysis"]
    settings = AnalysisSettings(
        max_frequency_rad_s=section["max_frequency_rad_s"],
        max_delay_s=section["max_delay_s"],
        max_gain_k=section["max_gain_k"],
        sample_period_s=model.sample_period_s if sampled else None,
        drift=drift_parameters(config) if "control" in config else None,
    )
    k = model.ch1_gain_k
    axes = []
    for axis in model.axes:
        try:
            loop = axis_loop(model, axis, k, settings)
        except SynthesisError:
            axes.append((axis.name, False, 0.0))
            continue
        stable = is_stable(loop, round_trip_s, settings.grid)
        margin = delay_margin(loop, settings.max_delay_s, settings.grid).delay_margin_s
        axes.append((axis.name, stable, margin))
    margins = [m for _, _, m in axes if m is not None]
    return PreflightResult(
        k=k, round_trip_delay_s=round_trip_s, sampled=sampled,
        stable=all(s for _, s, _ in axes), delay_margin_s=min(margins) if margins else None,
        axes=tuple(axes),
    )


def run_preflight(config: dict[str, Any], args: argparse.Namespace, program: str,
                  stream: TextIO | None = None, side: str | None = None,
                  clay_damping_N_s_per_m: float | None = None,
                  ) -> tuple[PreflightResult, int | None]:
    """Analyse, print the verdict line to ``stream`` (stderr) and return the result and
    ``None`` to go on, or :data:`EXIT_UNSTABLE` when the loop is unstable and
    ``--allow-unstable`` was not given (one line saying why is printed). ``side`` is the
    program's (for ``--peer-one-way-delay``); ``clay_damping_N_s_per_m`` the scenario's
    largest block damping (for ``--analysis-environment clay``). Raises
    :class:`ConfigError` for a bad flag."""
    stream = stream if stream is not None else sys.stderr
    assumed = getattr(args, "assumed_link_delay", DEFAULT_ASSUMED_LINK_DELAY_S)
    if not (math.isfinite(assumed) and assumed >= 0.0):
        raise ConfigError("--assumed-link-delay",
                          f"must be a finite number >= 0 s (got {assumed})")
    peer = getattr(args, "peer_delay", None)
    if peer is not None and not (math.isfinite(peer) and peer >= 0.0):
        raise ConfigError("--peer-one-way-delay", f"must be a finite number >= 0 s (got {peer})")
    tau = round_trip_delay_s(config, assumed, side, peer,
                             "initial" if governor_enabled(config, args) else "max")
    analysed = config
    environment = ""
    if getattr(args, "analysis_environment", "config") == "clay":
        if clay_damping_N_s_per_m is None:
            raise ConfigError("--analysis-environment", "no clay damping known for this run")
        analysed = with_damper_environment(config, clay_damping_N_s_per_m)
        environment = f", environment Tt = {clay_damping_N_s_per_m:g} s (clay)"
    result = check_stability(analysed, tau, bool(getattr(args, "sampled_analysis", False)))
    print(f"{program}: {result.describe()}{environment}", file=stream, flush=True)
    if result.stable:
        return result, None
    if config.get("control", {}).get("mode") == "tdpa":
        print(f"{program}: [control] mode = \"tdpa\": the passivity layer keeps the loop "
              "stable beyond this margin (docs/control.md)", file=stream, flush=True)
        return result, None
    if getattr(args, "allow_unstable", False):
        print(f"{program}: starting anyway (--allow-unstable)", file=stream, flush=True)
        return result, None
    print(f"{program}: refusing to start: the analysis calls the loop unstable at k = "
          f"{result.k:g} and a {tau * 1e3:.2f} ms round trip; pass --allow-unstable to run it",
          file=stream, flush=True)
    return result, EXIT_UNSTABLE
