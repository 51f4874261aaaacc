"""The master node: the Ch1/Ct1 compensators behind a safety layer, vectorised over lanes.

Per axis ``vh = Ch1 fh - Ct1 ft_recv`` (Tustin-discretised from
:mod:`haptic.common.model.synthesis`, one MIMO block with inputs
[fh_x, fh_y, ft_x, ft_y] and outputs [vh_x, vh_y]). The
compensator runs as a position *offset* from the handle's position at activation: the
command is ``origin + vh``, with the compensator state zero at activation, so the first
command equals the current position (no jump). Ch1 = k/(s^2 + 10 s) has an integrator, so
its output is a displacement; Gh(0) = 1, so the handle settles at ``origin + vh``.

Safety, in order, before a command leaves the node (docs/master.md):

1. non-finite handle force, position or tool force -> trip;
2. |fh| beyond ``force_trip_N``, measured speed beyond ``velocity_trip_m_per_s``, or a
   position beyond the workspace plus ``workspace_trip_margin_m`` -> trip;
3. fh and ft saturate at +-``force_limit_N``;
4. force ramp: forces reach the compensator only after ``ramp_small_samples`` consecutive
   samples with every |fh| below ``ramp_small_force_N``, then ramp in linearly over
   ``ramp_time_s`` (CHAI3D's start-up rule);
5. the command's rate is limited to ``velocity_limit_m_per_s`` and the command is clamped
   into the workspace box; a limited command re-bases the offset (``origin``) so the
   compensator never winds up against a limit.

A trip latches the lane in its safe state: the command holds the position measured at the
trip, the compensator is frozen and no force (handle or reflected) moves the handle, until
the node is activated again. Every trip and every onset of a saturation is a
:class:`SafetyEvent`; the node never raises on bad data.

The law runs as one Warp kernel over all lanes (:mod:`haptic.master.node_kernels`): the
real-time master steps one lane through a recorded CPU launch, the lockstep simulator a whole
sweep, with the same code. The state's arrays are numpy views of the kernel's buffers: change
them in place (``state.faulted[lane] = True``), never rebind them. Each step also reports what
the compensator used (``handle_force_used_N``, ``tool_force_used_N``: saturated and scaled by
the ramp, zero in a faulted lane), which the master sends to the slave so that Ch2 there
integrates exactly the force Ch1 integrated here. ``state.gain_ratio`` (k/k0, 1 at
activation) scales the compensator's inputs: the margin governor's k (master/margin_governor.py).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, fields
from typing import Any, NamedTuple

import numpy as np

from haptic.common.control import passivity_kernel
from haptic.common.model.block_kernels import compensator_arrays
from haptic.common.model.block_layout import CompensatorLayout
from haptic.common.model.lti import DiscreteLTI, Path, combine, discretize
from haptic.common.model.passivity import PassivityPort, PassivitySettings
from haptic.common.model.synthesis import AxisCompensators, synthesize
from haptic.common.model.teleop import TeleopModel
from haptic.common.runtime.replayed_launch import ReplayedLaunch
from haptic.master import node_kernels as kernels
from haptic.master.settings import SafetySettings

AXES = ("x", "y")
COMPENSATOR_INPUTS = ("fh_x", "fh_y", "ft_x", "ft_y")
COMPENSATOR_OUTPUTS = ("vh_x", "vh_y")
_LIMITS = ("handle force", "tool force", "command velocity", "workspace")
#: The Warp device of the node's buffers: the CPU, whose arrays numpy views share.
DEVICE = "cpu"


class SafetyEvent(NamedTuple):
    """One safety event: ``kind`` is ``trip``, ``saturate`` or ``enable``; ``axis`` is
    "x", "y" or ``None`` when it concerns the lane as a whole. Immutable, and a third of a
    frozen dataclass's cost to make (a sweep's unstable lanes make thousands)."""

    step: int
    time_s: float
    lane: int
    kind: str
    reason: str
    axis: str | None = None


@dataclass(eq=False)
class MasterNodeState:
    """Per-lane state of the node (the caller owns it); arrays have the lanes first and are
    views of the kernel's buffers (modify in place, never rebind)."""

    compensator: np.ndarray  # (lanes, n) compensator state
    origin_m: np.ndarray  # (lanes, 2) command offset
    last_command_m: np.ndarray  # (lanes, 2)
    last_position_m: np.ndarray  # (lanes, 2) last finite measured position
    hold_m: np.ndarray  # (lanes, 2) position held in the safe state
    small_force_count: np.ndarray  # (lanes,) consecutive small-force samples
    forces_enabled: np.ndarray  # (lanes,) bool
    ramp_elapsed_s: np.ndarray  # (lanes,)
    force_scale: np.ndarray  # (lanes,) ramp factor applied at the last step, 0..1
    gain_ratio: np.ndarray  # (lanes,) k/k0 the compensator's inputs are scaled by (governor)
    faulted: np.ndarray  # (lanes,) bool
    limiting: np.ndarray  # (lanes, 4, 2) bool: which limit was active at the last step
    command_m: np.ndarray  # (lanes, 2) the last step's command
    handle_force_used_N: np.ndarray  # (lanes, 2) fh the compensator used at the last step
    tool_force_used_N: np.ndarray  # (lanes, 2) ft the compensator used at the last step
    inputs: np.ndarray  # (lanes, 6) the kernel's inputs: fh x y (N), yh x y (m), ft x y (N)
    step: int = 0
    events: list[SafetyEvent] = field(default_factory=list)
    _kernel: Any = field(default=None, repr=False)  # the recorded launch over these buffers
    _trip_code: np.ndarray | None = field(default=None, repr=False)
    _event_bits: np.ndarray | None = field(default=None, repr=False)
    _event_count: np.ndarray | None = field(default=None, repr=False)
    _buffers: tuple = field(default=(), repr=False)  # keeps the Warp arrays alive
    #: The TDPA observer and controller of the handle's port (``tdpa`` mode), else None;
    #: its arrays are views of the passivity kernel's buffers.
    passivity: PassivityPort | None = None
    #: (lanes,) the slave's cumulative handed-over energy received, J (NaN: none yet); the
    #: passivity kernel takes it at every step (``tdpa`` mode).
    peer_energy_J: np.ndarray | None = None
    #: ``tdpa``: the tool's received position in handle coordinates, Ah1^-1 yt_recv (lanes,
    #: 2), m, the drift correction's target (NaN: none yet)
    peer_target_m: np.ndarray | None = None
    _passivity_kernel: Any = field(default=None, repr=False)

    @property
    def lanes(self) -> int:
        """Number of lanes."""
        return self.faulted.shape[0]


