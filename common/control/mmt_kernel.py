"""The Warp kernels of model-mediated teleoperation (:mod:`haptic.common.control.mmt`, the
numpy references): the slave's estimator and tracking, and the master's renderer; every lane
in one launch, one thread per lane, both axes.

tests/common/control/test_mmt.py runs each against its reference on the same inputs,
non-finite ones included.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from haptic.common.control.mmt import (
    EnvironmentModel,
    EstimatorSettings,
    EstimatorState,
    RendererSettings,
    RendererState,
)
from haptic.common.control.warp_lanes import DEVICE, LaneBuffers, warp

wp.config.log_level = wp.LOG_WARNING


@wp.struct
class EstimatorLimits:
    """The estimator's settings as the kernel reads them (SI)."""

    forgetting_factor: wp.float64
    contact_force_N: wp.float64
    release_force_N: wp.float64
    stiffness_prior_N_per_m: wp.float64
    stiffness_min_N_per_m: wp.float64
    stiffness_max_N_per_m: wp.float64
    damping_max_N_s_per_m: wp.float64
    initial_covariance: wp.vec3d
    covariance_trace_max: wp.float64
    tracking_gain_per_s: wp.float64
    force_limit_N: wp.float64
    speed_limit_m_per_s: wp.float64
    surface_tolerance_m: wp.float64


@wp.struct
class RendererLimits:
    """The renderer's settings as the kernel reads them (SI)."""

    period_s: wp.float64
    handle_mass_kg: wp.float64
    handle_damping_N_s_per_m: wp.float64
    force_limit_N: wp.float64
    stiffness_max_N_per_m: wp.float64
    damping_max_N_s_per_m: wp.float64
    position_limit_m: wp.float64
    surface_rate_m_per_s: wp.float64


@wp.func
def clamped_force(force: wp.float64, limit: wp.float64) -> wp.float64:
    """A measured force as the laws use it: 0 when non-finite, clamped."""
    if not wp.isfinite(force):
        return wp.float64(0.0)
    return wp.clamp(force, -limit, limit)


@wp.func
def rls_update(lane: int, axis: int, phi: wp.vec3d, force: wp.float64,
               theta: wp.array3d(dtype=wp.float64), covariance: wp.array4d(dtype=wp.float64),
               limits: EstimatorLimits):
    """One recursive least squares step with forgetting, bounds and the covariance cap."""
    lam = limits.forgetting_factor
    p_phi = wp.vec3d()
    phi_p = wp.vec3d()
    for i in range(3):
        p_phi[i] = (covariance[lane, axis, i, 0] * phi[0] + covariance[lane, axis, i, 1] * phi[1]
                    + covariance[lane, axis, i, 2] * phi[2])
        phi_p[i] = (phi[0] * covariance[lane, axis, 0, i] + phi[1] * covariance[lane, axis, 1, i]
                    + phi[2] * covariance[lane, axis, 2, i])
    denominator = lam + (phi[0] * p_phi[0] + phi[1] * p_phi[1] + phi[2] * p_phi[2])
    gain = wp.vec3d()
    for i in range(3):
        gain[i] = p_phi[i] / denominator
    error = force - (theta[lane, axis, 0] * phi[0] + theta[lane, axis, 1] * phi[1]
                     + theta[lane, axis, 2] * phi[2])
    new_p = wp.mat33d()
    for i in range(3):
        for j in range(3):
            new_p[i, j] = (covariance[lane, axis, i, j] - gain[i] * phi_p[j]) / lam
    trace = new_p[0, 0] + new_p[1, 1] + new_p[2, 2]
    scale = wp.float64(1.0)
    if trace > limits.covariance_trace_max:
        scale = limits.covariance_trace_max / trace
    for i in range(3):
        for j in range(3):
            covariance[lane, axis, i, j] = new_p[i, j] * scale
    theta[lane, axis, 0] = wp.clamp(theta[lane, axis, 0] + gain[0] * error,
                                    limits.stiffness_min_N_per_m, limits.stiffness_max_N_per_m)
    theta[lane, axis, 1] = wp.clamp(theta[lane, axis, 1] + gain[1] * error, wp.float64(0.0),
                                    limits.damping_max_N_s_per_m)
    theta[lane, axis, 2] = wp.clamp(theta[lane, axis, 2] + gain[2] * error,
                                    -limits.force_limit_N, limits.force_limit_N)


