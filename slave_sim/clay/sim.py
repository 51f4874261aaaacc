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
from haptic.common.model.clay_contact import (
    COUPLING_DAMPING_N_S_PER_M,
    COUPLING_STIFFNESS_N_PER_M,
    passivity_margin_N_s_per_m,
)
from haptic.common.runtime.replayed_launch import ReplayedLaunch
from haptic.slave_sim.clay.clay_numpy import (
    ContactConstants,
    GeometryConstants,
    cut_numpy,
    proxy_numpy,
    window_starts,
    yield_numpy,
)
from haptic.slave_sim.clay.workpiece import NO_BLOCK, Workpiece, build_workpiece

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


def device_problem(device: str) -> str | None:
    """What stops the clay running on ``device`` (None: nothing): a name that is not a Warp
    device, or a CUDA device this machine does not have."""
    from haptic.common.config.slave_schema import device_form_problem

    problem = device_form_problem(device)
    if problem is not None or not device.startswith("cuda"):
        return problem
    import warp as wp

    wp.init()
    count = wp.get_cuda_device_count()
    index = int(device.partition(":")[2] or 0)
    if index >= count:
        return f"no CUDA device {device!r} on this machine ({count} found)"
    return None


@dataclass(frozen=True)
class ClayStepResult:
    """What one clay step gives, per lane.

    ``force_N`` (lanes, 2): force the tool applies to the clay (the clay pushes back with
    -force_N); ``cutting`` (lanes,): the tool removed material this step; ``engagement``
    (lanes,): fraction 0..1 of the reference cut; ``removed_volume_m3`` (lanes,): volume
    removed this step; ``damping_N_s_per_m`` (lanes,): removal-weighted damping of the cut;
    ``proxy_position_m`` (lanes, 2): the proxy after the step (the clay's; None otherwise).
    """

    force_N: np.ndarray
    cutting: np.ndarray
    engagement: np.ndarray
    removed_volume_m3: np.ndarray
    damping_N_s_per_m: np.ndarray
    proxy_position_m: np.ndarray | None = None


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
    proxy: Any = None
    proxy_prev: Any = None
    resistance: Any = None
    direction: Any = None
    contact_ready: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    #: every lane's ``contact_ready`` is true (it never turns false again)
    contact_all_ready: bool = False
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

    def proxy_position_m(self) -> np.ndarray:
        """Each lane's proxy, the tool's contact point in the clay (lanes, 2), m (a copy)."""
        return np.array(_host(self.proxy))

    def resistance_N_s_per_m(self) -> np.ndarray:
        """Each lane's clay resistance c = B_eff e for the next step (lanes,), N s/m."""
        return np.array(_host(self.resistance))

    def place_proxy(self, position_m: np.ndarray, lanes: np.ndarray | slice | None = None
                    ) -> None:
        """Put the proxy of ``lanes`` (default all) at ``position_m`` ((lanes, 2) or (2,),
        m) with no resistance: the next step starts a fresh contact there (no sweep)."""
        index = slice(None) if lanes is None else lanes
        target = np.broadcast_to(np.asarray(position_m, float), (self.lanes, 2))
        for name, values in (("proxy", target), ("proxy_prev", target)):
            array = getattr(self, name)
            host = np.array(_host(array))
            host[index] = values[index]
            _assign(array, host)
        resistance = np.array(_host(self.resistance))
        resistance[index] = 0.0
        _assign(self.resistance, resistance)
        self.contact_ready[index] = True

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
        from haptic.slave_sim.clay.render import render_workpiece

        render_workpiece(path, self.workpiece, self.heights_m()[lane], tool_path_xy, title)


def _host(array: Any) -> np.ndarray:
    """A numpy view (CPU Warp array, numpy) or copy (CUDA Warp array) of ``array``."""
    return array.numpy() if hasattr(array, "numpy") else array


def _assign(array: Any, values: np.ndarray) -> None:
    """Write ``values`` into ``array`` (numpy or Warp, any device)."""
    if hasattr(array, "assign"):
        array.assign(np.ascontiguousarray(values))
    else:
        array[...] = values


