"""The slave node: the Ch2/Ct2 compensators, the virtual tool and its environment, stepped
at Ts over many independent lanes.

One step, per lane and axis (docs/clay.md, "Slave node")::

    vt   = -Ch2 fh_recv + Ct2 ft_prev     compensators (Tustin, one MIMO block)
    x'   = A x + B vt                     tool plant Gt (ZOH): position yt, velocity
    ft   = environment(yt, velocity, ...) clay (or linear Tt yt) at the new tool state

``ft_prev`` is the environment force of the previous step, computed from the tool state the
compensators now act on, so there is no algebraic loop. ``ft`` goes back to the master and
feeds Ct2 at the next step. The node holds no mutable state: everything that changes lives
in a :class:`SlaveState` the caller owns.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from haptic.common.config.scenario import Scenario, load_scenario
from haptic.common.model.block_kernels import compensator_arrays, write_exchange_inputs
from haptic.common.model.block_layout import CompensatorLayout
from haptic.common.model.drift import DriftCoupling
from haptic.common.model.lti import DiscreteLTI, Path, combine, discretize
from haptic.common.model.passivity import PassivityPort, PassivitySettings
from haptic.common.model.synthesis import AxisCompensators, synthesize
from haptic.common.model.teleop import TeleopModel, model_from_config
from haptic.common.model.work_area import work_area_from_config
from haptic.common.runtime.replayed_launch import ReplayedLaunch
from haptic.slave_sim import node_kernels as kernels
from haptic.slave_sim.environment import make_environment
from haptic.slave_sim.tool import POSITION_COLUMNS, VELOCITY_COLUMNS, tool_constants, tool_plant

COMPENSATOR_INPUTS = ("fh_x", "fh_y", "ft_x", "ft_y")
COMPENSATOR_OUTPUTS = ("vt_x", "vt_y")
#: The Warp device of the node's buffers: the CPU, whose arrays numpy views share (the clay
#: runs on its own device).
DEVICE = "cpu"


def _warp() -> Any:
    import warp as wp

    wp.config.log_level = wp.LOG_WARNING  # no start-up banner on stdout
    wp.init()
    return wp


def slave_compensators(model: TeleopModel,
                       synthesized: Sequence[AxisCompensators] | None = None) -> DiscreteLTI:
    """vt = -Ch2 fh + Ct2 ft for both axes as one MIMO block (Tustin): inputs
    (fh_x, fh_y, ft_x, ft_y) N, outputs (vt_x, vt_y) N. ``synthesized``: the model's
    compensators where they are already at hand (else they are synthesised here)."""
    paths = []
    n_axes = len(model.axes)
    for index, axis in enumerate(synthesize(model) if synthesized is None else synthesized):
        ts = model.sample_period_s
        ch2 = discretize(axis.ch2, ts, "tustin", f"fh_{axis.axis}", f"vt_{axis.axis}")
        ct2 = discretize(axis.ct2, ts, "tustin", f"ft_{axis.axis}", f"vt_{axis.axis}")
        paths.append(Path(ch2, source=index, target=index, gain=-1.0))
        paths.append(Path(ct2, source=n_axes + index, target=index, gain=1.0))
    return combine(paths, COMPENSATOR_INPUTS, COMPENSATOR_OUTPUTS)


@dataclass(eq=False)
class SlaveState:
    """Everything that changes in a slave node, lanes on the leading axis (``compensator``,
    ``tool``, ``halted`` and ``drift`` are views of the node kernels' buffers: modify them in
    place, never rebind them).

    ``compensator`` (lanes, n) and ``tool`` (lanes, 4: yt_x m, dyt_x m/s, yt_y, dyt_y)
    states; ``tool_force_N`` (lanes, 2) the environment force of the last step (ft);
    ``actuator_force_N`` (lanes, 2) the last vt; ``handle_position_m`` (lanes, 2) the last
    received handle position; ``halted`` (lanes,) lanes in the safe state; ``environment``
    the environment's own state (a ClayState for the clay); ``step_count`` steps taken.
    """

    compensator: np.ndarray
    tool: np.ndarray
    tool_force_N: np.ndarray
    actuator_force_N: np.ndarray
    handle_position_m: np.ndarray
    halted: np.ndarray
    environment: Any
    step_count: int = 0
    gain_ratio: np.ndarray | None = None
    """(lanes,) k/k0 the compensators' inputs are scaled by: the master's governed gain k
    (HandleState.gain_k) over this node's; None: 1 (common/analysis/margin_table.py)."""
    tool_force_scale: np.ndarray | None = None
    """(lanes,) the master's force ramp (HandleState.force_scale, 0..1) the Ct2 input ft is
    scaled by, as the master's Ct1 input is; None: 1."""
    #: The TDPA observer and controller of the tool's port (``tdpa`` mode), else None.
    passivity: PassivityPort | None = None
    #: The paper mode's drift coupling filter (common/model/drift.py), else None.
    drift: np.ndarray | None = None
    #: The kernels' buffers and recorded launches (:class:`_NodeKernels`); ``compensator``,
    #: ``tool``, ``halted`` and ``drift`` are numpy views of its buffers: change them in
    #: place, never rebind them.
    kernels: Any = None

    @property
    def lanes(self) -> int:
        """Number of independent lanes."""
        return self.tool.shape[0]

    def tool_position_m(self) -> np.ndarray:
        """Tool positions (lanes, 2), m (a copy)."""
        return self.tool[:, POSITION_COLUMNS]

    def tool_velocity_m_s(self) -> np.ndarray:
        """Tool velocities (lanes, 2), m/s (a copy)."""
        return self.tool[:, VELOCITY_COLUMNS]


