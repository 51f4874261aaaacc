"""The clay workpiece: a multi-block height field cut by the virtual tool (docs/clay.md).

Model in brief (docs/clay.md has the derivation):

- The workpiece is a height field, one clay column per cell of the x-y grid, each cell
  belonging to a block with its own viscous damping B (N s/m).
- The tool is a flat-end cylinder of radius R whose bottom sits at ``bottom_height_m``, with
  a chamfer of radial width w at its bottom edge. Each step lowers every cell under it to the
  tool's surface, at most ``cut_cap`` per cell and step.
- Force: the removed volume dV over the step, against the reference volume
  ``2 R d_ref |dp|`` that a full-depth cut sweeps for the tool's displacement dp, gives the
  engagement ``e = min(1, dV / (2 R d_ref |dp|))``; the force the tool applies to the clay is
  ``ft = B_eff e v`` with ``B_eff`` the removal-weighted damping of the cut cells. At full
  engagement ft = B v (the paper's viscous clay); the clay pushes back on the tool with -ft.

Two implementations of the same step: :class:`WarpClay` (NVIDIA Warp kernels, device "cpu"
or "cuda") and :class:`NumpyClay` (vectorised numpy, the reference). Both keep their state in
a :class:`ClayState` owned by the caller, lanes on the leading axis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from haptic.common.config.scenario import Scenario
from haptic.slave_sim.clay_numpy import GeometryConstants, cut_numpy, window_starts
from haptic.slave_sim.workpiece import NO_BLOCK, Workpiece, build_workpiece

CLAY_IMPLEMENTATIONS = ("warp", "numpy")
#: Displacement (m) under which a step counts as no motion for the engagement.
MIN_DISPLACEMENT_M = 1e-12


def resolve_device(device: str) -> str:
    """Warp device for ``device``: "auto" -> "cuda" when a CUDA device exists, else "cpu"."""
    if device != "auto":
        return device
    import warp as wp

    wp.init()
    return "cuda" if wp.get_cuda_device_count() > 0 else "cpu"


@dataclass(frozen=True)
class ClayStepResult:
    """What one clay step gives, per lane.

    ``force_N`` (lanes, 2): force the tool applies to the clay (the clay pushes back with
    -force_N); ``cutting`` (lanes,): the tool removed material this step; ``engagement``
    (lanes,): fraction 0..1 of the reference cut; ``removed_volume_m3`` (lanes,): volume
    removed this step; ``damping_N_s_per_m`` (lanes,): removal-weighted damping of the cut.
    """

    force_N: np.ndarray
    cutting: np.ndarray
    engagement: np.ndarray
    removed_volume_m3: np.ndarray
    damping_N_s_per_m: np.ndarray


def geometry_for(scenario: Scenario, sample_period_s: float) -> GeometryConstants:
    """The cut's constants for ``scenario`` stepped every ``sample_period_s`` s."""
    grid, tool = scenario.grid, scenario.tool
    dx, dy = grid.cell_size_x_m, grid.cell_size_y_m
    outer = tool.radius_m + 0.5 * tool.edge_width_m
    # The smoothstep chamfer rises reference_depth over edge_width; its steepest slope is 1.5
    # times the mean, so a cell drops at most that slope times the tool's travel per step.
    steepest_slope = 1.5 * tool.reference_depth_m / tool.edge_width_m
    return GeometryConstants(
        x0=grid.x_range_m[0],
        y0=grid.y_range_m[0],
        dx=dx,
        dy=dy,
        cells_x=grid.cells_x,
        cells_y=grid.cells_y,
        window_x=min(grid.cells_x, math.ceil(2.0 * outer / dx) + 2),
        window_y=min(grid.cells_y, math.ceil(2.0 * outer / dy) + 2),
        inner_radius=tool.radius_m - 0.5 * tool.edge_width_m,
        outer_radius=outer,
        edge_height=tool.reference_depth_m,
        inv_edge_width=1.0 / tool.edge_width_m,
        bottom_height=tool.bottom_height_m,
        cut_cap=steepest_slope * tool.max_speed_m_s * sample_period_s,
        cell_area=dx * dy,
    )