@wp.func
def new_model(lane: int, axis: int, position: wp.float64, force: wp.float64,
              side: wp.array2d(dtype=wp.float64), anchor: wp.array2d(dtype=wp.float64),
              theta: wp.array3d(dtype=wp.float64), covariance: wp.array4d(dtype=wp.float64),
              limits: EstimatorLimits):
    """A model on the side of ``force``, anchored here, from the prior."""
    zero = wp.float64(0.0)
    if force > zero:
        side[lane, axis] = wp.float64(1.0)
    else:
        side[lane, axis] = wp.float64(-1.0)
    anchor[lane, axis] = position
    theta[lane, axis, 0] = limits.stiffness_prior_N_per_m
    theta[lane, axis, 1] = zero
    theta[lane, axis, 2] = force
    for i in range(3):
        for j in range(3):
            covariance[lane, axis, i, j] = zero
        covariance[lane, axis, i, i] = limits.initial_covariance[i]


@wp.func
def contact_transition(lane: int, axis: int, sample: bool, position: wp.float64,
                       force: wp.float64, side: wp.array2d(dtype=wp.float64),
                       touching: wp.array2d(dtype=wp.float64),
                       anchor: wp.array2d(dtype=wp.float64),
                       theta: wp.array3d(dtype=wp.float64),
                       covariance: wp.array4d(dtype=wp.float64),
                       limits: EstimatorLimits) -> bool:
    """Touch or release; a touch on a side without a model starts one; the tool inside the
    model's surface beyond the tolerance without touching drops it. True when the estimate
    takes this sample (touching, not a model just started, the force under its limit)."""
    zero = wp.float64(0.0)
    one = wp.float64(1.0)
    if not sample:
        return False
    magnitude = wp.abs(force)
    if touching[lane, axis] != zero:
        if magnitude < limits.release_force_N:
            touching[lane, axis] = zero
    elif magnitude >= limits.contact_force_N:
        touching[lane, axis] = one
        sign = -one
        if force > zero:
            sign = one
        if side[lane, axis] != sign:
            new_model(lane, axis, position, force, side, anchor, theta, covariance, limits)
            return False
    if touching[lane, axis] != zero:
        return magnitude < limits.force_limit_N
    if side[lane, axis] != zero:
        surface = anchor[lane, axis] - theta[lane, axis, 2] / theta[lane, axis, 0]
        if side[lane, axis] * (position - surface) > limits.surface_tolerance_m:
            side[lane, axis] = zero
            for i in range(3):
                theta[lane, axis, i] = zero
                for j in range(3):
                    covariance[lane, axis, i, j] = zero
    return False


@wp.kernel
def mmt_estimator_kernel(
    tool_position: wp.array2d(dtype=wp.float64),
    tool_velocity: wp.array2d(dtype=wp.float64),
    tool_force: wp.array2d(dtype=wp.float64),
    handle_position_in: wp.array2d(dtype=wp.float64),
    handle_velocity_in: wp.array2d(dtype=wp.float64),
    fresh: wp.array(dtype=wp.bool),
    theta: wp.array3d(dtype=wp.float64),
    covariance: wp.array4d(dtype=wp.float64),
    anchor: wp.array2d(dtype=wp.float64),
    side: wp.array2d(dtype=wp.float64),
    handle_position: wp.array2d(dtype=wp.float64),
    handle_velocity: wp.array2d(dtype=wp.float64),
    touching: wp.array2d(dtype=wp.float64),
    command: wp.array2d(dtype=wp.float64),
    model: wp.array3d(dtype=wp.float64),
    limits: EstimatorLimits,
):
    """One period of one lane: contact, estimate, tracking command, the model to send."""
    lane = wp.tid()
    zero = wp.float64(0.0)
    take = fresh[lane]
    for axis in range(2):
        take = take and wp.isfinite(handle_position_in[lane, axis])
        take = take and wp.isfinite(handle_velocity_in[lane, axis])
    for axis in range(2):
        raw_x = tool_position[lane, axis]
        raw_v = tool_velocity[lane, axis]
        raw_f = tool_force[lane, axis]
        f = clamped_force(raw_f, limits.force_limit_N)
        sample = wp.isfinite(raw_x) and wp.isfinite(raw_v) and wp.isfinite(raw_f)
        x = zero
        v = zero
        if sample:
            x = raw_x
            v = raw_v
        if contact_transition(lane, axis, sample, x, f, side, touching, anchor, theta,
                              covariance, limits):
            rls_update(lane, axis, wp.vec3d(x - anchor[lane, axis], v, wp.float64(1.0)), f,
                       theta, covariance, limits)
        if take:
            handle_position[lane, axis] = handle_position_in[lane, axis]
            handle_velocity[lane, axis] = handle_velocity_in[lane, axis]
        out = zero
        if sample:
            out = handle_velocity[lane, axis] + limits.tracking_gain_per_s * (
                handle_position[lane, axis] - x)
        command[lane, axis] = wp.clamp(out, -limits.speed_limit_m_per_s,
                                       limits.speed_limit_m_per_s)
        if side[lane, axis] != zero:
            k = theta[lane, axis, 0]
            model[0, lane, axis] = k
            model[1, lane, axis] = theta[lane, axis, 1]
            model[2, lane, axis] = anchor[lane, axis] - theta[lane, axis, 2] / k
        else:
            model[0, lane, axis] = zero
            model[1, lane, axis] = zero
            model[2, lane, axis] = zero
        model[3, lane, axis] = side[lane, axis]


