"""Model-mediated teleoperation (Mitra and Niemeyer 2008; Xu, Steinbach et al.): the slave
estimates the local model of what its tool touches and sends it; the master renders that
model at once, whatever the delay; the slave's tool tracks the handle. The numpy references
of :mod:`haptic.common.control.mmt_kernel`.

**Estimator (slave)**, per axis: in contact (``|f| >= contact_force_N``, left when ``|f| <
release_force_N``; ``f`` the force the tool applies to its environment, N) a recursive least
squares with forgetting ``lam`` fits ``f = k (x - x0) + b v + f0`` (stiffness ``k`` N/m,
damping ``b`` N s/m, the force ``f0`` at the anchor ``x0``, the position where contact began)::

    K = P phi / (lam + phi' P phi),  theta += K (f - phi' theta),  P = (P - K phi' P) / lam

with ``phi = (x - x0, v, 1)``, then ``k`` clamped to ``[stiffness_min, stiffness_max]``,
``b`` to ``[0, damping_max]``, ``f0`` to the force limit, and ``P`` scaled down when its trace
exceeds ``covariance_trace_max`` (no wind-up while the motion excites nothing). A touch
with no model on its side starts one from the prior ``(stiffness_prior, 0, f)`` and ``P0``.
Leaving contact keeps the model (the surface is still there: the master, ahead of the tool by
the round trip, must keep feeling it, or it falls through and the tool bounces between touch
and release); a touch on the model's side resumes its estimate. The model is dropped only when
the tool, not touching, is inside the modelled surface by more than ``surface_tolerance_m``:
the surface is not where the model says. The fit skips samples whose force reached
``force_limit_N`` (clamped, they no longer fit). A sample with a non-finite field changes
nothing.

**The model on the wire**, per axis: :data:`MODEL_FIELDS`: ``stiffness_N_per_m``,
``damping_N_s_per_m``, ``contact_position_m`` (``xc = x0 - f0 / k``, where the spring's force
is zero) and ``contact_side`` (+1 or -1: the direction the tool pushes into the environment;
0: no contact, nothing to render).

**Renderer (master)**, per axis: the handle is commanded as a virtual mass ``M`` with damping
``B`` driven by the operator's force ``fh``; inside the model (penetration ``p = side (x -
xc) > 0``) the environment pushes back with ``side max(0, k p + b side v)`` (a wall never
pulls). The step is implicit Euler in everything (the force at the new position and
velocity), so for a constant model the operator's work ``sum fh dx`` always covers the change
of ``M v^2 / 2 + k p^2 / 2``: the rendering is passive at any period (the implicit solve has
three cases: free, inside, stopped on the surface). A received model with a non-finite or
out-of-range field is ignored (the last one stays). The rendered surface never jumps into the
handle: a new contact (a side where none or the other was) that finds the handle already
inside (it moved on, unaware, while the touch travelled back a round trip) starts its surface
at the handle, and the rendered surface moves towards the received one at most
``surface_rate_m_per_s``; rendering the received surface at once would hand the operator
``k p^2 / 2`` in one period (at 0.8 s round trip and 0.1 m/s, p is 7 cm: 5 J at 2 kN/m).
Arrays are (lanes, 2): x and y.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

MODEL_FIELDS = ("stiffness_N_per_m", "damping_N_s_per_m", "contact_position_m", "contact_side")


class EnvironmentModel(NamedTuple):
    """The estimated model over lanes, each (lanes, 2) (see the module's docstring)."""

    stiffness_N_per_m: np.ndarray
    damping_N_s_per_m: np.ndarray
    contact_position_m: np.ndarray
    contact_side: np.ndarray

    @classmethod
    def none(cls, lanes: int) -> EnvironmentModel:
        """No contact anywhere."""
        return cls(*(np.zeros((lanes, 2)) for _ in MODEL_FIELDS))

    def to_fields(self, lane: int) -> dict[str, list[float]]:
        """One lane's model as message fields (x, y lists of floats)."""
        return {name: [float(v) for v in getattr(self, name)[lane]] for name in MODEL_FIELDS}

    @classmethod
    def from_fields(cls, fields: dict[str, list[float]]) -> EnvironmentModel:
        """A one-lane model from message fields (the renderer screens the values)."""
        return cls(*(np.array([fields[name]], dtype=float) for name in MODEL_FIELDS))


@dataclass(frozen=True)
class EstimatorSettings:
    """The slave's estimator and tracking (SI units in the names)."""

    period_s: float
    forgetting_factor: float = 0.999
    contact_force_N: float = 0.3
    release_force_N: float = 0.15
    stiffness_prior_N_per_m: float = 1000.0
    stiffness_min_N_per_m: float = 10.0
    stiffness_max_N_per_m: float = 1e5
    damping_max_N_s_per_m: float = 500.0
    initial_covariance: tuple[float, float, float] = (1e8, 1e4, 1e2)
    covariance_trace_max: float = 1e9
    tracking_gain_per_s: float = 50.0
    force_limit_N: float = 40.0
    speed_limit_m_per_s: float = 1.0
    surface_tolerance_m: float = 0.001

    def __post_init__(self) -> None:
        if not 0.0 < self.forgetting_factor <= 1.0:
            raise ValueError("forgetting_factor must be in (0, 1]")
        if not 0.0 < self.release_force_N <= self.contact_force_N:
            raise ValueError("0 < release_force_N <= contact_force_N is required")
        if not 0.0 < self.stiffness_min_N_per_m <= self.stiffness_max_N_per_m:
            raise ValueError("0 < stiffness_min_N_per_m <= stiffness_max_N_per_m is required")
        if self.surface_tolerance_m < 0.0:
            raise ValueError("surface_tolerance_m must be >= 0")


@dataclass(eq=False)
class EstimatorState:
    """The slave's estimator over lanes: per axis ``theta`` (lanes, 2, 3) = (k, b, f0),
    ``covariance`` (lanes, 2, 3, 3), ``anchor_m`` and ``side`` (the model's, 0: none)
    (lanes, 2), the last received handle position and velocity (lanes, 2), and ``touching``
    (lanes, 2): 1 while the tool presses (the contact hysteresis), else 0."""

    theta: np.ndarray
    covariance: np.ndarray
    anchor_m: np.ndarray
    side: np.ndarray
    handle_position_m: np.ndarray
    handle_velocity_m_per_s: np.ndarray
    touching: np.ndarray

    @classmethod
    def create(cls, start_m: np.ndarray) -> EstimatorState:
        """No contact; the handle where the tool is."""
        start = np.array(start_m, dtype=float)
        lanes = start.shape[0]
        return cls(np.zeros((lanes, 2, 3)), np.zeros((lanes, 2, 3, 3)), np.zeros((lanes, 2)),
                   np.zeros((lanes, 2)), start.copy(), np.zeros((lanes, 2)),
                   np.zeros((lanes, 2)))


def _rls_update(settings: EstimatorSettings, theta: np.ndarray, covariance: np.ndarray,
                phi: tuple[np.ndarray, np.ndarray, np.ndarray], force: np.ndarray,
                update: np.ndarray) -> None:
    """One RLS step on the entries where ``update`` (element formulas in the kernel's order)."""
    lam = settings.forgetting_factor
    p = covariance
    p_phi = [p[..., i, 0] * phi[0] + p[..., i, 1] * phi[1] + p[..., i, 2] * phi[2]
             for i in range(3)]
    denominator = lam + (phi[0] * p_phi[0] + phi[1] * p_phi[1] + phi[2] * p_phi[2])
    gain = [p_phi[i] / denominator for i in range(3)]
    error = force - (theta[..., 0] * phi[0] + theta[..., 1] * phi[1] + theta[..., 2] * phi[2])
    phi_p = [phi[0] * p[..., 0, j] + phi[1] * p[..., 1, j] + phi[2] * p[..., 2, j]
             for j in range(3)]
    new_p = np.empty_like(p)
    for i in range(3):
        for j in range(3):
            new_p[..., i, j] = (p[..., i, j] - gain[i] * phi_p[j]) / lam
    trace = new_p[..., 0, 0] + new_p[..., 1, 1] + new_p[..., 2, 2]
    scale = np.where(trace > settings.covariance_trace_max,
                     settings.covariance_trace_max / np.where(trace > 0.0, trace, 1.0), 1.0)
    new_p = new_p * scale[..., None, None]
    k = np.clip(theta[..., 0] + gain[0] * error, settings.stiffness_min_N_per_m,
                settings.stiffness_max_N_per_m)
    b = np.clip(theta[..., 1] + gain[1] * error, 0.0, settings.damping_max_N_s_per_m)
    f0 = np.clip(theta[..., 2] + gain[2] * error, -settings.force_limit_N,
                 settings.force_limit_N)
    new_theta = np.stack([k, b, f0], axis=-1)
    theta[...] = np.where(update[..., None], new_theta, theta)
    covariance[...] = np.where(update[..., None, None], new_p, covariance)


def _contact_transition(settings: EstimatorSettings, state: EstimatorState, sample: np.ndarray,
                        x: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Touch, release, a new model or a dropped one (see the module's docstring), in place;
    returns where the estimate takes this sample: touching, not a model just started, the
    force under ``force_limit_N`` (a clamped force no longer fits the spring: fed to the fit it
    drags the estimate off, and the model the master renders with it)."""
    magnitude = np.abs(f)
    was = state.touching != 0.0
    leave = sample & was & (magnitude < settings.release_force_N)
    start = sample & ~was & (magnitude >= settings.contact_force_N)
    touching = np.where(leave, False, np.where(start, True, was))
    # a touch on a side without a model starts one, anchoring the prior at this sample
    new = start & (state.side != np.sign(f))
    in_model = state.side != 0.0
    safe_k = np.where(in_model, state.theta[..., 0], 1.0)
    depth = state.side * (x - (state.anchor_m - state.theta[..., 2] / safe_k))
    drop = sample & ~touching & in_model & (depth > settings.surface_tolerance_m)
    state.touching[...] = np.where(touching, 1.0, 0.0)
    state.side[...] = np.where(drop, 0.0, np.where(new, np.sign(f), state.side))
    state.anchor_m[...] = np.where(new, x, state.anchor_m)
    prior = np.stack([np.full_like(f, settings.stiffness_prior_N_per_m), np.zeros_like(f), f],
                     axis=-1)
    state.theta[...] = np.where((new | drop)[..., None],
                                np.where(new[..., None], prior, 0.0), state.theta)
    initial = np.diag(np.asarray(settings.initial_covariance, dtype=float))
    state.covariance[...] = np.where(new[..., None, None], initial,
                                     np.where(drop[..., None, None], 0.0, state.covariance))
    return sample & touching & ~new & (magnitude < settings.force_limit_N)


def estimator_step_reference(settings: EstimatorSettings, state: EstimatorState,
                             tool_position_m: np.ndarray, tool_velocity_m_per_s: np.ndarray,
                             tool_force_N: np.ndarray, handle_position_m: np.ndarray,
                             handle_velocity_m_per_s: np.ndarray, fresh: np.ndarray
                             ) -> tuple[np.ndarray, EnvironmentModel]:
    """One period of the slave over lanes: (the tool's velocity command m/s (lanes, 2), the
    model to send); ``state`` advances in place."""
    x, v = tool_position_m, tool_velocity_m_per_s
    f = np.clip(np.where(np.isfinite(tool_force_N), tool_force_N, 0.0),
                -settings.force_limit_N, settings.force_limit_N)
    sample = np.isfinite(x) & np.isfinite(v) & np.isfinite(tool_force_N)
    x = np.where(sample, x, 0.0)
    v = np.where(sample, v, 0.0)
    update = _contact_transition(settings, state, sample, x, f)
    phi = (x - state.anchor_m, v, np.ones_like(x))
    _rls_update(settings, state.theta, state.covariance, phi, f, update)
    # the tool tracks the newest usable handle state
    take = (np.asarray(fresh, bool)[:, None] & np.isfinite(handle_position_m)
            & np.isfinite(handle_velocity_m_per_s)).all(axis=1)[:, None]
    state.handle_position_m[...] = np.where(take, handle_position_m, state.handle_position_m)
    state.handle_velocity_m_per_s[...] = np.where(take, handle_velocity_m_per_s,
                                                  state.handle_velocity_m_per_s)
    limit = settings.speed_limit_m_per_s
    command = state.handle_velocity_m_per_s + settings.tracking_gain_per_s * (
        state.handle_position_m - x)
    command = np.clip(np.where(sample, command, 0.0), -limit, limit)
    return command, current_model(state)


def current_model(state: EstimatorState) -> EnvironmentModel:
    """The model the estimator's state describes (``xc = x0 - f0 / k``; k >= its minimum)."""
    k = state.theta[..., 0]
    in_contact = state.side != 0.0
    safe_k = np.where(in_contact, k, 1.0)
    position = np.where(in_contact, state.anchor_m - state.theta[..., 2] / safe_k, 0.0)
    return EnvironmentModel(np.where(in_contact, k, 0.0),
                            np.where(in_contact, state.theta[..., 1], 0.0), position,
                            state.side.copy())


@dataclass(frozen=True)
class RendererSettings:
    """The master's virtual handle and the bounds on what it accepts (SI units)."""

    period_s: float
    handle_mass_kg: float = 0.2
    handle_damping_N_s_per_m: float = 2.0
    force_limit_N: float = 40.0
    stiffness_max_N_per_m: float = 1e5
    damping_max_N_s_per_m: float = 500.0
    position_limit_m: float = 1.0
    surface_rate_m_per_s: float = 0.05

    def __post_init__(self) -> None:
        if not (self.period_s > 0.0 and self.handle_mass_kg > 0.0):
            raise ValueError("period_s and handle_mass_kg must be > 0")
        if self.surface_rate_m_per_s <= 0.0:
            raise ValueError("surface_rate_m_per_s must be > 0")
        if self.handle_damping_N_s_per_m < 0.0:
            raise ValueError("handle_damping_N_s_per_m must be >= 0")


@dataclass(eq=False)
class RendererState:
    """The master's virtual handle (position m, velocity m/s), the model it renders (its
    ``contact_position_m`` the rendered surface) and the received surface the rendered one
    moves towards, ``target_position_m``, each (lanes, 2)."""

    position_m: np.ndarray
    velocity_m_per_s: np.ndarray
    stiffness_N_per_m: np.ndarray
    damping_N_s_per_m: np.ndarray
    contact_position_m: np.ndarray
    contact_side: np.ndarray
    target_position_m: np.ndarray

    @classmethod
    def create(cls, start_m: np.ndarray) -> RendererState:
        """At rest at ``start_m`` (lanes, 2), nothing to render."""
        start = np.array(start_m, dtype=float)
        return cls(start.copy(), *(np.zeros_like(start) for _ in range(6)))


def _usable_model(settings: RendererSettings, model: EnvironmentModel) -> np.ndarray:
    """Per (lane, axis): every field finite and in range, the side -1, 0 or +1."""
    k, b, xc, side = model
    return (np.isfinite(k) & np.isfinite(b) & np.isfinite(xc) & np.isfinite(side)
            & (k >= 0.0) & (k <= settings.stiffness_max_N_per_m) & (b >= 0.0)
            & (b <= settings.damping_max_N_s_per_m) & (np.abs(xc) <= settings.position_limit_m)
            & ((side == 0.0) | (side == 1.0) | (side == -1.0)))


def _take_model(settings: RendererSettings, state: RendererState, model: EnvironmentModel,
                take: np.ndarray) -> None:
    """Take the received model where ``take``; a new contact's surface starts at the handle
    when the handle is inside it; the rendered surface then moves towards the received one at
    most ``surface_rate_m_per_s``."""
    k, b, xc, side = (np.where(take, value, 0.0) for value in model)
    new = take & (side != 0.0) & (side != state.contact_side)
    inside = side * (state.position_m - xc) > 0.0
    state.contact_position_m[...] = np.where(new, np.where(inside, state.position_m, xc),
                                             state.contact_position_m)
    state.stiffness_N_per_m[...] = np.where(take, k, state.stiffness_N_per_m)
    state.damping_N_s_per_m[...] = np.where(take, b, state.damping_N_s_per_m)
    state.contact_side[...] = np.where(take, side, state.contact_side)
    state.target_position_m[...] = np.where(take, xc, state.target_position_m)
    step = settings.surface_rate_m_per_s * settings.period_s
    state.contact_position_m[...] = state.contact_position_m + np.clip(
        state.target_position_m - state.contact_position_m, -step, step)


def renderer_step_reference(settings: RendererSettings, state: RendererState,
                            handle_force_N: np.ndarray, model: EnvironmentModel,
                            fresh: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One period of the master over lanes: (position command m, velocity m/s, the model's
    force on the handle N), each (lanes, 2); ``state`` advances in place."""
    take = _usable_model(settings, model) & np.asarray(fresh, bool)[:, None]
    _take_model(settings, state, model, take)
    ts, mass = settings.period_s, settings.handle_mass_kg
    fh = np.clip(np.where(np.isfinite(handle_force_N), handle_force_N, 0.0),
                 -settings.force_limit_N, settings.force_limit_N)
    x, v = state.position_m, state.velocity_m_per_s
    k, b = state.stiffness_N_per_m, state.damping_N_s_per_m
    xc, side = state.contact_position_m, state.contact_side
    free = (mass * v + ts * fh) / (mass + ts * settings.handle_damping_N_s_per_m)
    inside_free = (side != 0.0) & (side * (x + ts * free - xc) > 0.0)
    pressed = (mass * v + ts * (fh - k * (x - xc))) / (
        mass + ts * settings.handle_damping_N_s_per_m + ts * b + ts * ts * k)
    pressed_depth = side * (x + ts * pressed - xc)
    pressed_force = k * pressed_depth + b * side * pressed
    surface = (xc - x) / ts
    velocity = np.where(~inside_free, free, np.where(
        pressed_depth > 0.0, np.where(pressed_force >= 0.0, pressed, free), surface))
    contact_force = fh - settings.handle_damping_N_s_per_m * velocity - mass * (
        velocity - v) / ts
    on_handle = np.where(~inside_free, 0.0, np.where(
        pressed_depth > 0.0, np.where(pressed_force >= 0.0, -side * pressed_force, 0.0),
        -contact_force))
    state.velocity_m_per_s[...] = velocity
    state.position_m[...] = np.clip(x + ts * velocity, -settings.position_limit_m,
                                    settings.position_limit_m)
    return state.position_m.copy(), velocity.copy(), on_handle


__all__ = ["MODEL_FIELDS", "EnvironmentModel", "EstimatorSettings", "EstimatorState",
           "RendererSettings", "RendererState", "current_model", "estimator_step_reference",
           "renderer_step_reference"]
