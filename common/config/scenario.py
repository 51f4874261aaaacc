"""Slave scenarios: the workpiece (blocks of clay), the work area grid, the tool and the
environment, read from TOML files and validated with the configuration machinery.

A scenario file has these tables (units in the key names; see the shipped files in
``common/config/scenarios/``)::

    [scenario]   name, description, environment ("clay" or "linear")
    [grid]       x_range_m, y_range_m, cells_x, cells_y
    [tool]       radius_m, bottom_height_m, reference_depth_m, edge_width_m,
                 max_speed_m_s, start_position_m
    [operator]   handle_force_N (the constant force of the paper's experiments, for runners)
    [workpiece]  blocks = ["name", ...]  (the blocks that make up the workpiece, in order)
    [blocks.NAME] shape = "box" | "disc", height_m, damping_N_s_per_m, and for a box
                 x_range_m, y_range_m; for a disc center_m, radius_m

Every error is a :class:`~haptic.common.config.ConfigError` naming the dotted key or block:
an unknown block, overlapping blocks, a negative damping, a block outside the grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from haptic.common.config import (
    ConfigError,
    Field,
    Schema,
    parse_toml,
    read_config_text,
    validate_table,
)

ENVIRONMENT_KINDS = ("clay", "linear")
BLOCK_SHAPES = ("box", "disc")
SCENARIO_NAMES = ("constant-rate", "variable-rate", "arbitrary")


def _range(values: list[float]) -> str | None:
    if len(values) != 2:
        return "must be a list of two numbers [low, high]"
    if not values[0] < values[1]:
        return f"low end must be below the high end (got {values})"
    return None


def _pair(values: list[float]) -> str | None:
    return None if len(values) == 2 else "must be a list of two numbers [x, y]"


#: The most height-field cells along one axis (16384 x 16384 float64 heights: 2 GiB).
MAX_GRID_CELLS = 16384
_POSITIVE = {"minimum": 0.0, "exclusive_minimum": True}

SCENARIO_SCHEMA: Schema = {
    "scenario": {
        "name": Field("str", "Scenario name."),
        "description": Field("str", "One line saying what the scenario reproduces."),
        "environment": Field(
            "str", "Environment model of the tool: clay (Warp height field) or linear "
            "(ft = Tt yt with the model's environment impedance).", choices=ENVIRONMENT_KINDS,
        ),
    },
    "grid": {
        "x_range_m": Field("float_list", "Work area along x (cutting direction), m.",
                           check=_range),
        "y_range_m": Field("float_list", "Work area along y, m.", check=_range),
        "cells_x": Field("int", "Height-field cells along x (at most 16384).", minimum=1,
                         maximum=MAX_GRID_CELLS),
        "cells_y": Field("int", "Height-field cells along y (at most 16384).", minimum=1,
                         maximum=MAX_GRID_CELLS),
    },
    "tool": {
        "radius_m": Field("float", "Flat-end cylindrical tool radius, m.", **_POSITIVE),
        "bottom_height_m": Field("float", "Height of the tool's flat bottom above the base, m.",
                                 minimum=0.0),
        "reference_depth_m": Field(
            "float", "Depth of cut at which the engagement is 1 (force = B v), m.", **_POSITIVE
        ),
        "edge_width_m": Field(
            "float", "Radial width of the tool's bottom chamfer, m: spreads each cell's removal "
            "over this much travel (smooth force).", **_POSITIVE,
        ),
        "max_speed_m_s": Field(
            "float", "Largest tool speed cut without limit, m/s; sets the per-step removal cap "
            "of a cell (smooth onset inside the clay).", **_POSITIVE,
        ),
        "start_position_m": Field("float_list", "Tool start (x, y), m.", check=_pair),
    },
    "operator": {
        "handle_force_N": Field(
            "float_list", "Constant handle force (x, y) of the paper's experiment, N; used by "
            "runners that stand in for the operator.", check=_pair,
        ),
    },
}
# ``[workpiece]`` (a list of block names) and ``[blocks.NAME]`` (tables with free names and a
# shape-dependent schema) are checked by hand below with the same error style.

_BLOCK_COMMON: dict[str, Field] = {
    "shape": Field("str", "Block outline in x-y.", choices=BLOCK_SHAPES),
    "height_m": Field("float", "Clay height above the base, m.", **_POSITIVE),
    "damping_N_s_per_m": Field(
        "float", "Viscous damping B of the block's clay, N s/m (force B v at full engagement).",
        minimum=0.0,
    ),
}
BOX_SCHEMA: Schema = {
    **_BLOCK_COMMON,
    "x_range_m": Field("float_list", "Block extent along x, m.", check=_range),
    "y_range_m": Field("float_list", "Block extent along y, m.", check=_range),
}
DISC_SCHEMA: Schema = {
    **_BLOCK_COMMON,
    "center_m": Field("float_list", "Disc centre (x, y), m.", check=_pair),
    "radius_m": Field("float", "Disc radius, m.", **_POSITIVE),
}


@dataclass(frozen=True)
class GridSpec:
    """The work area and its height-field cells (cell size = range / cells, m)."""

    x_range_m: tuple[float, float]
    y_range_m: tuple[float, float]
    cells_x: int
    cells_y: int

    @property
    def cell_size_x_m(self) -> float:
        """Cell size along x, m."""
        return (self.x_range_m[1] - self.x_range_m[0]) / self.cells_x

    @property
    def cell_size_y_m(self) -> float:
        """Cell size along y, m."""
        return (self.y_range_m[1] - self.y_range_m[0]) / self.cells_y


@dataclass(frozen=True)
class ToolSpec:
    """The virtual cutting tool: a flat-end cylinder with a small bottom chamfer (m, m/s)."""

    radius_m: float
    bottom_height_m: float
    reference_depth_m: float
    edge_width_m: float
    max_speed_m_s: float
    start_position_m: tuple[float, float]


@dataclass(frozen=True)
class BlockSpec:
    """One block of clay: outline (box ranges or disc centre/radius, m), height m, damping."""

    name: str
    shape: str
    height_m: float
    damping_N_s_per_m: float
    x_range_m: tuple[float, float] = (0.0, 0.0)
    y_range_m: tuple[float, float] = (0.0, 0.0)
    center_m: tuple[float, float] = (0.0, 0.0)
    radius_m: float = 0.0

    def bounds_m(self) -> tuple[float, float, float, float]:
        """(x_min, x_max, y_min, y_max) of the outline, m."""
        if self.shape == "box":
            return (*self.x_range_m, *self.y_range_m)
        cx, cy = self.center_m
        r = self.radius_m
        return (cx - r, cx + r, cy - r, cy + r)


@dataclass(frozen=True)
class Scenario:
    """A validated slave scenario."""

    name: str
    description: str
    environment: str
    grid: GridSpec
    tool: ToolSpec
    handle_force_N: tuple[float, float]
    blocks: tuple[BlockSpec, ...]
    source: str

    def with_grid(self, cells_x: int, cells_y: int) -> Scenario:
        """A copy on another grid resolution over the same work area."""
        from dataclasses import replace

        return replace(self, grid=replace(self.grid, cells_x=cells_x, cells_y=cells_y))

    def with_environment(self, environment: str) -> Scenario:
        """A copy with another environment kind ("clay" or "linear")."""
        from dataclasses import replace

        if environment not in ENVIRONMENT_KINDS:
            kinds = ", ".join(ENVIRONMENT_KINDS)
            raise ConfigError("scenario.environment",
                              f"must be one of {kinds} (got {environment!r})")
        return replace(self, environment=environment)


def _validate_workpiece(table: Any) -> list[str]:
    if not isinstance(table, dict):
        raise ConfigError("workpiece", "must be a table")
    for key in table:
        if key != "blocks":
            raise ConfigError(f"workpiece.{key}", "unknown key")
    if "blocks" not in table:
        raise ConfigError("workpiece.blocks", "missing key")
    names = table["blocks"]
    if not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
        raise ConfigError("workpiece.blocks",
                          f"must be a non-empty list of block names (got {names!r})")
    seen: set[str] = set()
    for name in names:
        if name in seen:
            raise ConfigError("workpiece.blocks", f"block {name!r} is listed twice")
        seen.add(name)
    return names


def _validate_block(name: str, table: Any) -> BlockSpec:
    key = f"blocks.{name}"
    if not isinstance(table, dict):
        raise ConfigError(key, "must be a table")
    shape = table.get("shape")
    if shape not in BLOCK_SHAPES:
        shapes = ", ".join(BLOCK_SHAPES)
        raise ConfigError(f"{key}.shape", f"must be one of {shapes} (got {shape!r})")
    damping = table.get("damping_N_s_per_m")
    if isinstance(damping, int | float) and not isinstance(damping, bool) and damping < 0:
        raise ConfigError(f"{key}.damping_N_s_per_m",
                          f"block {name!r} has a negative damping ({damping:g} N s/m); "
                          "must be >= 0")
    checked = validate_table(table, BOX_SCHEMA if shape == "box" else DISC_SCHEMA, {}, key)
    if shape == "box":
        return BlockSpec(name, shape, checked["height_m"], checked["damping_N_s_per_m"],
                         x_range_m=tuple(checked["x_range_m"]),
                         y_range_m=tuple(checked["y_range_m"]))
    return BlockSpec(name, shape, checked["height_m"], checked["damping_N_s_per_m"],
                     center_m=tuple(checked["center_m"]), radius_m=checked["radius_m"])


def _overlap(a: BlockSpec, b: BlockSpec) -> bool:
    """True when the outlines of two blocks share an area (touching edges do not count)."""
    ax0, ax1, ay0, ay1 = a.bounds_m()
    bx0, bx1, by0, by1 = b.bounds_m()
    if ax1 <= bx0 or bx1 <= ax0 or ay1 <= by0 or by1 <= ay0:
        return False
    if a.shape == "box" and b.shape == "box":
        return True
    if a.shape == "disc" and b.shape == "disc":
        return math.dist(a.center_m, b.center_m) < a.radius_m + b.radius_m
    box, disc = (a, b) if a.shape == "box" else (b, a)
    cx, cy = disc.center_m
    nearest_x = min(max(cx, box.x_range_m[0]), box.x_range_m[1])
    nearest_y = min(max(cy, box.y_range_m[0]), box.y_range_m[1])
    return math.hypot(cx - nearest_x, cy - nearest_y) < disc.radius_m


def scenario_from_table(table: dict[str, Any], source: str) -> Scenario:
    """Validate a parsed scenario file; raises :class:`ConfigError` naming the problem."""
    if not isinstance(table, dict):
        raise ConfigError("", f"{source}: a scenario must be a TOML table")
    known = set(SCENARIO_SCHEMA) | {"workpiece", "blocks"}
    for key in table:
        if key not in known:
            raise ConfigError(key, "unknown table")
    main = validate_table({k: v for k, v in table.items() if k in SCENARIO_SCHEMA},
                          SCENARIO_SCHEMA, {})
    names = _validate_workpiece(table.get("workpiece"))
    defined = table.get("blocks", {})
    if not isinstance(defined, dict):
        raise ConfigError("blocks", "must be a table of [blocks.NAME] tables")
    for name in names:
        if name not in defined:
            raise ConfigError("workpiece.blocks",
                              f"unknown block {name!r}: no [blocks.{name}] table is defined")
    for name in defined:
        if name not in names:
            raise ConfigError(f"blocks.{name}",
                              f"block {name!r} is defined but not listed in workpiece.blocks")
    blocks = tuple(_validate_block(name, defined[name]) for name in names)
    grid = GridSpec(tuple(main["grid"]["x_range_m"]), tuple(main["grid"]["y_range_m"]),
                    main["grid"]["cells_x"], main["grid"]["cells_y"])
    gx0, gx1 = grid.x_range_m
    gy0, gy1 = grid.y_range_m
    for block in blocks:
        x0, x1, y0, y1 = block.bounds_m()
        if x0 < gx0 or x1 > gx1 or y0 < gy0 or y1 > gy1:
            raise ConfigError(
                f"blocks.{block.name}",
                f"block {block.name!r} (x {x0:g}..{x1:g} m, y {y0:g}..{y1:g} m) lies outside "
                f"the grid (x {gx0:g}..{gx1:g} m, y {gy0:g}..{gy1:g} m)",
            )
    for i, a in enumerate(blocks):
        for b in blocks[i + 1:]:
            if _overlap(a, b):
                raise ConfigError(f"blocks.{b.name}",
                                  f"blocks {a.name!r} and {b.name!r} overlap")
    tool_table = main["tool"]
    tool = ToolSpec(
        radius_m=tool_table["radius_m"],
        bottom_height_m=tool_table["bottom_height_m"],
        reference_depth_m=tool_table["reference_depth_m"],
        edge_width_m=tool_table["edge_width_m"],
        max_speed_m_s=tool_table["max_speed_m_s"],
        start_position_m=tuple(tool_table["start_position_m"]),
    )
    if tool.edge_width_m >= 2.0 * tool.radius_m:
        raise ConfigError("tool.edge_width_m",
                          f"must be below the tool diameter {2 * tool.radius_m:g} m")
    sx, sy = tool.start_position_m
    if not (gx0 <= sx <= gx1 and gy0 <= sy <= gy1):
        raise ConfigError("tool.start_position_m", f"({sx:g}, {sy:g}) m lies outside the grid")
    return Scenario(
        name=main["scenario"]["name"],
        description=main["scenario"]["description"],
        environment=main["scenario"]["environment"],
        grid=grid,
        tool=tool,
        handle_force_N=tuple(main["operator"]["handle_force_N"]),
        blocks=blocks,
        source=source,
    )


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Load a shipped scenario by name (``constant-rate``, ``variable-rate``, ``arbitrary``)
    or a scenario file by path. Raises :class:`ConfigError` naming the problem."""
    text: str
    source = str(name_or_path)
    if isinstance(name_or_path, str) and name_or_path in SCENARIO_NAMES:
        text = resources.files("haptic.common.config").joinpath(
            f"scenarios/{name_or_path}.toml").read_text()
    else:
        path = Path(name_or_path)
        try:
            unknown = not source or (not path.suffix and not path.exists())
        except OSError:  # a name the file system cannot take (too long; pathlib's exists()
            # already answers False for one with a NUL)
            unknown = True
        if unknown:
            raise ConfigError("slave.scenario", f"unknown scenario {source!r}; shipped ones: "
                              f"{', '.join(SCENARIO_NAMES)}, or give a .toml path")
        try:
            text = read_config_text(path, "scenario file")
        except ConfigError as error:
            raise ConfigError("slave.scenario", str(error)) from None
    return scenario_from_table(parse_toml(text, source), source)


def max_block_damping(scenario: Any) -> float | None:
    """The largest block damping of a scenario, N s/m (``None`` without blocks)."""
    values = [block.damping_N_s_per_m for block in scenario.blocks]
    return max(values) if values else None