@wp.func
def usable_model(k: wp.float64, b: wp.float64, xc: wp.float64, side: wp.float64,
                 limits: RendererLimits) -> bool:
    """Every field finite and in range, the side -1, 0 or +1."""
    ok = wp.isfinite(k) and wp.isfinite(b) and wp.isfinite(xc) and wp.isfinite(side)
    ok = ok and k >= wp.float64(0.0) and k <= limits.stiffness_max_N_per_m
    ok = ok and b >= wp.float64(0.0) and b <= limits.damping_max_N_s_per_m
    ok = ok and wp.abs(xc) <= limits.position_limit_m
    return ok and (side == wp.float64(0.0) or side == wp.float64(1.0)
                   or side == wp.float64(-1.0))


@wp.kernel
def mmt_renderer_kernel(
    handle_force: wp.array2d(dtype=wp.float64),
    model_in: wp.array3d(dtype=wp.float64),
    fresh: wp.array(dtype=wp.bool),
    position: wp.array2d(dtype=wp.float64),
    velocity: wp.array2d(dtype=wp.float64),
    model: wp.array3d(dtype=wp.float64),
    target: wp.array2d(dtype=wp.float64),
    on_handle: wp.array2d(dtype=wp.float64),
    limits: RendererLimits,
):
    """One period of one lane: take a usable model (a new contact's surface at the handle
    when the handle is inside it), move the rendered surface towards the received one at the
    bounded rate, then the implicit step of the virtual handle against it (free, pressed in,
    or stopped on the surface)."""
    lane = wp.tid()
    ts = limits.period_s
    mass = limits.handle_mass_kg
    damping = limits.handle_damping_N_s_per_m
    zero = wp.float64(0.0)
    step = limits.surface_rate_m_per_s * ts
    for axis in range(2):
        x = position[lane, axis]
        if fresh[lane] and usable_model(model_in[0, lane, axis], model_in[1, lane, axis],
                                        model_in[2, lane, axis], model_in[3, lane, axis],
                                        limits):
            side_in = model_in[3, lane, axis]
            surface_in = model_in[2, lane, axis]
            if side_in != zero and side_in != model[3, lane, axis]:
                if side_in * (x - surface_in) > zero:
                    model[2, lane, axis] = x
                else:
                    model[2, lane, axis] = surface_in
            model[0, lane, axis] = model_in[0, lane, axis]
            model[1, lane, axis] = model_in[1, lane, axis]
            model[3, lane, axis] = side_in
            target[lane, axis] = surface_in
        model[2, lane, axis] = model[2, lane, axis] + wp.clamp(
            target[lane, axis] - model[2, lane, axis], -step, step)
        k = model[0, lane, axis]
        b = model[1, lane, axis]
        xc = model[2, lane, axis]
        side = model[3, lane, axis]
        fh = clamped_force(handle_force[lane, axis], limits.force_limit_N)
        v = velocity[lane, axis]
        free = (mass * v + ts * fh) / (mass + ts * damping)
        out = free
        force = zero
        if side != zero and side * (x + ts * free - xc) > zero:
            pressed = (mass * v + ts * (fh - k * (x - xc))) / (
                mass + ts * damping + ts * b + ts * ts * k)
            depth = side * (x + ts * pressed - xc)
            pushed = k * depth + b * side * pressed
            if depth > zero:
                if pushed >= zero:
                    out = pressed
                    force = -side * pushed
            else:
                out = (xc - x) / ts
                force = -(fh - damping * out - mass * (out - v) / ts)
        velocity[lane, axis] = out
        position[lane, axis] = wp.clamp(x + ts * out, -limits.position_limit_m,
                                        limits.position_limit_m)
        on_handle[lane, axis] = force