@dataclass(frozen=True)
class SlaveOutputs:
    """One step's outputs, per lane (arrays (lanes, 2) unless said otherwise).

    ``tool_position_m``, ``tool_velocity_m_s``: the tool after the step; ``tool_force_N``: ft,
    the force the tool applies to the clay (sent to the master); ``actuator_force_N``: vt
    applied over the step; ``cutting`` (lanes,): material removed this step;
    ``engagement`` (lanes,): 0..1 of the reference cut; ``removed_volume_m3`` (lanes,);
    ``tracking_error_m``: yt - Ah1 yh_recv (diagnostic).
    """

    tool_position_m: np.ndarray
    tool_velocity_m_s: np.ndarray
    tool_force_N: np.ndarray
    actuator_force_N: np.ndarray
    cutting: np.ndarray
    engagement: np.ndarray
    removed_volume_m3: np.ndarray
    tracking_error_m: np.ndarray


class SlaveNode:
    """The slave side as one block: inputs handle force fh_recv (N) and handle position
    yh_recv (m) as received from the master, outputs :class:`SlaveOutputs`.

    ``environment`` is the name of the tool's environment ("clay" or "linear"; ``None``: the
    scenario's), ``clay_impl`` "warp" or "numpy", ``device`` the Warp device ("auto").
    ``compensators``: the Ch2/Ct2 block to run (one per lane, stacked, as the lockstep's
    lanes have); ``None``: synthesised for the model's k.
    """

    def __init__(self, model: TeleopModel, scenario: Scenario, environment: str | None = None,
                 clay_impl: str = "warp", device: str = "auto",
                 passivity: PassivitySettings | None = None,
                 drift: DriftCoupling | None = None,
                 tool_bounds_m: tuple[Sequence[float], Sequence[float]] | None = None,
                 passivity_standby: bool = False, compensators: Any = None) -> None:
        self.model = model
        #: The wall the tool stays inside: (low (x, y), high (x, y)), m, the work area both
        #: sides hold (common/model/work_area.py); None: no wall.
        self.tool_bounds_m = None if tool_bounds_m is None else (
            np.asarray(tool_bounds_m[0], float).copy(), np.asarray(tool_bounds_m[1], float).copy())
        #: The paper mode's drift coupling (common/model/drift.py); None: off.
        self.drift = drift
        #: ``None``: the paper's scheme; else the TDPA layer's settings (``tdpa`` mode).
        self.passivity = passivity
        #: the TDPA layer is built switched off and follows the master's
        #: :attr:`~haptic.common.wire.messages.Flags.TDPA_SWITCHED` (``paper`` mode: the
        #: master's governor may switch it on; slave_sim/tick.py)
        self.passivity_standby = bool(passivity_standby and passivity is not None)
        self.scenario = scenario
        self.sample_period_s = model.sample_period_s
        self.compensators = slave_compensators(model) if compensators is None else (
            compensators)
        self.plant = tool_plant(model)
        mass, damping, stiffness = tool_constants(model)
        self._inv_period_s = 1.0 / model.sample_period_s
        self._position_ratio = np.array([a.position_ratio_ah1 for a in model.axes])
        self.environment_kind = environment or scenario.environment
        self.environment = make_environment(self.environment_kind, model, scenario, clay_impl,
                                            device)
        self._kernel_matrices: tuple[Any, tuple, int, Any] | None = None
        self._constants = self._kernel_constants(mass, damping, stiffness)
        # Load (or compile, a few s the first time) the kernels of the compensators' layout
        # now, never inside a tick (compensators replaced later load theirs at initial_state).
        _warp().load_module(kernels.step_kernels(self._matrices()[3])[0].module, device=DEVICE)

    def _kernel_constants(self, mass: np.ndarray, damping: np.ndarray,
                          stiffness: np.ndarray) -> Any:
        """The kernels' :class:`~haptic.slave_sim.node_kernels.SlaveConstants` (SI units)."""
        constants = kernels.SlaveConstants()
        constants.position_ratio_x, constants.position_ratio_y = map(float,
                                                                     self._position_ratio)
        drift = self.drift
        constants.drift_on = int(drift is not None)
        if drift is not None:
            constants.drift_a, constants.drift_b = drift.coefficients()
            constants.drift_stiffness_N_per_m = drift.stiffness_N_per_m
        constants.bounds_on = int(self.tool_bounds_m is not None)
        if self.tool_bounds_m is not None:
            low, high = self.tool_bounds_m
            constants.low_x_m, constants.low_y_m = map(float, low)
            constants.high_x_m, constants.high_y_m = map(float, high)
        constants.inv_mass_x_per_kg, constants.inv_mass_y_per_kg = map(float, 1.0 / mass)
        constants.damping_x_N_s_per_m, constants.damping_y_N_s_per_m = map(float, damping)
        constants.stiffness_x_N_per_m, constants.stiffness_y_N_per_m = map(float, stiffness)
        return constants

    def _matrices(self) -> tuple[tuple, tuple, int, Any]:
        """The compensators' matrices as (L, ., .) Warp arrays (L = 1: one block for every
        lane; a stacked block gives one per lane) packed in their block layout, the plant's,
        whether they are per lane, and the layout
        (:class:`~haptic.common.model.block_layout.CompensatorLayout`); built again when
        :attr:`compensators` was replaced (the lockstep's lanes)."""
        block = self.compensators
        if self._kernel_matrices is None or self._kernel_matrices[0] is not block:
            wp = _warp()
            per_lane = np.ndim(block.A) == 3
            arrays = [np.ascontiguousarray(np.asarray(m, float) if per_lane
                                           else np.asarray(m, float)[None])
                      for m in (block.A, block.B, block.C, block.D)]
            layout, packed, _ = CompensatorLayout.of(*arrays)
            compensator = tuple(wp.array(m, dtype=wp.float64, device=DEVICE) for m in packed)
            plant = tuple(wp.array(np.ascontiguousarray(m, float), dtype=wp.float64,
                                   device=DEVICE) for m in (self.plant.A, self.plant.B))
            self._kernel_matrices = (block, (compensator, plant), int(per_lane), layout)
        _, (compensator, plant), per_lane, layout = self._kernel_matrices
        return compensator, plant, per_lane, layout

    @classmethod
    def from_config(cls, config: dict[str, Any], scenario: Scenario | None = None) -> SlaveNode:
        """The node of a validated configuration (``[model]``, ``[slave]``, ``[control]``)."""
        section = config["slave"]
        scenario = scenario or load_scenario(section["scenario"])
        environment = None if section["environment"] == "scenario" else section["environment"]
        from haptic.common.config.control_schema import (
            drift_coupling,
            passivity_settings,
            standby_passivity_settings,
        )

        model = model_from_config(config)
        area = work_area_from_config(config, scenario.grid.x_range_m, scenario.grid.y_range_m)
        # paper mode: the layer on standby, for a master whose governor switches it on
        passivity = passivity_settings(config)
        standby = passivity is None
        return cls(model, scenario, environment, section["clay_impl"], section["device"],
                   standby_passivity_settings(config) if standby else passivity,
                   drift_coupling(config, model.sample_period_s),
                   (area.tool_low_m, area.tool_high_m), standby)

    def initial_state(self, lanes: int = 1, start_position_m: np.ndarray | None = None
                      ) -> SlaveState:
        """``lanes`` lanes at rest with the tool at ``start_position_m`` ((2,) or (lanes, 2),
        m; default: the scenario's start) and fresh workpieces."""
        start = np.broadcast_to(
            np.asarray(self.scenario.tool.start_position_m if start_position_m is None
                       else start_position_m, float), (lanes, 2))
        runtime = _NodeKernels(self, lanes)
        runtime.tool[:, POSITION_COLUMNS] = start
        return SlaveState(
            compensator=runtime.compensator,
            tool=runtime.tool,
            tool_force_N=np.zeros((lanes, 2)),
            actuator_force_N=np.zeros((lanes, 2)),
            handle_position_m=start / self._position_ratio,
            halted=runtime.halted,
            environment=self.environment.initial_state(lanes),
            passivity=None if self.passivity is None else PassivityPort.create(
                self.passivity, self.sample_period_s, lanes, self.passivity.slave_keep_J,
                active=not self.passivity_standby),
            drift=None if self.drift is None else runtime.drift,
            kernels=runtime,
        )

    def step(self, state: SlaveState, handle_force_N: np.ndarray,
             handle_position_m: np.ndarray, peer_energy_J: np.ndarray | None = None
             ) -> SlaveOutputs:
        """Advance every lane by one period Ts; inputs (lanes, 2) in N and m;
        ``peer_energy_J`` (lanes,): the master's cumulative input energy received (``tdpa``
        mode; ignored otherwise). The law runs in :mod:`haptic.slave_sim.node_kernels`."""
        position, velocity, result = self._advance(state, handle_force_N, handle_position_m,
                                                   peer_energy_J)
        return SlaveOutputs(
            tool_position_m=position,
            tool_velocity_m_s=velocity,
            tool_force_N=state.tool_force_N,
            actuator_force_N=state.actuator_force_N,
            cutting=result.cutting,
            engagement=result.engagement,
            removed_volume_m3=result.removed_volume_m3,
            tracking_error_m=position - self._position_ratio * handle_position_m,
        )

    def advance(self, state: SlaveState, handle_force_N: np.ndarray,
                handle_position_m: np.ndarray, peer_energy_J: np.ndarray | None = None
                ) -> None:
        """:meth:`step` without its outputs: the state (the node's, the environment's)
        advances exactly as :meth:`step` advances it. For the steps whose outputs nobody
        reads (a catch-up tick's earlier samples, slave_sim/tick.py): building the outputs
        costs several us a step."""
        self._advance(state, handle_force_N, handle_position_m, peer_energy_J)

    def _advance(self, state: SlaveState, handle_force_N: np.ndarray,
                 handle_position_m: np.ndarray, peer_energy_J: np.ndarray | None
                 ) -> tuple[np.ndarray, np.ndarray, Any]:
        """One step of :meth:`step`; returns the tool's position and velocity after it
        ((lanes, 2) copies, m and m/s) and the environment's result."""
        runtime = state.kernels
        self._write_inputs(runtime, state, handle_force_N, handle_position_m)
        port = state.passivity
        if port is not None and not (bool(port.active[0]) if runtime.lanes == 1
                                     else port.active.any()):  # on standby: the paper's scheme
            if peer_energy_J is not None:
                port.receive(peer_energy_J)  # noted, not credited: counters stay monotone
            port = None
        tool = state.tool
        shift = None
        runtime.halted_count[0] = 0
        if port is None:
            runtime.step.launch()
            previous = runtime.motion[:, 0:2].copy()
        else:  # tdpa: the layer acts between the compensators and the tool's motion
            runtime.actuate.launch()
            runtime.actuator[...] = self._passivity_force(
                state, port, runtime.actuator.copy(), handle_position_m, peer_energy_J)
            previous = tool[:, POSITION_COLUMNS]
            # the tool moves towards Ah1 yh where that adds no energy
            shift = self._drift_shift(state, port, handle_position_m)
            tool[:, POSITION_COLUMNS] += shift
            runtime.move.launch()
        actuator = runtime.actuator.copy()
        position = tool[:, 0::2].copy()  # POSITION_COLUMNS, as a slice (a faster copy)
        velocity = tool[:, 1::2].copy()  # VELOCITY_COLUMNS
        result = self.environment.step(state.environment, previous, position, velocity,
                                       runtime.motion[:, 2:4].copy())
        if shift is not None:  # the drift moves the tool's base, slowly: the environment
            # sees the swept positions and the plant's own speed (a force law of the speed
            # would otherwise charge the step after it was judged); the outputs the whole
            velocity = velocity + shift * self._inv_period_s
        force = result.force_N
        if runtime.halted_count[0]:
            force = force.copy()
            force[state.halted] = 0.0
        state.tool_force_N = force
        state.actuator_force_N = actuator
        if port is not None:  # the work the environment did on the tool, into the network
            port.observe(-np.einsum("ij,ij->i", force, position - previous))
        state.handle_position_m = handle_position_m
        state.step_count += 1
        return position, velocity, result

    @staticmethod
    def _write_inputs(runtime: _NodeKernels, state: SlaveState, handle_force_N: np.ndarray,
                      handle_position_m: np.ndarray) -> None:
        """The step's inputs into the kernels' buffer (:data:`~haptic.slave_sim.node_kernels.
        INPUT_COLUMNS`): the exchanged forces and position as both nodes write them
        (:func:`~haptic.common.model.block_kernels.write_exchange_inputs`), then the force
        ramp and the gain ratio (by columns, and only where they change, for more lanes)."""
        scale, gain = state.tool_force_scale, state.gain_ratio
        if write_exchange_inputs(runtime.inputs, handle_force_N, handle_position_m,
                                 state.tool_force_N):  # one lane: these columns too
            row = runtime.inputs_row
            row[6] = 1.0 if scale is None else scale[0]
            row[7] = 1.0 if gain is None else gain[0]
            runtime.unit_scale = runtime.unit_gain = False  # the columns written here
            return
        inputs = runtime.inputs
        if scale is not None or not runtime.unit_scale:  # 1 where none: written once
            inputs[:, 6] = 1.0 if scale is None else scale
            runtime.unit_scale = scale is None
        if gain is not None or not runtime.unit_gain:
            inputs[:, 7] = 1.0 if gain is None else gain
            runtime.unit_gain = gain is None

    def _passivity_force(self, state: SlaveState, port: PassivityPort, actuator: np.ndarray,
                         handle_position_m: np.ndarray, peer_energy_J: np.ndarray | None
                         ) -> np.ndarray:
        """TDPA at the tool's port (common/model/passivity.py): the drift correction towards
        ``Ah1 yh`` where it adds no energy, then the adaptive damper on the tool."""
        if peer_energy_J is not None:
            port.receive(peer_energy_J)
        velocity = state.tool[:, VELOCITY_COLUMNS]
        gap = self._position_ratio * np.asarray(handle_position_m) - state.tool[
            :, POSITION_COLUMNS]
        force = state.tool_force_N
        return port.damp(actuator + port.drift_force(gap, velocity, force), velocity, force)

    def _drift_shift(self, state: SlaveState, port: PassivityPort,
                     handle_position_m: np.ndarray) -> np.ndarray:
        """The tool's drift step (lanes, 2), m (:meth:`PassivityPort.drift_shift`); none on
        halted lanes. The environment sees it as the tool's motion of this step."""
        gap = self._position_ratio * np.asarray(handle_position_m) - state.tool[
            :, POSITION_COLUMNS]
        shift = port.drift_shift(gap, state.tool_force_N)
        shift[state.halted] = 0.0
        return shift

    def safe_stop(self, state: SlaveState, lanes: np.ndarray | slice | None = None) -> None:
        """Put ``lanes`` (default: all) in the safe state: the tool stops where it is (zero
        velocity), the actuator force and the force sent back are zero, and the compensator
        states are cleared. Halted lanes stay put and send zero force until :meth:`resume`."""
        index = slice(None) if lanes is None else lanes
        state.halted[index] = True
        if state.drift is not None:
            state.drift[index] = 0.0
        state.tool[index, 1] = 0.0
        state.tool[index, 3] = 0.0
        state.compensator[index] = 0.0
        state.actuator_force_N[index] = 0.0
        state.tool_force_N = state.tool_force_N.copy()
        state.tool_force_N[index] = 0.0

    def resume(self, state: SlaveState, lanes: np.ndarray | slice | None = None) -> None:
        """Leave the safe state: ``lanes`` start again at rest from where the tool stopped,
        with cleared compensator states (no jump in the actuator force)."""
        index = slice(None) if lanes is None else lanes
        state.compensator[index] = 0.0
        state.halted[index] = False

    def resync(self, state: SlaveState, handle_position_m: np.ndarray,
               lanes: np.ndarray | slice | None = None) -> None:
        """Re-synchronise halted ``lanes`` to the received handle position (lanes, 2), m: the
        tool is placed at ``Ah1 yh`` at rest, compensators cleared, no force sent back, so
        that ``yt = Ah1 yh`` when the lanes resume. The clay's proxy is placed there too, so
        the clay sees no sweep between the old and new places (a plunge into clay there is
        spread over steps by the clay's per-step cut cap): this carries the tool through any
        clay in between, which is why a running program resyncs with
        :class:`haptic.slave_sim.resync.ToolResync` (through the clay at a bounded speed)."""
        index = slice(None) if lanes is None else lanes
        target = self._position_ratio * np.asarray(handle_position_m, float)
        state.tool[index, 0] = target[index, 0] if target.ndim == 2 else target[0]
        state.tool[index, 2] = target[index, 1] if target.ndim == 2 else target[1]
        state.tool[index, 1] = 0.0
        state.tool[index, 3] = 0.0
        state.compensator[index] = 0.0
        state.actuator_force_N[index] = 0.0
        state.tool_force_N = state.tool_force_N.copy()
        state.tool_force_N[index] = 0.0
        state.handle_position_m = np.array(np.broadcast_to(handle_position_m,
                                                           state.handle_position_m.shape))
        place_proxy = getattr(state.environment, "place_proxy", None)
        if place_proxy is not None:  # the clay's contact starts afresh where the tool is now
            place_proxy(state.tool[:, POSITION_COLUMNS], index)

    @property
    def clay_device(self) -> str | None:
        """Where the clay steps: a Warp device ("cpu", "cuda", ...), "numpy", or ``None``
        when the environment has no clay."""
        clay = getattr(self.environment, "clay", None)
        return None if clay is None else str(clay.device)

    @property
    def position_ratio(self) -> np.ndarray:
        """Ah1 per axis (x, y), dimensionless: the tool follows ``Ah1 yh``."""
        return self._position_ratio.copy()

    def tracking_error_m(self, state: SlaveState, handle_position_m: np.ndarray) -> np.ndarray:
        """yt - Ah1 yh for every lane (lanes, 2), m."""
        return state.tool_position_m() - self._position_ratio * np.asarray(handle_position_m)