@dataclass(eq=False)
class ClayState:
    """The mutable clay of ``lanes`` workpieces: owned by the caller, stepped by a clay model.

    ``heights`` is the implementation's array (numpy, or a Warp array) of shape
    (lanes, cells_y, cells_x) in m; ``damping`` (lanes, n_blocks) N s/m may be changed per
    lane for a sweep; ``removed_total_m3`` (lanes,) sums every step's removal.
    """

    workpiece: Workpiece
    heights: Any
    damping: Any
    removed_total_m3: np.ndarray
    initial_volume_m3: np.ndarray
    runtime: dict[str, Any] = field(default_factory=dict)

    @property
    def lanes(self) -> int:
        """Number of independent workpieces."""
        return self.removed_total_m3.shape[0]

    def set_block_damping(self, damping_N_s_per_m: np.ndarray) -> None:
        """Give each lane its own block dampings, shape (lanes, n_blocks) or (n_blocks,),
        N s/m (a sweep over clay stiffness); works on any device."""
        values = np.broadcast_to(np.asarray(damping_N_s_per_m, float),
                                 (self.lanes, len(self.workpiece.block_names)))
        if values.min() < 0.0:
            raise ValueError("block damping must be >= 0 N s/m")
        if hasattr(self.damping, "assign"):
            self.damping.assign(np.ascontiguousarray(values))
        else:
            self.damping[...] = values

    def block_damping_N_s_per_m(self) -> np.ndarray:
        """The lanes' block dampings (lanes, n_blocks), N s/m (a copy)."""
        return np.array(self.damping.numpy() if hasattr(self.damping, "numpy") else self.damping)

    def heights_m(self) -> np.ndarray:
        """The height field as numpy (lanes, cells_y, cells_x), m (a copy)."""
        return np.array(self.heights.numpy() if hasattr(self.heights, "numpy") else self.heights)

    def volume_m3(self) -> np.ndarray:
        """Clay volume left per lane, m^3 (float64 sums)."""
        return self.heights_m().sum(axis=(1, 2)) * self.workpiece.cell_area_m2

    def conservation_error_m3(self) -> np.ndarray:
        """(initial volume - volume left) - removed total, per lane, m^3: zero when conserved."""
        return (self.initial_volume_m3 - self.volume_m3()) - self.removed_total_m3

    def save_npz(self, path: str | Path, lane: int = 0) -> None:
        """Save one lane's workpiece: heights, block ids and names, grid ranges, removal."""
        wp_ = self.workpiece
        np.savez_compressed(
            path,
            heights_m=self.heights_m()[lane],
            initial_heights_m=wp_.heights_m,
            block_id=wp_.block_id,
            block_names=np.array(wp_.block_names),
            block_damping_N_s_per_m=self.block_damping_N_s_per_m()[lane],
            x_range_m=np.array(wp_.grid.x_range_m),
            y_range_m=np.array(wp_.grid.y_range_m),
            removed_total_m3=self.removed_total_m3[lane],
        )

    def render_png(self, path: str | Path, tool_path_xy: np.ndarray | None = None,
                   lane: int = 0, title: str | None = None) -> None:
        """Render one lane's height map (mm) with block boundaries and the tool path."""
        from haptic.slave_sim.render import render_workpiece

        render_workpiece(path, self.workpiece, self.heights_m()[lane], tool_path_xy, title)


