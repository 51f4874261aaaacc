"""The master node: the Ch1/Ct1 compensators behind a safety layer, vectorised over lanes.

Per axis ``vh = Ch1 fh - Ct1 ft_recv`` (Tustin-discretised from :mod:`haptic.common.synthesis`,
one MIMO block with inputs [fh_x, fh_y, ft_x, ft_y] and outputs [vh_x, vh_y]). The
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
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from haptic.common.lti import DiscreteLTI, Path, combine, discretize
from haptic.common.model import TeleopModel
from haptic.common.synthesis import synthesize
from haptic.master.settings import SafetySettings

AXES = ("x", "y")
COMPENSATOR_INPUTS = ("fh_x", "fh_y", "ft_x", "ft_y")
COMPENSATOR_OUTPUTS = ("vh_x", "vh_y")
_LIMITS = ("handle force", "tool force", "command velocity", "workspace")


@dataclass(frozen=True)
class SafetyEvent:
    """One safety event: ``kind`` is ``trip``, ``saturate`` or ``enable``; ``axis`` is
    "x", "y" or ``None`` when it concerns the lane as a whole."""

    step: int
    time_s: float
    lane: int
    kind: str
    reason: str
    axis: str | None = None


@dataclass
class MasterNodeState:
    """Per-lane state of the node (the caller owns it); arrays have the lanes first."""

    compensator: np.ndarray  # (lanes, n) compensator state
    origin_m: np.ndarray  # (lanes, 2) command offset
    last_command_m: np.ndarray  # (lanes, 2)
    last_position_m: np.ndarray  # (lanes, 2) last finite measured position
    hold_m: np.ndarray  # (lanes, 2) position held in the safe state
    small_force_count: np.ndarray  # (lanes,) consecutive small-force samples
    forces_enabled: np.ndarray  # (lanes,) bool
    ramp_elapsed_s: np.ndarray  # (lanes,)
    force_scale: np.ndarray  # (lanes,) ramp factor applied at the last step, 0..1
    faulted: np.ndarray  # (lanes,) bool
    limiting: np.ndarray  # (lanes, 4, 2) bool: which limit was active at the last step
    step: int = 0
    events: list[SafetyEvent] = field(default_factory=list)


def master_compensator(model: TeleopModel) -> DiscreteLTI:
    """Ch1 and Ct1 of both axes, Tustin at Ts, as one block: vh = Ch1 fh - Ct1 ft."""
    period_s = model.sample_period_s
    paths = []
    for index, axis in enumerate(synthesize(model)):
        paths.append(Path(discretize(axis.ch1, period_s, "tustin"), source=index, target=index))
        paths.append(Path(discretize(axis.ct1, period_s, "tustin"), source=2 + index,
                          target=index, gain=-1.0))
    return combine(paths, COMPENSATOR_INPUTS, COMPENSATOR_OUTPUTS)


class MasterNode:
    """Compensator plus safety layer; :meth:`step` maps (fh, yh, ft_recv) to the command."""

    def __init__(self, compensator: DiscreteLTI, safety: SafetySettings) -> None:
        if compensator.input_names != COMPENSATOR_INPUTS or (
            compensator.output_names != COMPENSATOR_OUTPUTS
        ):
            raise ValueError("compensator must map [fh_x, fh_y, ft_x, ft_y] to [vh_x, vh_y]")
        self.compensator = compensator
        self.safety = safety
        self.period_s = compensator.period_s
        self._workspace_min = np.asarray(safety.workspace_min_m, float)
        self._workspace_max = np.asarray(safety.workspace_max_m, float)

    @classmethod
    def from_model(cls, model: TeleopModel, safety: SafetySettings) -> MasterNode:
        """The node for the configured model and safety limits."""
        return cls(master_compensator(model), safety)

    def activate(self, position_m: np.ndarray) -> MasterNodeState:
        """A fresh state for lanes starting at ``position_m`` (lanes, 2): the command holds
        that position, forces are not yet enabled."""
        position = np.array(np.atleast_2d(position_m), float)
        lanes = position.shape[0]
        faulted = ~np.all(np.isfinite(position), axis=1)
        safe = np.nan_to_num(position)
        state = MasterNodeState(
            compensator=self.compensator.initial_state(lanes), origin_m=safe.copy(),
            last_command_m=safe.copy(), last_position_m=safe.copy(), hold_m=safe.copy(),
            small_force_count=np.zeros(lanes, int), forces_enabled=np.zeros(lanes, bool),
            ramp_elapsed_s=np.zeros(lanes), force_scale=np.zeros(lanes),
            faulted=np.zeros(lanes, bool), limiting=np.zeros((lanes, len(_LIMITS), 2), bool),
        )
        for lane in np.flatnonzero(faulted):
            self._trip(state, lane, "non-finite handle position at activation", None)
        return state

    def resume(self, position_m: np.ndarray, reason: str = "link resynchronised") -> (
            MasterNodeState):
        """A fresh state after a link outage, at ``position_m`` (lanes, 2), m: like
        :meth:`activate` (command holds the position, compensator zero), but the forces ramp
        in over ``ramp_time_s`` at once instead of waiting for small-force samples: the
        operator may be pushing through the outage, and the ramp alone keeps the force from
        jumping. One ``enable`` event per healthy lane."""
        state = self.activate(position_m)
        healthy = ~state.faulted
        state.forces_enabled[healthy] = True
        state.small_force_count[healthy] = self.safety.ramp_small_samples
        for lane in np.flatnonzero(healthy):
            state.events.append(SafetyEvent(0, 0.0, int(lane), "enable",
                                            f"forces ramp in over {self.safety.ramp_time_s:g} s "
                                            f"({reason})"))
        return state

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
        state.events.append(SafetyEvent(state.step, state.step * self.period_s, lane, "trip",
                                        reason, axis))

    def step(
        self,
        state: MasterNodeState,
        handle_force_N: np.ndarray,
        handle_position_m: np.ndarray,
        tool_force_recv_N: np.ndarray,
    ) -> np.ndarray:
        """One period: returns the handle position command (lanes, 2), m, always finite.

        ``handle_force_N``: fh measured by the sensor (N); ``handle_position_m``: yh from
        the encoders (m); ``tool_force_recv_N``: the tool force received from the slave (N),
        zero when there is none.
        """
        safety = self.safety
        fh = np.asarray(handle_force_N, float)
        yh = np.asarray(handle_position_m, float)
        ft = np.asarray(tool_force_recv_N, float)
        period = self.period_s

        # 1. Non-finite inputs: the lane trips and holds its last finite position.
        fh_ok, yh_ok, ft_ok = np.isfinite(fh), np.isfinite(yh), np.isfinite(ft)
        if not (fh_ok.all() and yh_ok.all() and ft_ok.all()):
            for name, ok in (("handle force", fh_ok), ("handle position", yh_ok),
                             ("tool force", ft_ok)):
                self._trip_where(state, ~ok, f"non-finite {name}")
        measured = np.where(yh_ok, yh, state.last_position_m)
        velocity = (measured - state.last_position_m) / period
        state.last_position_m[...] = measured
        fh = np.where(fh_ok, fh, 0.0)
        ft = np.where(ft_ok, ft, 0.0)

        # 2. Trips on measured force, speed and position.
        self._trip_where(state, np.abs(fh) > safety.force_trip_N,
                         f"handle force beyond {safety.force_trip_N:g} N")
        self._trip_where(state, np.abs(velocity) > safety.velocity_trip_m_per_s,
                         f"handle speed beyond {safety.velocity_trip_m_per_s:g} m/s")
        margin = safety.workspace_trip_margin_m
        outside = (measured < self._workspace_min - margin) | (
            measured > self._workspace_max + margin)
        self._trip_where(state, outside, "handle outside the workspace")

        # 3. Force saturation.
        limit = safety.force_limit_N
        self._note_limits(state, 0, np.abs(fh) > limit, f"handle force saturated at {limit:g} N")
        self._note_limits(state, 1, np.abs(ft) > limit, f"tool force saturated at {limit:g} N")
        fh = np.minimum(np.maximum(fh, -limit), limit)
        ft = np.minimum(np.maximum(ft, -limit), limit)

        # 4. Force ramp after activation.
        small = np.all(np.abs(fh) < safety.ramp_small_force_N, axis=1)
        waiting = ~state.forces_enabled & ~state.faulted
        state.small_force_count[...] = np.where(small, state.small_force_count + 1, 0)
        opening = waiting & (state.small_force_count >= safety.ramp_small_samples)
        state.forces_enabled |= opening
        for lane in np.flatnonzero(opening) if opening.any() else ():
            state.events.append(SafetyEvent(state.step, state.step * period, int(lane),
                                            "enable", "forces enabled after "
                                            f"{safety.ramp_small_samples} small-force samples"))
        if safety.ramp_time_s > 0.0:
            scale = np.clip(state.ramp_elapsed_s / safety.ramp_time_s, 0.0, 1.0)
        else:
            scale = np.ones_like(state.ramp_elapsed_s)
        scale = np.where(state.forces_enabled, scale, 0.0)
        state.ramp_elapsed_s += np.where(state.forces_enabled, period, 0.0)
        state.force_scale[...] = scale

        # The compensator: a position offset from the origin; frozen in faulted lanes.
        inputs = scale[:, None] * np.concatenate([fh, ft], axis=1)
        any_faulted = bool(state.faulted.any())
        if any_faulted:
            frozen = state.compensator[state.faulted].copy()
        offset = self.compensator.step(state.compensator, inputs)
        if any_faulted:
            state.compensator[state.faulted] = frozen
        raw = state.origin_m + offset

        # 5. Command rate and workspace limits, re-basing the offset when they act.
        max_step = safety.velocity_limit_m_per_s * period
        delta = raw - state.last_command_m
        self._note_limits(state, 2, np.abs(delta) > max_step,
                          f"command rate limited to {safety.velocity_limit_m_per_s:g} m/s")
        command = state.last_command_m + np.minimum(np.maximum(delta, -max_step), max_step)
        outside_box = (command < self._workspace_min) | (command > self._workspace_max)
        self._note_limits(state, 3, outside_box, "command clamped to the workspace")
        command = np.minimum(np.maximum(command, self._workspace_min), self._workspace_max)
        state.origin_m += command - raw

        command = np.where(state.faulted[:, None], state.hold_m, command)
        state.last_command_m[...] = command
        state.step += 1
        return command.copy()

    def _trip_where(self, state: MasterNodeState, condition: np.ndarray, reason: str) -> None:
        if not condition.any():
            return
        for lane, axis in zip(*np.nonzero(condition), strict=True):
            self._trip(state, int(lane), reason, AXES[axis])

    def _note_limits(self, state: MasterNodeState, which: int, active: np.ndarray,
                     reason: str) -> None:
        starting = active & ~state.limiting[:, which, :] & ~state.faulted[:, None]
        state.limiting[:, which, :] = active
        if not starting.any():
            return
        for lane, axis in zip(*np.nonzero(starting), strict=True):
            state.events.append(SafetyEvent(state.step, state.step * self.period_s, int(lane),
                                            "saturate", reason, AXES[axis]))


def _mask(lanes: np.ndarray, count: int) -> np.ndarray:
    lanes = np.asarray(lanes)
    if lanes.dtype == bool:
        return lanes
    mask = np.zeros(count, bool)
    mask[lanes.astype(int)] = True
    return mask
