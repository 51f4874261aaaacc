"""One SVG heat map per metric of ``haptic-sim compare`` (docs/architectures.md).

Rows are control x task, columns round trip x loss; a cell shows the median of the metric
over the bounded grid cells that share its row and column (the loss models and the jitters:
an unbounded run's figures measure its divergence, not the control), and for ``bounded`` the
fraction of them that stayed bounded. Where none of them is bounded or has the figure (no
contact) the cell is marked. Plain SVG text, no plotting dependency: a
sequential colour scale (dark to light as the value grows), its legend with the units, and
each cell's value written in it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from xml.sax.saxutils import escape

import numpy as np


@dataclass(frozen=True)
class HeatmapMetric:
    """A cell key drawn as a heat map: ``key`` times ``display_scale`` in ``unit``; ``log``:
    a logarithmic colour scale (figures spanning decades)."""

    key: str
    title: str
    unit: str
    display_scale: float = 1.0
    log: bool = False


HEATMAP_METRICS = (
    HeatmapMetric("bounded", "bounded: fraction of the cells that stayed bounded", "fraction"),
    HeatmapMetric("peak_force_N", "peak force (operator or environment)", "N", log=True),
    HeatmapMetric("impact_overshoot_ratio", "impact overshoot of the wall force",
                  "ratio (peak - settled) / settled", log=True),
    HeatmapMetric("rms_position_error_m", "RMS position error handle - tool", "mm", 1e3,
                  log=True),
    HeatmapMetric("rms_force_error_N", "RMS force error operator - environment", "N", log=True),
    HeatmapMetric("final_position_gap_m", "final position gap handle - tool", "mm", 1e3,
                  log=True),
    HeatmapMetric("perceived_stiffness_ratio", "perceived stiffness / wall stiffness",
                  "ratio (1: transparent)"),
)

#: Viridis' anchors, dark to light: the colour's lightness grows with the value.
_ANCHORS = ((0x44, 0x01, 0x54), (0x3B, 0x52, 0x8B), (0x21, 0x91, 0x8C), (0x5E, 0xC9, 0x62),
            (0xFD, 0xE7, 0x25))
_MISSING_FILL = "#ffffff"
_CELL_W, _CELL_H = 46, 22
_LEFT, _TOP = 180, 84
_LEGEND_W, _LEGEND_H = 300, 12


@dataclass(frozen=True)
class HeatmapTable:
    """The heat map's values in display units: ``values[i, j]`` for ``rows[i]`` (control,
    task) and ``columns[j]`` (round trip s, loss); NaN where no figure exists."""

    rows: list[tuple[str, str]]
    columns: list[tuple[float, float]]
    values: np.ndarray


def heatmap_table(data: dict[str, Any], metric: HeatmapMetric) -> HeatmapTable:
    """The median of ``metric`` over the bounded cells of ``data``
    (:meth:`CompareResult.to_json`) per control x task and round trip x loss; for
    ``bounded``: the bounded fraction of all of them."""
    tasks = list(data["grid"]["tasks"])
    present = {(cell["control"], cell["task"]) for cell in data["cells"]}
    rows = [(control, task) for control in data["controls"] for task in tasks
            if (control, task) in present]
    columns = sorted({(cell["round_trip_s"], cell["loss"]) for cell in data["cells"]})
    groups: dict[tuple[int, int], list[float]] = {}
    row_index = {row: i for i, row in enumerate(rows)}
    column_index = {column: j for j, column in enumerate(columns)}
    for cell in data["cells"]:
        key = (row_index[(cell["control"], cell["task"])],
               column_index[(cell["round_trip_s"], cell["loss"])])
        value = cell.get(metric.key)
        kept = metric.key == "bounded" or cell["bounded"]
        figure = float(value) if value is not None and kept else math.nan
        groups.setdefault(key, []).append(figure)
    values = np.full((len(rows), len(columns)), math.nan)
    for (i, j), figures in groups.items():
        finite = [figure for figure in figures if math.isfinite(figure)]
        if finite:
            values[i, j] = float(np.median(finite)) * metric.display_scale
    return HeatmapTable(rows, columns, values)


def colour_at(fraction: float) -> str:
    """The scale's colour at ``fraction`` (0: lowest, 1: highest; clipped), as #rrggbb."""
    position = min(max(fraction, 0.0), 1.0) * (len(_ANCHORS) - 1)
    index = min(int(position), len(_ANCHORS) - 2)
    weight = position - index
    low, high = _ANCHORS[index], _ANCHORS[index + 1]
    return "#" + "".join(f"{round(a + weight * (b - a)):02x}" for a, b in zip(low, high,
                                                                              strict=True))


