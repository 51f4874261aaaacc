"""Delay-robustness evidence: the linear loop swept over round trips 0-1 s, jitter
0-20 ms and loss 0-20 % (independent and bursty) with the paper's scheme and with the TDPA
layer, every cell's figures, and the transparency cost against delay for both controls.

Usage: ``python bench/tdpa_sweep.py [--quick] [--json] [--out DIR] [--check]``. ``--out``
writes ``tdpa_sweep.json`` (every cell) and ``transparency.png``; ``--check`` exits 1 when a
tdpa cell up to 1 s round trip, 20 % loss and 10 ms jitter is unbounded or ends with a gap
over 2 mm (the passivity layer's drift target). Figures go to stdout; nothing here is asserted
on timing.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from haptic.common.config import load_config
from haptic.common.model.teleop import model_from_config
from haptic.lockstep.sweep import SweepSettings, run_sweep_grid

FULL = dict(gains=(3.0, 13.0, 19.0),
            delays=(0.0, 0.01, 0.02, 0.05, 0.1, 0.2, 0.35, 0.5, 0.75, 1.0),
            jitters=(0.0, 0.01, 0.02), losses=(0.0, 0.1, 0.2), duration=8.0)
QUICK = dict(gains=(13.0,), delays=(0.0, 0.02, 0.2, 1.0), jitters=(0.0, 0.01),
             losses=(0.0, 0.2), duration=6.0)
#: The target for tdpa: every cell bounded and a final gap <= 2 mm up to here.
TARGET = dict(round_trip_s=1.0 + 1e-3, jitter_s=0.01, loss=0.2, gap_m=0.002)


def run(quick: bool) -> dict:
    """Both controls over the grid, independent and bursty loss."""
    grid = QUICK if quick else FULL
    model = model_from_config(load_config(None))
    base = SweepSettings(gains_k=grid["gains"], delays_s=grid["delays"],
                         duration_s=grid["duration"])
    report: dict = {"grid": {key: list(value) if isinstance(value, tuple) else value
                             for key, value in grid.items()}}
    for control in ("paper", "tdpa"):
        summaries = []
        for bursty in (False, True):
            losses = tuple(loss for loss in grid["losses"] if not bursty or loss > 0.0)
            summary, _ = run_sweep_grid(model, replace(base, control=control, bursty=bursty),
                                        grid["jitters"], losses)
            summaries.append(summary)
        cells = [cell for summary in summaries for cell in summary["per_cell"]]
        report[control] = {
            "cells": len(cells), "bounded": sum(c["bounded"] for c in cells),
            "unbounded": sum(not c["bounded"] for c in cells),
            "agree": sum(s["agree"] for s in summaries),
            "wall_seconds": round(sum(s["wall_seconds"] for s in summaries), 1),
            "per_cell": cells,
        }
    report["tdpa_target_misses"] = target_misses(report["tdpa"]["per_cell"])
    return report


def target_misses(cells: list[dict]) -> list[dict]:
    """The tdpa cells inside the target's range that are unbounded or end with a gap > 2 mm."""
    inside = [c for c in cells if c["round_trip_s"] <= TARGET["round_trip_s"]
              and c["jitter_s"] <= TARGET["jitter_s"] and c["loss"] <= TARGET["loss"]]
    return [c for c in inside if not c["bounded"] or c["final_position_gap_m"] is None
            or c["final_position_gap_m"] > TARGET["gap_m"]]


def plot_transparency(report: dict, path: Path) -> None:
    """RMS force error and RMS position error against round trip, both controls, no loss or
    jitter, one line per gain; unbounded cells drawn hollow."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    styles = {"paper": "--", "tdpa": "-"}
    for control in ("paper", "tdpa"):
        cells = [c for c in report[control]["per_cell"]
                 if c["jitter_s"] == 0.0 and c["loss"] == 0.0 and not c["bursty"]]
        for gain in sorted({c["k"] for c in cells}):
            row = sorted((c for c in cells if c["k"] == gain), key=lambda c: c["round_trip_s"])
            delay_ms = np.array([c["round_trip_s"] * 1e3 for c in row])
            for ax, key, scale in ((axes[0], "rms_force_error_N", 1.0),
                                   (axes[1], "rms_position_error_m", 1e3)):
                values = np.array([np.nan if c[key] is None else c[key] * scale for c in row])
                bounded = np.array([c["bounded"] for c in row])
                line, = ax.plot(delay_ms[bounded], values[bounded], styles[control],
                                marker="o", label=f"{control}, k = {gain:g}")
                ax.plot(delay_ms[~bounded], np.minimum(values[~bounded], 1e3), "o",
                        mfc="none", color=line.get_color())
    axes[0].set_ylabel("RMS force error fh - ft/Ah2 (N)")
    axes[1].set_ylabel("RMS position error yh - yt (mm)")
    for ax in axes:
        ax.set_xlabel("round-trip delay (ms)")
        ax.set_yscale("log")
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle("Transparency cost against delay (linear loop, 1 N pulse; hollow: unbounded)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--out", type=Path)
    parser.add_argument("--check", action="store_true")
    args = parser.parse_args(argv)
    report = run(args.quick)
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "tdpa_sweep.json").write_text(json.dumps(report))
        plot_transparency(report, args.out / "transparency.png")
    brief = {control: {k: v for k, v in report[control].items() if k != "per_cell"}
             for control in ("paper", "tdpa")}
    brief["tdpa_target_misses"] = len(report["tdpa_target_misses"])
    print(json.dumps(report if args.json else brief))
    if args.check and report["tdpa_target_misses"]:
        print("tdpa sweep: cells miss the target", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
