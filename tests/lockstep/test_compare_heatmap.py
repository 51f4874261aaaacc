"""The comparison's heat maps: well-formed SVG, one cell per control x task and round trip x
loss, the colour growing with the value, a missing figure drawn as a marked cell."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from haptic.lockstep.compare_files import write_compare_files
from haptic.lockstep.compare_heatmap import (
    HEATMAP_METRICS,
    colour_at,
    heatmap_svg,
    heatmap_table,
)

SVG = "{http://www.w3.org/2000/svg}"
ROUND_TRIPS_S = (0.0, 0.05, 0.2)
LOSSES = (0.0, 0.2)


def _cell(control: str, task: str, round_trip: float, loss: float, model: str,
          value: float | None) -> dict[str, Any]:
    return {"control": control, "task": task, "round_trip_s": round_trip, "loss": loss,
            "loss_model": model, "jitter_s": 0.0, "bounded": value is not None and value != 6.5,
            "peak_force_N": value, "rms_position_error_m": value}


def _data() -> dict[str, Any]:
    """Two controls x two tasks x 3 delays x 2 losses, two loss models per lossy column; the
    value grows along the columns; the bursty cell at 200 ms, 20 % (6.5) is unbounded; one
    group (wave, wall, 200 ms, 20 %) has no figure."""
    cells = []
    for control in ("paper", "wave"):
        for task in ("free-sine", "wall"):
            for j, (round_trip, loss) in enumerate((rt, ls) for rt in ROUND_TRIPS_S
                                                   for ls in LOSSES):
                missing = (control, task, round_trip, loss) == ("wave", "wall", 0.2, 0.2)
                models = ("independent", "bursty") if loss else ("independent",)
                for k, model in enumerate(models):
                    value = None if missing else 1.0 + j + 0.5 * k
                    cells.append(_cell(control, task, round_trip, loss, model, value))
    return {"controls": ["paper", "wave"], "grid": {"tasks": ["free-sine", "wall", "clay-cut"]},
            "cells": cells}


def _cells(svg: str) -> list[ET.Element]:
    root = ET.fromstring(svg)
    assert root.tag == f"{SVG}svg"
    return [rect for rect in root.iter(f"{SVG}rect")
            if "cell" in rect.get("class", "").split()]


def _lightness(fill: str) -> float:
    red, green, blue = (int(fill[i:i + 2], 16) for i in (1, 3, 5))
    return 0.2126 * red + 0.7152 * green + 0.0722 * blue


@pytest.mark.parametrize("metric", HEATMAP_METRICS, ids=lambda metric: metric.key)
def test_every_metric_is_well_formed_with_one_cell_per_row_and_column(metric) -> None:
    table = heatmap_table(_data(), metric)
    assert table.rows == [("paper", "free-sine"), ("paper", "wall"), ("wave", "free-sine"),
                          ("wave", "wall")]
    assert len(table.columns) == len(ROUND_TRIPS_S) * len(LOSSES)
    cells = _cells(heatmap_svg(table, metric))
    assert len(cells) == len(table.rows) * len(table.columns)
    positions = {(cell.get("data-row"), cell.get("data-round-trip-s"), cell.get("data-loss"))
                 for cell in cells}
    assert len(positions) == len(cells)


def test_a_cell_is_the_median_of_the_bounded_cells_and_bounded_a_fraction() -> None:
    peak, bounded = HEATMAP_METRICS[1], HEATMAP_METRICS[0]
    assert peak.key == "peak_force_N" and bounded.key == "bounded"
    values = heatmap_table(_data(), peak).values
    # column 1: (0 ms, 20 %), values 2.0 (independent) and 2.5 (bursty), both bounded
    assert values[0, 1] == pytest.approx(2.25)
    # column 5: (200 ms, 20 %), 6.0 bounded and 6.5 not: the unbounded run is left out
    assert values[0, 5] == pytest.approx(6.0)
    fractions = heatmap_table(_data(), bounded).values
    assert fractions[0, 1] == 1.0 and fractions[0, 2] == 1.0 and fractions[0, 5] == 0.5
    assert fractions[3, 5] == 0.0  # the group without a figure is unbounded


def test_the_colour_grows_lighter_with_the_value() -> None:
    ramp = [_lightness(colour_at(k / 50)) for k in range(51)]
    assert all(b >= a for a, b in zip(ramp, ramp[1:], strict=False)) and ramp[-1] > ramp[0]
    for metric in (HEATMAP_METRICS[1], HEATMAP_METRICS[3]):
        cells = [cell for cell in _cells(heatmap_svg(heatmap_table(_data(), metric), metric))
                 if "missing" not in cell.get("class", "")]
        ordered = sorted(cells, key=lambda cell: float(cell.get("data-value")))
        lightness = [_lightness(cell.get("fill")) for cell in ordered]
        assert all(b >= a for a, b in zip(lightness, lightness[1:], strict=False))
        assert lightness[-1] > lightness[0]


def test_a_missing_figure_is_a_marked_cell() -> None:
    metric = HEATMAP_METRICS[1]
    table = heatmap_table(_data(), metric)
    assert math.isnan(table.values[3, 5]) and int(np.isnan(table.values).sum()) == 1
    svg = heatmap_svg(table, metric)
    missing = [cell for cell in _cells(svg) if "missing" in cell.get("class", "").split()]
    assert len(missing) == 1
    assert missing[0].get("data-row") == "wave / wall"
    assert float(missing[0].get("data-round-trip-s")) == 0.2
    assert missing[0].get("data-value") is None
    assert "n/a" in svg


def test_the_legend_states_the_units_and_the_files_are_written(tmp_path: Path) -> None:
    position = HEATMAP_METRICS[3]
    svg = heatmap_svg(heatmap_table(_data(), position), position)
    assert "mm (log scale)" in svg
    # the display unit is mm: the largest cell (6.0 m, the 6.5 m one unbounded) reads 6000
    assert max(float(cell.get("data-value", "nan")) for cell in _cells(svg)
               if cell.get("data-value")) == pytest.approx(6000.0)
    write_compare_files(_data(), tmp_path)
    for metric in HEATMAP_METRICS:
        ET.parse(tmp_path / f"heatmap_{metric.key}.svg")