@dataclass(frozen=True)
class _Scale:
    """Maps a display value onto [0, 1]: linear, or logarithmic between positive bounds."""

    low: float
    high: float
    log: bool

    def fraction(self, value: float) -> float:
        if self.log:
            value = max(value, self.low)
            low, high, value = math.log10(self.low), math.log10(self.high), math.log10(value)
        else:
            low, high = self.low, self.high
        return 0.5 if high <= low else (value - low) / (high - low)

    def ticks(self) -> list[float]:
        if not self.log:
            return [float(t) for t in np.linspace(self.low, self.high, 5)]
        first, last = math.ceil(math.log10(self.low)), math.floor(math.log10(self.high))
        decades = [10.0 ** p for p in range(first, last + 1)]
        step = max(1, math.ceil(len(decades) / 6))
        return [self.low, *decades[::step], self.high]


def _scale(values: np.ndarray, metric: HeatmapMetric) -> _Scale:
    finite = values[np.isfinite(values)]
    if metric.key == "bounded":
        return _Scale(0.0, 1.0, False)
    if metric.log:
        positive = finite[finite > 0]
        if positive.size:
            return _Scale(float(positive.min()), float(positive.max()), True)
    if finite.size:
        return _Scale(float(finite.min()), float(finite.max()), False)
    return _Scale(0.0, 1.0, False)


def format_value(value: float) -> str:
    """A cell's value in at most 7 characters."""
    if value == 0.0:
        return "0"
    if abs(value) >= 1e4 or abs(value) < 1e-3:
        return f"{value:.1e}"
    return f"{value:.3g}"


def _text(x: float, y: float, body: str, size: int = 10, anchor: str = "middle",
          fill: str = "#000000") -> str:
    return (f'<text x="{x:.1f}" y="{y:.1f}" font-size="{size}" text-anchor="{anchor}" '
            f'fill="{fill}">{escape(body)}</text>')


def _cell(x: float, y: float, value: float, scale: _Scale, labels: str) -> list[str]:
    """One cell's rectangle and value; a missing figure is white, crossed and says n/a."""
    cx, cy = x + _CELL_W / 2, y + _CELL_H / 2 + 3
    if not math.isfinite(value):
        return [f'<rect class="cell missing" {labels} x="{x}" y="{y}" width="{_CELL_W}" '
                f'height="{_CELL_H}" fill="{_MISSING_FILL}" stroke="#999999"/>',
                f'<line x1="{x}" y1="{y}" x2="{x + _CELL_W}" y2="{y + _CELL_H}" '
                f'stroke="#bbbbbb"/>', _text(cx, cy, "n/a", 9, fill="#666666")]
    fraction = scale.fraction(value)
    fill = colour_at(fraction)
    ink = "#000000" if fraction > 0.55 else "#ffffff"
    return [f'<rect class="cell" {labels} data-value="{value!r}" x="{x}" y="{y}" '
            f'width="{_CELL_W}" height="{_CELL_H}" fill="{fill}" stroke="#ffffff"/>',
            _text(cx, cy, format_value(value), 9, fill=ink)]


def _legend(x: float, y: float, scale: _Scale, metric: HeatmapMetric) -> list[str]:
    """The colour bar with its ticks and units, and the n/a swatch."""
    parts = ['<defs><linearGradient id="scale" x1="0" x2="1" y1="0" y2="0">']
    parts += [f'<stop offset="{k / 20:.2f}" stop-color="{colour_at(k / 20)}"/>'
              for k in range(21)]
    parts += ["</linearGradient></defs>",
              f'<rect class="legend" x="{x}" y="{y}" width="{_LEGEND_W}" height="{_LEGEND_H}" '
              f'fill="url(#scale)"/>',
              _text(x, y - 4, f"{metric.unit}{' (log scale)' if scale.log else ''}", 10,
                    "start")]
    for tick in scale.ticks():
        tx = x + _LEGEND_W * min(max(scale.fraction(tick), 0.0), 1.0)
        parts += [f'<line x1="{tx:.1f}" y1="{y + _LEGEND_H}" x2="{tx:.1f}" '
                  f'y2="{y + _LEGEND_H + 4}" stroke="#000000"/>',
                  _text(tx, y + _LEGEND_H + 14, format_value(tick), 9)]
    sx = x + _LEGEND_W + 30
    parts += [f'<rect x="{sx}" y="{y}" width="{_CELL_W}" height="{_LEGEND_H}" '
              f'fill="{_MISSING_FILL}" stroke="#999999"/>',
              _text(sx + _CELL_W + 6, y + 10, "n/a: no bounded cell with this figure", 9,
                    "start")]
    return parts