class _ClayBase:
    """What both implementations share: construction from a scenario and the force law."""

    impl = ""

    def __init__(self, scenario: Scenario, sample_period_s: float) -> None:
        self.scenario = scenario
        self.sample_period_s = float(sample_period_s)
        self.workpiece = build_workpiece(scenario)
        self.geometry = geometry_for(scenario, sample_period_s)
        tool = scenario.tool
        #: Cross-section (m^2) of the reference cut: tool diameter x reference depth.
        self.reference_area_m2 = 2.0 * tool.radius_m * tool.reference_depth_m

    def _new_state(self, lanes: int, heights: Any, damping: Any) -> ClayState:
        volume = np.full(lanes, self.workpiece.heights_m.sum() * self.workpiece.cell_area_m2)
        return ClayState(self.workpiece, heights, damping, np.zeros(lanes), volume)

    def _result(self, state: ClayState, sums: np.ndarray, previous_xy: np.ndarray,
                position_xy: np.ndarray, velocity_xy: np.ndarray) -> ClayStepResult:
        removed = sums[:, 0].copy()
        state.removed_total_m3 += removed
        step = position_xy - previous_xy
        displacement = np.sqrt(step[:, 0] * step[:, 0] + step[:, 1] * step[:, 1])
        cutting = removed > 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = removed / (self.reference_area_m2 * displacement)
            engagement = np.where(displacement > MIN_DISPLACEMENT_M, np.minimum(ratio, 1.0),
                                  cutting.astype(float))
            damping = np.where(cutting, sums[:, 1] / removed, 0.0)
        force = (damping * engagement)[:, None] * velocity_xy
        return ClayStepResult(force, cutting, engagement, removed, damping)

    def footprint_windows(self, position_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """First column and row of each lane's footprint window (for tests and plots)."""
        return window_starts(np.asarray(position_xy, float), self.geometry)

    @property
    def window_cells(self) -> tuple[int, int]:
        """(window_y, window_x): cells each launch covers per lane."""
        return self.geometry.window_y, self.geometry.window_x


class NumpyClay(_ClayBase):
    """The clay step in vectorised numpy (the reference implementation)."""

    impl = "numpy"
    device = "numpy"

    def initial_state(self, lanes: int = 1) -> ClayState:
        """Fresh workpieces for ``lanes`` lanes."""
        heights = np.repeat(self.workpiece.heights_m[None], lanes, axis=0)
        damping = np.repeat(self.workpiece.block_damping_N_s_per_m[None], lanes, axis=0)
        return self._new_state(lanes, heights, damping)

    def step(self, state: ClayState, previous_xy: np.ndarray, position_xy: np.ndarray,
             velocity_xy: np.ndarray) -> ClayStepResult:
        """Cut along the move ``previous_xy`` -> ``position_xy`` (lanes, 2) m, tool velocity
        ``velocity_xy`` (lanes, 2) m/s at the new position."""
        sums = cut_numpy(state.heights, self.workpiece.block_id, state.damping,
                         np.asarray(position_xy, float), self.geometry)
        return self._result(state, sums, previous_xy, position_xy, velocity_xy)


class WarpClay(_ClayBase):
    """The clay step as one NVIDIA Warp kernel launch over every lane's footprint window.

    On the CPU device the tool position and the sums are zero-copy numpy views of the Warp
    arrays and the launch is recorded once (``record_cmd=True``) and replayed each step. On
    CUDA the step copies the tool positions in, zeroes the sums, replays the recorded launch
    and copies the sums back (pinned host buffers).
    """

    impl = "warp"

    def __init__(self, scenario: Scenario, sample_period_s: float, device: str = "auto") -> None:
        super().__init__(scenario, sample_period_s)
        import warp as wp

        from haptic.slave_sim import clay_kernels

        wp.init()
        self._wp = wp
        self._kernels = clay_kernels
        self.device = resolve_device(device)
        self._block_id = wp.array(self.workpiece.block_id, dtype=wp.int32, device=self.device)
        geo = clay_kernels.ClayGeometry()
        g = self.geometry
        for name in ("x0", "y0", "dx", "dy", "inner_radius", "outer_radius", "edge_height",
                     "inv_edge_width",
                     "bottom_height", "cut_cap", "cell_area"):
            setattr(geo, name, wp.float64(getattr(g, name)))
        for name in ("cells_x", "cells_y", "window_x", "window_y"):
            setattr(geo, name, int(getattr(g, name)))
        self._geo = geo

    def initial_state(self, lanes: int = 1) -> ClayState:
        """Fresh workpieces for ``lanes`` lanes, and the recorded launch that cuts them."""
        wp = self._wp
        heights = wp.array(np.repeat(self.workpiece.heights_m[None], lanes, axis=0),
                           dtype=wp.float64, device=self.device)
        damping = wp.array(np.repeat(self.workpiece.block_damping_N_s_per_m[None], lanes, axis=0),
                           dtype=wp.float64, device=self.device)
        tool = wp.zeros((lanes, 2), dtype=wp.float64, device=self.device)
        sums = wp.zeros((lanes, 2), dtype=wp.float64, device=self.device)
        state = self._new_state(lanes, heights, damping)
        g = self.geometry
        launch = wp.launch(
            self._kernels.cut_kernel,
            dim=(lanes, g.window_y),
            inputs=[heights, self._block_id, damping, tool, self._geo, sums],
            device=self.device,
            record_cmd=True,
        )
        runtime: dict[str, Any] = {"launch": launch, "tool": tool, "sums": sums}
        if self.device == "cpu":
            runtime["tool_host"] = tool.numpy()  # zero-copy views on the CPU device
            runtime["sums_host"] = sums.numpy()
        else:
            runtime["tool_host"] = wp.zeros((lanes, 2), dtype=wp.float64, device="cpu",
                                            pinned=True)
            runtime["sums_host"] = wp.zeros((lanes, 2), dtype=wp.float64, device="cpu",
                                            pinned=True)
        state.runtime = runtime
        return state

    def step(self, state: ClayState, previous_xy: np.ndarray, position_xy: np.ndarray,
             velocity_xy: np.ndarray) -> ClayStepResult:
        """Cut along the move ``previous_xy`` -> ``position_xy`` (lanes, 2) m, tool velocity
        ``velocity_xy`` (lanes, 2) m/s at the new position."""
        rt = state.runtime
        if self.device == "cpu":
            rt["tool_host"][...] = position_xy
            sums = rt["sums_host"]
            sums[...] = 0.0
            rt["launch"].launch()
        else:
            wp = self._wp
            rt["tool_host"].numpy()[...] = position_xy
            wp.copy(rt["tool"], rt["tool_host"])
            rt["sums"].zero_()
            rt["launch"].launch()
            wp.copy(rt["sums_host"], rt["sums"])
            wp.synchronize_device(self.device)
            sums = rt["sums_host"].numpy()
        return self._result(state, sums, previous_xy, position_xy, velocity_xy)


def make_clay(scenario: Scenario, sample_period_s: float, impl: str = "warp",
              device: str = "auto") -> WarpClay | NumpyClay:
    """The clay model named ``impl`` ("warp" or "numpy") for ``scenario``."""
    if impl == "warp":
        return WarpClay(scenario, sample_period_s, device)
    if impl == "numpy":
        return NumpyClay(scenario, sample_period_s)
    raise ValueError(f"clay implementation must be one of {CLAY_IMPLEMENTATIONS} (got {impl!r})")


__all__ = [
    "CLAY_IMPLEMENTATIONS", "NO_BLOCK", "ClayState", "ClayStepResult", "NumpyClay", "WarpClay",
    "geometry_for", "make_clay", "resolve_device",
]