class _ClayBase:
    """What both implementations share: construction from a scenario and the force law."""

    impl = ""

    def __init__(self, scenario: Scenario, sample_period_s: float,
                 coupling_stiffness_N_per_m: float = COUPLING_STIFFNESS_N_PER_M,
                 coupling_damping_N_s_per_m: float = COUPLING_DAMPING_N_S_PER_M) -> None:
        if coupling_stiffness_N_per_m <= 0.0 or coupling_damping_N_s_per_m < 0.0:
            raise ValueError("the tool-proxy coupling needs a stiffness > 0 N/m and a "
                             "damping >= 0 N s/m")
        self.scenario = scenario
        self.sample_period_s = float(sample_period_s)
        self.workpiece = build_workpiece(scenario)
        self.geometry = geometry_for(scenario, sample_period_s)
        tool = scenario.tool
        #: Cross-section (m^2) of the reference cut: tool diameter x reference depth.
        self.reference_area_m2 = 2.0 * tool.radius_m * tool.reference_depth_m
        self.coupling_stiffness_N_per_m = float(coupling_stiffness_N_per_m)
        self.coupling_damping_N_s_per_m = float(coupling_damping_N_s_per_m)
        self.contact = ContactConstants(
            stiffness=self.coupling_stiffness_N_per_m, damping=self.coupling_damping_N_s_per_m,
            period=self.sample_period_s, reference_area=self.reference_area_m2,
            min_step=MIN_DISPLACEMENT_M)

    def passivity_margin_N_s_per_m(self, tool_damping_N_s_per_m: float) -> float:
        """Colgate and Brown's bound for the coupling rendered on a device of physical
        damping ``tool_damping_N_s_per_m``: ``Bt - (K Ts / 2 + b)``, N s/m; > 0 is passive."""
        return passivity_margin_N_s_per_m(tool_damping_N_s_per_m, self.sample_period_s,
                                          self.coupling_stiffness_N_per_m,
                                          self.coupling_damping_N_s_per_m)

    def _new_state(self, lanes: int, heights: Any, damping: Any) -> ClayState:
        volume = np.full(lanes, self.workpiece.heights_m.sum() * self.workpiece.cell_area_m2)
        state = ClayState(self.workpiece, heights, damping, np.zeros(lanes), volume)
        state.contact_ready = np.zeros(lanes, bool)
        return state

    def step(self, state: ClayState, previous_xy: np.ndarray, position_xy: np.ndarray,
             velocity_xy: np.ndarray) -> ClayStepResult:
        """One step: the tool moved from ``previous_xy`` to ``position_xy`` (lanes, 2), m,
        with velocity ``velocity_xy`` (lanes, 2), m/s at the new position. The proxy
        advances by the implicit contact law and cuts the clay on its way; a lane's first
        step places its proxy at ``previous_xy``."""
        if not state.contact_all_ready:  # contact_ready only ever turns true
            if not state.contact_ready.all():
                state.place_proxy(previous_xy, ~state.contact_ready)
            state.contact_all_ready = True
        return self._advance(state, np.asarray(position_xy, float),
                             np.asarray(velocity_xy, float))

    def _advance(self, state: ClayState, position_xy: np.ndarray, velocity_xy: np.ndarray
                 ) -> ClayStepResult:
        raise NotImplementedError

    def _result(self, state: ClayState, sums: np.ndarray, previous_xy: np.ndarray,
                position_xy: np.ndarray, force: np.ndarray) -> ClayStepResult:
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
        return ClayStepResult(np.array(force), cutting, engagement, removed, damping,
                              np.array(position_xy))

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
        state = self._new_state(lanes, heights, damping)
        state.proxy = np.zeros((lanes, 2))
        state.proxy_prev = np.zeros((lanes, 2))
        state.resistance = np.zeros(lanes)
        state.direction = np.zeros((lanes, 2))
        return state

    def _advance(self, state: ClayState, position_xy: np.ndarray, velocity_xy: np.ndarray
                 ) -> ClayStepResult:
        force = np.zeros((state.lanes, 2))
        proxy_numpy(position_xy, velocity_xy, state.proxy, state.proxy_prev, state.resistance,
                    state.direction, force, self.contact)
        sums = cut_numpy(state.heights, self.workpiece.block_id, state.damping, state.proxy,
                         self.geometry)
        yield_numpy(state.proxy, state.proxy_prev, sums, state.resistance, state.direction,
                    self.contact)
        return self._result(state, sums, state.proxy_prev.copy(), state.proxy.copy(), force)