class _NodeKernels:
    """One state's kernel buffers (Warp arrays on the CPU with numpy views of them) and the
    recorded launches of :mod:`haptic.slave_sim.node_kernels` over them: ``step`` (both
    stages), ``actuate`` and ``move`` (the stages apart, the TDPA layer between them)."""

    def __init__(self, node: SlaveNode, lanes: int) -> None:
        wp = _warp()
        compensator_matrices, (plant_a, plant_b), per_lane, layout = node._matrices()
        step_kernel, actuator_kernel, motion_kernel = kernels.step_kernels(layout)
        if per_lane and compensator_matrices[0].shape[0] != lanes:
            raise ValueError(f"compensators stacked for {compensator_matrices[0].shape[0]} "
                             f"lanes, started with {lanes}")
        n = layout.blocks * layout.block_states  # the packed layout's states
        f64 = wp.float64
        inputs = wp.zeros((lanes, len(kernels.INPUT_COLUMNS)), dtype=f64, device=DEVICE)
        compensator = wp.zeros((lanes, n), dtype=f64, device=DEVICE)
        tool = wp.zeros((lanes, 4), dtype=f64, device=DEVICE)
        drift = wp.zeros((lanes, 4), dtype=f64, device=DEVICE)
        actuator = wp.zeros((lanes, 2), dtype=f64, device=DEVICE)
        halted = wp.zeros(lanes, dtype=wp.bool, device=DEVICE)
        halted_count = wp.zeros(1, dtype=wp.int32, device=DEVICE)
        motion = wp.zeros((lanes, len(kernels.MOTION_COLUMNS)), dtype=f64, device=DEVICE)
        constants = node._constants
        actuate_args = [inputs, compensator_arrays(compensator_matrices, per_lane, compensator),
                        tool, drift, actuator]
        #: the step kernel's arguments, in its order (slave_sim/catch_up.py launches them too)
        self.step_arguments = [*actuate_args, plant_a, plant_b, halted, halted_count, motion,
                               constants]
        #: the compensators' layout the kernels were compiled for
        self.layout = layout
        self.step = ReplayedLaunch(wp.launch(step_kernel, dim=lanes, device=DEVICE,
                                             inputs=self.step_arguments, record_cmd=True))
        self.actuate = ReplayedLaunch(wp.launch(actuator_kernel, dim=lanes, device=DEVICE,
                                 inputs=[*actuate_args, constants], record_cmd=True))
        self.move = ReplayedLaunch(wp.launch(motion_kernel, dim=lanes, device=DEVICE,
                              inputs=[plant_a, plant_b, tool, halted, halted_count, actuator,
                                      motion, constants], record_cmd=True))
        self.lanes = lanes
        #: (lanes, 8) the step's inputs (:data:`~haptic.slave_sim.node_kernels.INPUT_COLUMNS`)
        self.inputs = inputs.numpy()
        #: the first lane's row of :attr:`inputs` (a view: the one-lane step writes into it)
        self.inputs_row = self.inputs[0]
        #: whether the scale and gain columns hold the 1 of a state without them (the step
        #: then leaves them as they are)
        self.unit_scale = False
        self.unit_gain = False
        self.compensator = compensator.numpy()
        self.tool = tool.numpy()
        self.drift = drift.numpy()
        self.halted = halted.numpy()
        #: (1,) the halted lanes of the last step (reset before each)
        self.halted_count = halted_count.numpy()
        #: (lanes, 2) vt of the step, N
        self.actuator = actuator.numpy()
        #: (lanes, 4) the tool before the step (m) and its acceleration after it (m/s^2)
        self.motion = motion.numpy()
        # the Warp arrays own the memory the views and the launches use
        self._buffers = (inputs, compensator, tool, drift, actuator, halted, halted_count,
                         motion)
