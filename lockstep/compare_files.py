"""The files ``haptic-sim compare --out DIR`` writes: the whole result as compare.json, one
row per cell as cells.csv (the same keys; empty where a figure does not exist) and one SVG
heat map per metric, heatmap_<metric>.svg (lockstep/compare_heatmap.py)."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

from haptic.lockstep.compare_heatmap import write_heatmaps

CELL_COLUMNS = ("control", "task", "round_trip_s", "loss", "loss_model", "jitter_s", "bounded",
                "predicted_bounded", "peak_force_N", "impact_overshoot_ratio",
                "rms_position_error_m", "rms_force_error_N", "final_position_gap_m",
                "perceived_stiffness_ratio", "cut_force_N", "cut_speed_m_per_s")


def write_compare_files(data: dict[str, Any], out: Path) -> None:
    """Write ``data`` (:meth:`CompareResult.to_json`) into ``out`` (created if missing)."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "compare.json").write_text(json.dumps(data, indent=1))
    with (out / "cells.csv").open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=CELL_COLUMNS, extrasaction="ignore")
        writer.writeheader()
        for cell in data["cells"]:
            writer.writerow({key: "" if cell.get(key) is None else cell[key]
                             for key in CELL_COLUMNS})
    write_heatmaps(data, out)


__all__ = ["CELL_COLUMNS", "write_compare_files"]