class EstimatorKernel:
    """The slave's estimator and tracking over lanes on the Warp kernel; :attr:`state` is an
    :class:`EstimatorState` of numpy views of the kernel's buffers."""

    _STATE = ("theta", "covariance", "anchor_m", "side", "handle_position_m",
              "handle_velocity_m_per_s", "touching")
    _INPUTS = ("tool_position", "tool_velocity", "tool_force", "handle_position_in",
               "handle_velocity_in")

    def __init__(self, settings: EstimatorSettings, start_m: np.ndarray) -> None:
        wp = warp()
        limits = EstimatorLimits()
        for name in ("forgetting_factor", "contact_force_N", "release_force_N",
                     "stiffness_prior_N_per_m", "stiffness_min_N_per_m",
                     "stiffness_max_N_per_m", "damping_max_N_s_per_m", "covariance_trace_max",
                     "tracking_gain_per_s", "force_limit_N", "speed_limit_m_per_s",
                     "surface_tolerance_m"):
            setattr(limits, name, float(getattr(settings, name)))
        limits.initial_covariance = wp.vec3d(*settings.initial_covariance)
        start = EstimatorState.create(start_m)
        self.lanes = start.anchor_m.shape[0]
        self.buffers = LaneBuffers()
        for name in self._INPUTS:
            self.buffers.add(name, np.zeros((self.lanes, 2)))
        self.buffers.add("fresh", np.zeros(self.lanes, bool), wp.bool)
        for name in self._STATE:
            self.buffers.add(name, getattr(start, name))
        self.buffers.add("command", np.zeros((self.lanes, 2)))
        self.buffers.add("model", np.zeros((4, self.lanes, 2)))
        self.state = EstimatorState(*(self.buffers.view[name] for name in self._STATE))
        arrays = self.buffers.arrays
        #: the launch, recorded once over the persistent buffers (a node may replay it)
        self.command = wp.launch(mmt_estimator_kernel, dim=self.lanes, device=DEVICE, inputs=[
            *(arrays[name] for name in (*self._INPUTS, "fresh", *self._STATE)),
            arrays["command"], arrays["model"], limits], record_cmd=True)

    def step(self, tool_position_m: np.ndarray, tool_velocity_m_per_s: np.ndarray,
             tool_force_N: np.ndarray, handle_position_m: np.ndarray,
             handle_velocity_m_per_s: np.ndarray, fresh: np.ndarray
             ) -> tuple[np.ndarray, EnvironmentModel]:
        """One period (see :func:`haptic.common.control.mmt.estimator_step_reference`)."""
        view = self.buffers.view
        for name, value in zip(self._INPUTS, (tool_position_m, tool_velocity_m_per_s,
                                              tool_force_N, handle_position_m,
                                              handle_velocity_m_per_s), strict=True):
            view[name][...] = value
        view["fresh"][...] = fresh
        self.command.launch()
        return view["command"], EnvironmentModel(*view["model"])


class RendererKernel:
    """The master's renderer over lanes on the Warp kernel; :attr:`state` is a
    :class:`RendererState` of numpy views of the kernel's buffers."""

    def __init__(self, settings: RendererSettings, start_m: np.ndarray) -> None:
        wp = warp()
        limits = RendererLimits()
        for name in ("period_s", "handle_mass_kg", "handle_damping_N_s_per_m",
                     "force_limit_N", "stiffness_max_N_per_m", "damping_max_N_s_per_m",
                     "position_limit_m", "surface_rate_m_per_s"):
            setattr(limits, name, float(getattr(settings, name)))
        start = RendererState.create(start_m)
        self.lanes = start.position_m.shape[0]
        self.buffers = LaneBuffers()
        self.buffers.add("handle_force", np.zeros((self.lanes, 2)))
        self.buffers.add("model_in", np.zeros((4, self.lanes, 2)))
        self.buffers.add("fresh", np.zeros(self.lanes, bool), wp.bool)
        self.buffers.add("position", start.position_m)
        self.buffers.add("velocity", start.velocity_m_per_s)
        self.buffers.add("model", np.zeros((4, self.lanes, 2)))
        self.buffers.add("target", np.zeros((self.lanes, 2)))
        self.buffers.add("on_handle", np.zeros((self.lanes, 2)))
        view = self.buffers.view
        self.state = RendererState(view["position"], view["velocity"], *view["model"],
                                   view["target"])
        arrays = self.buffers.arrays
        #: the launch, recorded once over the persistent buffers (a node may replay it)
        self.command = wp.launch(mmt_renderer_kernel, dim=self.lanes, device=DEVICE, inputs=[
            arrays["handle_force"], arrays["model_in"], arrays["fresh"], arrays["position"],
            arrays["velocity"], arrays["model"], arrays["target"], arrays["on_handle"], limits],
            record_cmd=True)

    def step(self, handle_force_N: np.ndarray, model: EnvironmentModel, fresh: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One period (see :func:`haptic.common.control.mmt.renderer_step_reference`)."""
        view = self.buffers.view
        view["handle_force"][...] = handle_force_N
        for field, value in enumerate(model):
            view["model_in"][field] = value
        view["fresh"][...] = fresh
        self.command.launch()
        return view["position"], view["velocity"], view["on_handle"]


__all__ = ["EstimatorKernel", "EstimatorLimits", "RendererKernel", "RendererLimits",
           "mmt_estimator_kernel", "mmt_renderer_kernel"]