def master_compensator(model: TeleopModel,
                       synthesized: Sequence[AxisCompensators] | None = None) -> DiscreteLTI:
    """Ch1 and Ct1 of both axes, Tustin at Ts, as one block: vh = Ch1 fh - Ct1 ft.
    ``synthesized``: the model's compensators where they are already at hand (else they are
    synthesised here)."""
    period_s = model.sample_period_s
    paths = []
    for index, axis in enumerate(synthesize(model) if synthesized is None else synthesized):
        paths.append(Path(discretize(axis.ch1, period_s, "tustin"), source=index, target=index))
        paths.append(Path(discretize(axis.ct1, period_s, "tustin"), source=2 + index,
                          target=index, gain=-1.0))
    return combine(paths, COMPENSATOR_INPUTS, COMPENSATOR_OUTPUTS)


def _warp() -> Any:
    import warp as wp

    wp.config.log_level = wp.LOG_WARNING  # no start-up banner on stdout
    wp.init()
    return wp


class MasterNode:
    """Compensator plus safety layer; :meth:`step` maps (fh, yh, ft_recv) to the command.

    ``compensator``: one block for every lane (:class:`~haptic.common.model.lti.DiscreteLTI`) or
    one per lane (a stacked block whose ``A`` is (lanes, n, n), as the sweep uses).
    """

    def __init__(self, compensator: Any, safety: SafetySettings,
                 passivity: PassivitySettings | None = None,
                 passivity_standby: bool = False) -> None:
        if tuple(compensator.input_names) != COMPENSATOR_INPUTS or (
            tuple(compensator.output_names) != COMPENSATOR_OUTPUTS
        ):
            raise ValueError("compensator must map [fh_x, fh_y, ft_x, ft_y] to [vh_x, vh_y]")
        self.compensator = compensator
        self.safety = safety
        self.period_s = compensator.period_s
        #: ``None``: the paper's scheme; else the TDPA layer's settings (``tdpa`` mode).
        self.passivity = passivity
        #: the TDPA layer is built switched off, for the margin governor to switch on at run
        #: time (``paper`` mode with ``[governor] action = "tdpa"``; master/tick.py)
        self.passivity_standby = bool(passivity_standby and passivity is not None)
        self._workspace_min = np.asarray(safety.workspace_min_m, float)
        self._workspace_max = np.asarray(safety.workspace_max_m, float)
        self._matrices: tuple | None = None
        self._layout: CompensatorLayout | None = None
        self._limits: Any = None
        self._trip_reasons = (
            "non-finite handle force", "non-finite handle position", "non-finite tool force",
            f"handle force beyond {safety.force_trip_N:g} N",
            f"handle speed beyond {safety.velocity_trip_m_per_s:g} m/s",
            "handle outside the workspace")
        limit = safety.force_limit_N
        self._limit_reasons = (
            f"handle force saturated at {limit:g} N", f"tool force saturated at {limit:g} N",
            f"command rate limited to {safety.velocity_limit_m_per_s:g} m/s",
            "command clamped to the workspace")
        #: each ``event_bits`` value's events (:meth:`_event_plan`), decoded once
        self._event_plans: dict[int, tuple[tuple[int, str, str, str | None], ...]] = {}
        # Load (or compile, about 2 s the first time) the kernel now, never inside a tick.
        self._kernel_constants()
        _warp().load_module(kernels.step_kernel(self._layout).module, device=DEVICE)
        if passivity is not None:
            _warp().load_module(passivity_kernel, device=DEVICE)

    @classmethod
    def from_model(cls, model: TeleopModel, safety: SafetySettings,
                   passivity: PassivitySettings | None = None,
                   passivity_standby: bool = False) -> MasterNode:
        """The node for the configured model and safety limits (and TDPA layer, switched off
        until the governor switches it on with ``passivity_standby``)."""
        return cls(master_compensator(model), safety, passivity, passivity_standby)

    def _kernel_constants(self) -> tuple[tuple, Any]:
        """The compensator's matrices as Warp arrays packed in their block layout
        (:attr:`_layout`; L = 1: one block for all lanes) and the limits struct, built once
        per node."""
        if self._matrices is None:
            wp = _warp()
            block = self.compensator
            per_lane = np.ndim(block.A) == 3
            arrays = [np.ascontiguousarray(np.asarray(m, float) if per_lane
                                           else np.asarray(m, float)[None])
                      for m in (block.A, block.B, block.C, block.D)]
            self._layout, packed, _ = CompensatorLayout.of(*arrays)
            self._matrices = (tuple(wp.array(m, dtype=wp.float64, device=DEVICE)
                                    for m in packed), int(per_lane))
            safety = self.safety
            limits = kernels.MasterLimits()
            limits.period_s = self.period_s
            limits.force_limit_N = safety.force_limit_N
            limits.force_trip_N = safety.force_trip_N
            limits.max_command_step_m = safety.velocity_limit_m_per_s * self.period_s
            limits.velocity_trip_m_per_s = safety.velocity_trip_m_per_s
            limits.workspace_min_x_m, limits.workspace_min_y_m = map(float,
                                                                     self._workspace_min)
            limits.workspace_max_x_m, limits.workspace_max_y_m = map(float,
                                                                     self._workspace_max)
            limits.workspace_trip_margin_m = safety.workspace_trip_margin_m
            limits.ramp_small_force_N = safety.ramp_small_force_N
            limits.ramp_small_samples = int(safety.ramp_small_samples)
            limits.ramp_time_s = safety.ramp_time_s
            self._limits = limits
        return self._matrices, self._limits

    def initial_state(self, position_m: np.ndarray) -> MasterNodeState:
        """A new state for lanes starting at ``position_m`` (lanes, 2), m, as :meth:`activate`
        leaves one: the command holds that position, forces are not yet enabled, a lane whose
        position is not finite is tripped. It allocates the Warp buffers and records the
        launches (about twenty arrays: make it before the real-time loop; :meth:`activate` and
        :meth:`resume` then set it afresh in place)."""
        position = np.array(np.atleast_2d(position_m), float)
        lanes = position.shape[0]
        (matrices, per_lane), limits = self._kernel_constants()
        if per_lane and matrices[0].shape[0] != lanes:
            raise ValueError(f"compensator stacked for {matrices[0].shape[0]} lanes, "
                             f"activated with {lanes}")
        state = self._new_state(np.nan_to_num(position), matrices, per_lane, limits)
        self._trip_non_finite(state, position, None)
        return state

    def activate(self, state: MasterNodeState, position_m: np.ndarray,
                 lanes: np.ndarray | None = None, continue_run: bool = False) -> None:
        """Start ``lanes`` of ``state`` afresh, in place, at ``position_m`` (lanes, 2), m: the
        command holds that position, the compensator is zero, forces are not yet enabled; a
        lane whose position is not finite is tripped. No Warp buffer is allocated and no
        launch recorded (the real-time loop's activation: the state's own are reused).

        ``lanes`` None: the whole state, its step count and events included, and its
        passivity port (whose monotone counters and switch carry on with ``continue_run``: a
        renewal within a run); a (lanes,) bool mask: those lanes' rows only, an event of
        theirs at the state's current step (the passivity port carries on as it is)."""
        position = np.array(np.atleast_2d(position_m), float)
        if position.shape[0] != state.lanes:
            raise ValueError(f"cannot activate a state of {state.lanes} lanes for "
                             f"{position.shape[0]}")
        safe = np.nan_to_num(position)
        if lanes is None:
            self._reinitialise(state, safe, continue_run)
        else:
            self._reinitialise_rows(state, safe, np.asarray(lanes, bool))
        self._trip_non_finite(state, position, lanes)

    def _trip_non_finite(self, state: MasterNodeState, position_m: np.ndarray,
                         lanes: np.ndarray | None) -> None:
        """Trip ``lanes`` (None: all) whose activation position (lanes, 2) is not finite."""
        faulted_at_start = ~np.all(np.isfinite(position_m), axis=1)
        if lanes is not None:
            faulted_at_start &= lanes
        for lane in np.flatnonzero(faulted_at_start):
            self._trip(state, lane, "non-finite handle position at activation", None)

    def _new_state(self, safe: np.ndarray, matrices: tuple, per_lane: int,
                   limits: Any) -> MasterNodeState:
        """A state at ``safe`` (lanes, 2), m (finite): its Warp buffers, the recorded launch
        over them and this node's constants (``matrices``, ``per_lane``, ``limits``), and the
        passivity port where configured."""
        wp = _warp()
        lanes = safe.shape[0]
        n = self._layout.blocks * self._layout.block_states  # the packed layout's states

        def buffer(shape: tuple, dtype: Any, value: np.ndarray | None = None) -> Any:
            array = wp.zeros(shape, dtype=dtype, device=DEVICE)
            if value is not None:
                array.numpy()[...] = value
            return array

        f64, i32 = wp.float64, wp.int32
        compensator = buffer((lanes, n), f64)
        origin, last_command = buffer((lanes, 2), f64, safe), buffer((lanes, 2), f64, safe)
        last_position, hold = buffer((lanes, 2), f64, safe), buffer((lanes, 2), f64, safe)
        small_count = buffer((lanes,), i32)
        enabled = buffer((lanes,), wp.bool)
        ramp_elapsed, force_scale = buffer((lanes,), f64), buffer((lanes,), f64)
        gain_ratio = buffer((lanes,), f64, np.ones(lanes))
        faulted = buffer((lanes,), wp.bool)
        limiting = buffer((lanes, len(_LIMITS), 2), wp.bool)
        command = buffer((lanes, 2), f64, safe)
        used = buffer((lanes, 4), f64)
        inputs = buffer((lanes, 6), f64)
        trip_code = buffer((lanes,), i32)
        event_bits = buffer((lanes,), i32)
        event_count = buffer((2,), i32)  # lanes with an event, lanes that tripped
        buffers = (inputs, *matrices, compensator, origin, last_command,
                   last_position, hold, small_count, enabled, ramp_elapsed, force_scale,
                   gain_ratio, faulted, limiting, command, used, trip_code, event_bits,
                   event_count)
        launch = wp.launch(kernels.step_kernel(self._layout), dim=lanes, device=DEVICE,
                           inputs=[inputs, compensator_arrays(matrices, per_lane, compensator),
                                   origin, last_command, last_position, hold, small_count,
                                   enabled,
                                   ramp_elapsed, force_scale, gain_ratio, faulted, limiting,
                                   command, used,
                                   trip_code, event_bits, event_count, limits],
                           record_cmd=True)
        used_view = used.numpy()
        state = MasterNodeState(
            compensator=compensator.numpy(), origin_m=origin.numpy(),
            last_command_m=last_command.numpy(), last_position_m=last_position.numpy(),
            hold_m=hold.numpy(), small_force_count=small_count.numpy(),
            forces_enabled=enabled.numpy(), ramp_elapsed_s=ramp_elapsed.numpy(),
            force_scale=force_scale.numpy(), gain_ratio=gain_ratio.numpy(),
            faulted=faulted.numpy(),
            limiting=limiting.numpy(), command_m=command.numpy(),
            handle_force_used_N=used_view[:, 0:2], tool_force_used_N=used_view[:, 2:4],
            inputs=inputs.numpy(), _kernel=ReplayedLaunch(launch), _trip_code=trip_code.numpy(),
            _event_bits=event_bits.numpy(), _event_count=event_count.numpy(),
            _buffers=buffers,
        )
        if self.passivity is not None:
            self._attach_passivity(state, safe, (inputs, enabled, faulted, command, last_command,
                                                 origin))
        return state

    def resume(self, state: MasterNodeState, position_m: np.ndarray,
               lanes: np.ndarray | None = None, reason: str = "link resynchronised",
               continue_run: bool = False) -> None:
        """Start ``lanes`` afresh after a link outage, in place, at ``position_m`` (lanes, 2),
        m: like :meth:`activate` (same ``lanes`` and ``continue_run``; command holds the
        position, compensator zero), but the forces ramp in over ``ramp_time_s`` at once
        instead of waiting for small-force samples: the operator may be pushing through the
        outage, and the ramp alone keeps the force from jumping. One ``enable`` event per
        healthy lane."""
        self.activate(state, position_m, lanes, continue_run)
        healthy = ~state.faulted if lanes is None else np.asarray(lanes, bool) & ~state.faulted
        state.forces_enabled[healthy] = True
        state.small_force_count[healthy] = self.safety.ramp_small_samples
        time_s = state.step * self.period_s
        for lane in np.flatnonzero(healthy):
            state.events.append(SafetyEvent(state.step, time_s, int(lane), "enable",
                                            f"forces ramp in over {self.safety.ramp_time_s:g} s "
                                            f"({reason})"))

    def _reinitialise(self, state: MasterNodeState, safe_m: np.ndarray,
                      continue_run: bool) -> None:
        """``state``'s buffers set to what :meth:`initial_state` gives at ``safe_m`` (lanes,
        2), m (finite); the compensator's matrices and the recorded launches are kept (they
        are this node's). ``continue_run``: the passivity port's ``sent_J``, ``peer_sent_J``
        and ``active`` are kept (the peer keeps seeing ``sent_J`` grow)."""
        for held in (state.origin_m, state.last_command_m, state.last_position_m,
                     state.hold_m, state.command_m):
            held[...] = safe_m
        for cleared in (state.compensator, state.small_force_count, state.forces_enabled,
                        state.ramp_elapsed_s, state.force_scale, state.faulted, state.limiting,
                        state.handle_force_used_N, state.tool_force_used_N, state.inputs,
                        state._trip_code, state._event_bits, state._event_count):
            cleared[...] = 0
        state.gain_ratio[...] = 1.0
        state.step = 0
        state.events = []
        port = state.passivity
        if port is not None:
            kept = (port.sent_J, port.peer_sent_J, port.active) if continue_run else ()
            for item in fields(port):
                value = getattr(port, item.name)
                if isinstance(value, np.ndarray) and not any(value is k for k in kept):
                    value[...] = 0
            if not continue_run:
                port.active[...] = not self.passivity_standby
            port.previous_position_m[...] = safe_m
            state.peer_energy_J[...] = np.nan
            state.peer_target_m[...] = np.nan

    def _reinitialise_rows(self, state: MasterNodeState, safe_m: np.ndarray,
                           lanes: np.ndarray) -> None:
        """The rows of ``lanes`` ((lanes,) bool) of every per-lane array of ``state`` set to
        what :meth:`initial_state` gives at ``safe_m`` (lanes, 2), m; the passivity port is
        left as it is."""
        for held in (state.origin_m, state.last_command_m, state.last_position_m,
                     state.hold_m, state.command_m):
            held[lanes] = safe_m[lanes]
        for cleared in (state.compensator, state.small_force_count, state.forces_enabled,
                        state.ramp_elapsed_s, state.force_scale, state.faulted, state.limiting,
                        state.handle_force_used_N, state.tool_force_used_N, state.inputs):
            cleared[lanes] = 0
        state.gain_ratio[lanes] = 1.0
        if state.peer_energy_J is not None:
            state.peer_energy_J[lanes] = np.nan
        if state.peer_target_m is not None:
            state.peer_target_m[lanes] = np.nan

    def trip(self, state: MasterNodeState, lanes: np.ndarray, reason: str) -> None:
        """Put ``lanes`` (bool mask or indices) in the safe state for an outside reason
        (a drive fault, a missing PDO); an event records ``reason``."""
        for lane in np.flatnonzero(_mask(lanes, len(state.faulted))):
            self._trip(state, int(lane), reason, None)

    def _trip(self, state: MasterNodeState, lane: int, reason: str, axis: str | None) -> None:
        if state.faulted[lane]:
            return
        state.faulted[lane] = True
        state.hold_m[lane] = state.last_position_m[lane]
        state.events.append(SafetyEvent(state.step, state.step * self.period_s, int(lane),
                                        "trip", reason, axis))

    def step(
        self,
        state: MasterNodeState,
        handle_force_N: np.ndarray,
        handle_position_m: np.ndarray,
        tool_force_recv_N: np.ndarray,
        peer_energy_J: np.ndarray | None = None,
    ) -> np.ndarray:
        """One period: returns the handle position command (lanes, 2), m, always finite.

        ``handle_force_N``: fh measured by the sensor (N); ``handle_position_m``: yh from
        the encoders (m); ``tool_force_recv_N``: the tool force received from the slave (N),
        zero when there is none; ``peer_energy_J`` (lanes,): the slave's cumulative input
        energy received (``tdpa`` mode; ignored otherwise).
        """
        inputs = state.inputs
        inputs[:, 0:2] = handle_force_N
        inputs[:, 2:4] = handle_position_m
        inputs[:, 4:6] = tool_force_recv_N
        if peer_energy_J is not None and state.peer_energy_J is not None:
            state.peer_energy_J[...] = peer_energy_J
        return self.step_inputs(state).copy()

    def step_inputs(self, state: MasterNodeState) -> np.ndarray:
        """One period on the inputs already written to ``state.inputs`` (lanes, 6: fh x y in
        N, yh x y in m, ft x y in N); returns ``state.command_m`` (lanes, 2), m, a view the
        next step overwrites. The real-time tick writes its six numbers and calls this."""
        state._kernel.launch()
        if state._passivity_kernel is not None:  # TDPA at the handle's port
            state._passivity_kernel.launch()
        if state._event_count[0]:
            self._collect_events(state)
        state.step += 1
        return state.command_m

    def _attach_passivity(self, state: MasterNodeState, position: np.ndarray,
                          node_buffers: tuple) -> None:
        """The TDPA port of ``state``: its arrays as views of Warp buffers, and the recorded
        launch of :mod:`haptic.common.control.passivity_kernel` over them and the node's buffers."""
        wp = _warp()
        lanes = position.shape[0]
        buffers: list = []
        types = {np.float64: wp.float64, np.int64: wp.int64, np.bool_: wp.bool}

        def zeros(shape: tuple, dtype: Any) -> np.ndarray:
            array = wp.zeros(shape, dtype=types[dtype], device=DEVICE)
            buffers.append(array)
            return array.numpy()

        settings = self.passivity
        port = PassivityPort.create(settings, self.period_s, lanes, settings.master_keep_J,
                                    zeros, active=not self.passivity_standby)
        port.previous_position_m[...] = position
        peer = wp.full(lanes, wp.float64(np.nan), dtype=wp.float64, device=DEVICE)
        limits = passivity_kernel.PassivityLimits()
        limits.period_s = self.period_s
        limits.force_limit_N = self.safety.force_limit_N
        limits.force_floor_N = settings.force_floor_N
        limits.conductance_max_m_per_N_s = settings.conductance_max_m_per_N_s
        limits.correction_speed_max_m_per_s = settings.correction_speed_max_m_per_s
        limits.correction_accel_max_m_per_s2 = settings.correction_accel_max_m_per_s2
        limits.credit_max_J = settings.credit_max_J
        limits.keep_J = settings.master_keep_J
        limits.workspace_min_x_m, limits.workspace_min_y_m = map(float, self._workspace_min)
        limits.workspace_max_x_m, limits.workspace_max_y_m = map(float, self._workspace_max)
        limits.drift_rate_per_s = settings.master_drift_rate_per_s
        limits.drift_speed_max_m_per_s = settings.master_drift_speed_max_m_per_s
        inputs, enabled, faulted, command, last_command, origin = node_buffers
        target = wp.full((lanes, 2), wp.float64(np.nan), dtype=wp.float64, device=DEVICE)
        # PassivityPort's field order: tank, sent, peer_sent, input, output, forgotten,
        # dissipated, correction, (damper force), active steps, previous position.
        tank, sent, peer_sent, energy_in, energy_out, forgotten, dissipated, correction = (
            buffers[:8])
        state.passivity = port
        state.peer_energy_J = peer.numpy()
        state.peer_target_m = target.numpy()
        state._passivity_kernel = ReplayedLaunch(wp.launch(
            passivity_kernel.master_passivity_kernel, dim=lanes, device=DEVICE,
            inputs=[inputs, peer, target, enabled, faulted, command, last_command, origin,
                    buffers[10], tank, sent, peer_sent, energy_in, energy_out, forgotten,
                    dissipated, correction, buffers[9], buffers[11], limits], record_cmd=True))
        state._buffers = (*state._buffers, *buffers, peer, target)

    def _collect_events(self, state: MasterNodeState) -> None:
        """Turn the kernel's event codes into :class:`SafetyEvent` in the safety layer's
        order: trips, handle and tool force saturation, the gate opening, rate, workspace."""
        counts = state._event_count
        trips = counts[1]
        counts[0] = counts[1] = 0
        step, time_s = state.step, state.step * self.period_s
        codes, bits = state._trip_code, state._event_bits
        events = state.events
        if trips:
            tripped = np.flatnonzero(codes >= 0)
            for lane, code in sorted(zip(tripped.tolist(), codes[tripped].tolist(), strict=True),
                                     key=lambda pair: (pair[1] // 2, pair[0])):
                events.append(SafetyEvent(step, time_s, lane, "trip",
                                          self._trip_reasons[code // 2], AXES[code % 2]))
        flagged = np.flatnonzero(bits)
        if not flagged.size:
            return
        # each flagged lane's value (a Python int) looked up in the plans; with several lanes,
        # a stable sort by the layer's order keeps the lanes, then the axes, ascending
        plans = self._event_plans
        lanes, values = flagged.tolist(), bits[flagged].tolist()
        if len(lanes) == 1:
            lane, value = lanes[0], values[0]
            plan = plans.get(value) or self._new_event_plan(value)
            events.extend([SafetyEvent(step, time_s, lane, kind, reason, axis)
                           for _, kind, reason, axis in plan])
            return
        found = [(rank, lane, kind, reason, axis)
                 for lane, value in zip(lanes, values, strict=True)
                 for rank, kind, reason, axis in plans.get(value) or self._new_event_plan(value)]
        found.sort(key=_rank)
        events.extend([SafetyEvent(step, time_s, lane, kind, reason, axis)
                       for _, lane, kind, reason, axis in found])

    def _new_event_plan(self, value: int) -> tuple[tuple[int, str, str, str | None], ...]:
        """:meth:`_event_plan` of ``value``, kept for the next lane with that value."""
        plan = self._event_plans[value] = self._event_plan(value)
        return plan

    def _event_plan(self, value: int) -> tuple[tuple[int, str, str, str | None], ...]:
        """The events one lane's ``event_bits`` value stands for, as (rank in the safety
        layer's order, kind, reason, axis): handle and tool force saturation, the gate
        opening, rate, workspace; x before y."""
        plan: list[tuple[int, str, str, str | None]] = []
        for rank, which in enumerate((0, 1, "enable", 2, 3)):
            if which == "enable":
                if value >> kernels.ENABLE_BIT & 1:
                    plan.append((rank, "enable", "forces enabled after "
                                 f"{self.safety.ramp_small_samples} small-force samples", None))
                continue
            for axis in (0, 1):
                if value >> (2 * which + axis) & 1:
                    plan.append((rank, "saturate", self._limit_reasons[which], AXES[axis]))
        return tuple(plan)


def _rank(found: tuple) -> int:
    """The sort key of :meth:`MasterNode._collect_events`' entries: their rank."""
    return found[0]


def _mask(lanes: np.ndarray, count: int) -> np.ndarray:
    lanes = np.asarray(lanes)
    if lanes.dtype == bool:
        return lanes
    mask = np.zeros(count, bool)
    mask[lanes.astype(int)] = True
    return mask