class WarpClay(_ClayBase):
    """The clay step as three recorded NVIDIA Warp launches: the proxy's implicit step (one
    thread per lane), the cut at the proxy over every lane's footprint window, and the clay's
    resistance for the next step (one thread per lane).

    On the CPU device the tool's position and velocity, the force and the sums are zero-copy
    numpy views of the Warp arrays and the launches are recorded once (``record_cmd=True``)
    and replayed each step. On CUDA the step is one captured graph that copies the tool's
    state in, launches the three kernels and copies the force, results and proxy positions
    out (pinned host buffers).
    """

    impl = "warp"

    def __init__(self, scenario: Scenario, sample_period_s: float, device: str = "auto",
                 coupling_stiffness_N_per_m: float = COUPLING_STIFFNESS_N_PER_M,
                 coupling_damping_N_s_per_m: float = COUPLING_DAMPING_N_S_PER_M) -> None:
        super().__init__(scenario, sample_period_s, coupling_stiffness_N_per_m,
                         coupling_damping_N_s_per_m)
        import warp as wp

        from haptic.slave_sim.clay import clay_kernels

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
        cc = clay_kernels.ContactConstants()
        for name in ("stiffness", "damping", "period", "reference_area", "min_step"):
            setattr(cc, name, wp.float64(getattr(self.contact, name)))
        self._cc = cc

    #: Arrays copied in (CUDA) before the launches, and out after them.
    _INPUTS = ("tool", "velocity")
    _OUTPUTS = ("force", "proxy", "result")

    def initial_state(self, lanes: int = 1) -> ClayState:
        """Fresh workpieces for ``lanes`` lanes, and the recorded launches that cut them."""
        wp = self._wp
        dev = self.device
        heights = wp.array(np.repeat(self.workpiece.heights_m[None], lanes, axis=0),
                           dtype=wp.float64, device=dev)
        damping = wp.array(np.repeat(self.workpiece.block_damping_N_s_per_m[None], lanes, axis=0),
                           dtype=wp.float64, device=dev)
        columns = {"result": len(self._kernels.RESULT_COLUMNS)}  # (lanes, 2) otherwise
        arrays = {name: wp.zeros((lanes, columns.get(name, 2)), dtype=wp.float64, device=dev)
                  for name in ("tool", "velocity", "force", "sums", "proxy", "proxy_prev",
                               "direction", "result")}
        resistance = wp.zeros(lanes, dtype=wp.float64, device=dev)
        state = self._new_state(lanes, heights, damping)
        state.proxy, state.proxy_prev = arrays["proxy"], arrays["proxy_prev"]
        state.resistance, state.direction = resistance, arrays["direction"]
        k = self._kernels
        a = arrays
        launches = [
            wp.launch(k.proxy_kernel, dim=lanes,
                      inputs=[a["tool"], a["velocity"], a["proxy"], a["proxy_prev"], resistance,
                              a["direction"], a["force"], a["sums"], self._cc],
                      device=dev, record_cmd=True),
            wp.launch(k.cut_kernel, dim=(lanes, self.geometry.window_y),
                      inputs=[heights, self._block_id, damping, a["proxy"], self._geo,
                              a["sums"]],
                      device=dev, record_cmd=True),
            wp.launch(k.yield_kernel, dim=lanes,
                      inputs=[a["proxy"], a["proxy_prev"], a["sums"], resistance,
                              a["direction"], self._cc, a["result"]],
                      device=dev, record_cmd=True),
        ]
        runtime: dict[str, Any] = {"launches": [ReplayedLaunch(launch) for launch in launches],
                                   "arrays": arrays}
        if dev == "cpu":  # zero-copy views on the CPU device
            runtime["host"] = {name: arrays[name].numpy() for name in self._INPUTS + self._OUTPUTS}
        else:
            runtime["pinned"] = {name: wp.zeros((lanes, columns.get(name, 2)),
                                                dtype=wp.float64, device="cpu", pinned=True)
                                 for name in self._INPUTS + self._OUTPUTS}
            runtime["host"] = {name: array.numpy() for name, array in runtime["pinned"].items()}
            runtime["graph"] = self._capture_step(runtime)
        state.runtime = runtime
        return state

    def step_arguments(self, state: ClayState) -> list[Any]:
        """The Warp arrays and constants of ``state``'s step, in the order a kernel that runs
        the proxy, the cut and the yield itself takes them (slave_sim/catch_up_kernels.py):
        the tool's position and velocity (inputs), proxy, previous proxy, resistance,
        direction, force, sums, contact constants, heights, block ids, block dampings,
        geometry, result."""
        a = state.runtime["arrays"]
        return [a["tool"], a["velocity"], a["proxy"], a["proxy_prev"], state.resistance,
                a["direction"], a["force"], a["sums"], self._cc, state.heights,
                self._block_id, state.damping, self._geo, a["result"]]

    def _capture_step(self, runtime: dict[str, Any]) -> Any:
        """The CUDA step as one graph: the inputs copied in from the pinned buffers, the three
        launches, the outputs copied back (a replay costs one launch instead of eight; the
        state's arrays are only ever written in place, so the graph's pointers stay valid)."""
        wp = self._wp
        with wp.ScopedCapture(device=self.device, force_module_load=False) as capture:
            for name in self._INPUTS:
                wp.copy(runtime["arrays"][name], runtime["pinned"][name])
            for launch in runtime["launches"]:
                launch.launch()
            for name in self._OUTPUTS:
                wp.copy(runtime["pinned"][name], runtime["arrays"][name])
        return capture.graph

    def _advance(self, state: ClayState, position_xy: np.ndarray, velocity_xy: np.ndarray
                 ) -> ClayStepResult:
        rt = state.runtime
        host = rt["host"]
        host["tool"][...] = position_xy
        host["velocity"][...] = velocity_xy
        if self.device == "cpu":
            for launch in rt["launches"]:
                launch.launch()
        else:
            self._wp.capture_launch(rt["graph"])
            self._wp.synchronize_device(self.device)
        result = host["result"]  # the yield kernel's bookkeeping (numpy's: _result)
        removed = result[:, 0].copy()
        state.removed_total_m3 += removed
        return ClayStepResult(host["force"].copy(), result[:, 1] > 0.0, result[:, 2].copy(),
                              removed, result[:, 3].copy(), host["proxy"].copy())


def make_clay(scenario: Scenario, sample_period_s: float, impl: str = "warp",
              device: str = "auto", **coupling: float) -> WarpClay | NumpyClay:
    """The clay model named ``impl`` ("warp" or "numpy") for ``scenario``; ``coupling``:
    ``coupling_stiffness_N_per_m`` and ``coupling_damping_N_s_per_m`` (module defaults)."""
    if impl == "warp":
        return WarpClay(scenario, sample_period_s, device, **coupling)
    if impl == "numpy":
        return NumpyClay(scenario, sample_period_s, **coupling)
    raise ValueError(f"clay implementation must be one of {CLAY_IMPLEMENTATIONS} (got {impl!r})")


__all__ = [
    "CLAY_IMPLEMENTATIONS", "NO_BLOCK", "ClayState", "ClayStepResult", "NumpyClay", "WarpClay",
    "device_problem", "geometry_for", "make_clay", "resolve_device",
]