def _headers(table: HeatmapTable) -> list[str]:
    """Round trips over their loss columns, the losses under them, the rows' labels."""
    parts = [_text(_LEFT - 8, _TOP - 22, "round trip ms", 10, "end"),
             _text(_LEFT - 8, _TOP - 6, "loss %", 10, "end")]
    round_trips = sorted({round_trip for round_trip, _ in table.columns})
    for round_trip in round_trips:
        indices = [j for j, (rt, _) in enumerate(table.columns) if rt == round_trip]
        x0, x1 = _LEFT + indices[0] * _CELL_W, _LEFT + (indices[-1] + 1) * _CELL_W
        parts += [_text((x0 + x1) / 2, _TOP - 22, f"{round_trip * 1e3:g}", 10),
                  f'<line x1="{x0 + 2}" y1="{_TOP - 18}" x2="{x1 - 2}" y2="{_TOP - 18}" '
                  f'stroke="#000000"/>']
    for j, (_, loss) in enumerate(table.columns):
        parts.append(_text(_LEFT + (j + 0.5) * _CELL_W, _TOP - 6, f"{loss * 100:g}", 9))
    for i, (control, task) in enumerate(table.rows):
        parts.append(_text(_LEFT - 8, _TOP + i * _CELL_H + _CELL_H / 2 + 4,
                           f"{control} / {task}", 10, "end"))
    return parts


def heatmap_svg(table: HeatmapTable, metric: HeatmapMetric) -> str:
    """The heat map of ``table`` as an SVG document (one ``rect.cell`` per table entry)."""
    scale = _scale(table.values, metric)
    width = max(_LEFT + len(table.columns) * _CELL_W + 20, _LEFT + _LEGEND_W + _CELL_W + 300)
    legend_y = _TOP + len(table.rows) * _CELL_H + 30
    height = legend_y + _LEGEND_H + 30
    statistic = "fraction bounded" if metric.key == "bounded" else "median of the bounded cells"
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
             f'viewBox="0 0 {width} {height}" font-family="sans-serif">',
             f'<rect width="{width}" height="{height}" fill="#ffffff"/>',
             _text(10, 20, f"{metric.title} ({metric.unit})", 14, "start"),
             _text(10, 38, f"{statistic} over the loss models and jitters of each round trip "
                   f"and loss; rows control / task", 10, "start")]
    parts += _headers(table)
    for i, (control, task) in enumerate(table.rows):
        for j, (round_trip, loss) in enumerate(table.columns):
            labels = (f'data-row="{escape(control)} / {escape(task)}" '
                      f'data-round-trip-s="{round_trip!r}" data-loss="{loss!r}"')
            parts += _cell(_LEFT + j * _CELL_W, _TOP + i * _CELL_H, float(table.values[i, j]),
                           scale, labels)
    parts += _legend(_LEFT, legend_y, scale, metric)
    parts.append("</svg>")
    return "\n".join(parts) + "\n"


def write_heatmaps(data: dict[str, Any], out: Path) -> list[Path]:
    """Write ``heatmap_<metric>.svg`` per metric into ``out`` (which exists); their paths."""
    paths = []
    for metric in HEATMAP_METRICS:
        path = out / f"heatmap_{metric.key}.svg"
        path.write_text(heatmap_svg(heatmap_table(data, metric), metric))
        paths.append(path)
    return paths


__all__ = ["HEATMAP_METRICS", "HeatmapMetric", "HeatmapTable", "colour_at", "format_value",
           "heatmap_svg", "heatmap_table", "write_heatmaps"]
