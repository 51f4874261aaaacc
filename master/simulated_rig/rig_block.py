"""The simulated rig as a pure block: both handle axes and the operator, no I/O.

Per axis the handle actuator Gh (eqs 31, 32: position command m -> handle position m, the
servo and the operator's grasp inside) is discretised by zero-order hold at Ts in a state
space that also gives the handle's velocity and acceleration. The operator model
(:mod:`haptic.master.simulated_rig.operator`) supplies the intent force ``uh``; the force the sensor
measures is (eq 33 with the paper's sign convention)::

    fh = uh - Th (yh - y_grasp),   Th = m s^2 + b s + k  (N/m)

evaluated with the handle's position, velocity and acceleration, plus seeded Gaussian noise.

Timing contract (the one a CiA 402 drive in cyclic synchronous position mode has, and the
one the sampled-data analysis models): :meth:`RigModel.step` is called once per SYNC k with
the target latched during cycle k-1. It first advances the plant over [t_{k-1}, t_k) with
the command applied there, then applies the new target for [t_k, t_{k+1}), then samples
position, velocity and acceleration at t_k (the acceleration with the command now
applied) and the operator force. A command computed in cycle k from this sample is passed
to the call at SYNC k+1: zero-order hold plus one sample of computation delay, no
algebraic loop.

The block holds only matrices; :class:`RigState` (owned by the caller) holds the state of
every lane, so a lockstep simulator can step many lanes at once, without CAN. The step runs
as one Warp kernel over the lanes (:mod:`haptic.master.simulated_rig.rig_kernels`), with the
operator
model's law inside it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import control
import numpy as np
import scipy.linalg

from haptic.common.model.teleop import TeleopModel
from haptic.common.runtime.replayed_launch import ReplayedLaunch
from haptic.master.simulated_rig.operator import OperatorModel, OperatorState

AXES = ("x", "y")


def _warp() -> Any:
    import warp as wp

    wp.config.log_level = wp.LOG_WARNING  # no start-up banner on stdout
    wp.init()
    return wp


@dataclass(eq=False)
class RigState:
    """Per-lane rig state (the caller owns it); the arrays are numpy views of the kernel's
    buffers (change them in place, never rebind them).

    ``plant``: (lanes, n) axis states at t_{k-1}; ``applied_command_m``: (lanes, 2) the
    command applied over [t_{k-1}, t_k); ``grasp_position_m``: (lanes, 2) handle position
    where the operator's arm is at rest; ``operator``: the operator model's state; ``rng``:
    the seeded generator for sensor noise. The step's inputs: ``target_m`` (lanes, 2), m
    (NaN: keep the applied command) and ``tool_force_N`` (lanes, 2), N; ``sample`` (lanes, 12)
    the last step's outputs (:data:`~haptic.master.simulated_rig.rig_kernels.SAMPLE_PAIRS`).
    """

    plant: np.ndarray
    applied_command_m: np.ndarray
    grasp_position_m: np.ndarray
    operator: OperatorState
    rng: np.random.Generator
    target_m: np.ndarray | None = None
    tool_force_N: np.ndarray | None = None
    noise_N: np.ndarray | None = None
    sample: np.ndarray | None = None
    kernel: Any = field(default=None, repr=False)  # the recorded launch over these buffers
    buffers: tuple = field(default=(), repr=False)  # keeps the Warp arrays alive


@dataclass(frozen=True)
class RigSample:
    """What the rig's sensors see at t_k, per lane and axis (lanes, 2)."""

    handle_position_m: np.ndarray
    handle_velocity_m_per_s: np.ndarray
    handle_acceleration_m_per_s2: np.ndarray
    operator_intent_force_N: np.ndarray
    handle_force_N: np.ndarray  # noise-free fh = uh - Th y
    handle_force_measured_N: np.ndarray  # fh plus sensor noise


def _zoh(A: np.ndarray, B: np.ndarray, period_s: float) -> tuple[np.ndarray, np.ndarray]:
    n, m = B.shape
    block = np.zeros((n + m, n + m))
    block[:n, :n] = A
    block[:n, n:] = B
    exponential = scipy.linalg.expm(block * period_s)
    return exponential[:n, :n], exponential[:n, n:]


class RigModel:
    """Both handle axes (ZOH-discretised Gh) with the operator, stepped at ``period_s``.

    Parameters
    ----------
    handle_actuators:
        Gh per axis (x, y), strictly proper continuous transfer functions, m/m.
    operator_impedance_N_per_m:
        Th per axis, polynomial in s of degree <= 2, highest power first (N/m).
    period_s:
        Ts, s.
    operator:
        The operator model giving the intent force uh (N).
    force_noise_std_N:
        Standard deviation of the sensor's Gaussian noise per channel, N.
    """

    def __init__(
        self,
        handle_actuators: Sequence[control.TransferFunction],
        operator_impedance_N_per_m: Sequence[Sequence[float]],
        period_s: float,
        operator: OperatorModel,
        force_noise_std_N: float = 0.0,
    ) -> None:
        if len(handle_actuators) != 2 or len(operator_impedance_N_per_m) != 2:
            raise ValueError("one Gh and one Th per axis (x, y) expected")
        self.period_s = float(period_s)
        self.operator = operator
        self.force_noise_std_N = float(force_noise_std_N)
        blocks = [self._axis_blocks(gh, name) for gh, name in zip(handle_actuators, AXES,
                                                                   strict=True)]
        self.handle_actuators = tuple(handle_actuators)
        self.n_states = sum(b["A"].shape[0] for b in blocks)
        n = self.n_states
        self.A = np.zeros((n, n))
        self.B = np.zeros((n, 2))
        self.position_C = np.zeros((2, n))
        self.velocity_C = np.zeros((2, n))
        self.velocity_D = np.zeros(2)
        self.acceleration_C = np.zeros((2, n))
        self.acceleration_D = np.zeros(2)
        self._equilibrium = np.zeros((2, n))  # state per unit held position, per axis
        offset = 0
        for axis, b in enumerate(blocks):
            size = b["A"].shape[0]
            window = slice(offset, offset + size)
            self.A[window, window] = b["A"]
            self.B[window, axis] = b["B"][:, 0]
            self.position_C[axis, window] = b["C"]
            self.velocity_C[axis, window] = b["Cv"]
            self.velocity_D[axis] = b["Dv"]
            self.acceleration_C[axis, window] = b["Ca"]
            self.acceleration_D[axis] = b["Da"]
            self._equilibrium[axis, window] = b["equilibrium"]
            offset += size
        impedance = np.zeros((2, 3))
        for axis, polynomial in enumerate(operator_impedance_N_per_m):
            coefficients = np.trim_zeros(np.asarray(polynomial, float), "f")
            if coefficients.size > 3:
                raise ValueError(f"Th for axis {AXES[axis]} has degree > 2; the rig model "
                                 "gives position, velocity and acceleration only")
            impedance[axis, 3 - coefficients.size:] = coefficients
        #: Th per axis as [mass kg, damping N s/m, stiffness N/m].
        self.operator_impedance = impedance
        self._constants: tuple | None = None
        # Load (or compile, about 2 s the first time) the kernels now, never inside a tick.
        from haptic.master.simulated_rig import rig_kernels

        _warp().load_module(rig_kernels, device="cpu")
        _warp().load_module(rig_kernels.rig_step_kernel(self.n_states).module, device="cpu")

    def _axis_blocks(self, gh: control.TransferFunction, name: str) -> dict[str, np.ndarray]:
        realisation = control.ss(gh)
        A = np.atleast_2d(np.asarray(realisation.A, float))
        B = np.asarray(realisation.B, float).reshape(-1, 1)
        C = np.asarray(realisation.C, float).reshape(1, -1)
        D = float(np.asarray(realisation.D).ravel()[0])
        if D != 0.0 or A.shape[0] == 0:
            raise ValueError(f"Gh for axis {name} must be strictly proper (a servo has no "
                             "direct feedthrough)")
        try:
            equilibrium = -np.linalg.solve(A, B[:, 0])
        except np.linalg.LinAlgError:
            raise ValueError(f"Gh for axis {name} has a pole at s = 0; a position servo "
                             "must hold a position") from None
        dc_gain = float(C[0] @ equilibrium)
        if abs(dc_gain) < 1e-12:
            raise ValueError(f"Gh for axis {name} has zero DC gain")
        Ad, Bd = _zoh(A, B, self.period_s)
        return {
            "A": Ad, "B": Bd, "C": C[0],
            "Cv": (C @ A)[0], "Dv": float((C @ B)[0, 0]),
            "Ca": (C @ A @ A)[0], "Da": float((C @ A @ B)[0, 0]),
            # State that holds position 1 m with the command 1/G(0) held.
            "equilibrium": equilibrium / dc_gain,
        }

    @property
    def dc_gains(self) -> np.ndarray:
        """Gh(0) per axis, m/m."""
        return np.array([float(np.real(control.evalfr(g, 0.0))) for g in self.handle_actuators])

    @classmethod
    def from_model(cls, model: TeleopModel, operator: OperatorModel,
                   force_noise_std_N: float = 0.0) -> RigModel:
        """The rig of the configured model: Gh and Th of axes x, y at the model's Ts."""
        return cls(
            [model.axis(a).handle_actuator_gh for a in AXES],
            [model.axis(a).operator_impedance_th_N_per_m for a in AXES],
            model.sample_period_s, operator, force_noise_std_N,
        )

    def _kernel_constants(self) -> tuple:
        """The matrices as Warp arrays, built once per rig."""
        if self._constants is None:
            wp = _warp()
            outputs_c = np.stack([self.position_C, self.velocity_C, self.acceleration_C])
            outputs_d = np.stack([np.zeros(2), self.velocity_D, self.acceleration_D])
            self._constants = tuple(
                wp.array(np.ascontiguousarray(m), dtype=wp.float64, device="cpu")
                for m in (self.A, self.B, outputs_c, outputs_d, self.operator_impedance))
        return self._constants

    def initial_state(self, position_m: np.ndarray, rng: np.random.Generator) -> RigState:
        """Every lane at rest at ``position_m`` (lanes, 2), holding that position, the
        operator grasping the handle there."""
        from haptic.master.simulated_rig import rig_kernels

        wp = _warp()
        position = np.atleast_2d(np.asarray(position_m, float))
        lanes = position.shape[0]

        def buffer(columns: int, value: np.ndarray | None = None) -> Any:
            array = wp.zeros((lanes, columns), dtype=wp.float64, device="cpu")
            if value is not None:
                array.numpy()[...] = value
            return array

        target = buffer(2, np.nan)
        tool_force, noise = buffer(2), buffer(2)
        plant = buffer(self.n_states, position @ self._equilibrium)
        applied = buffer(2, position / self.dc_gains)
        grasp = buffer(2, position)
        sample = buffer(2 * len(rig_kernels.SAMPLE_PAIRS))
        operator = self.operator.initial_state(lanes)
        launch = wp.launch(rig_kernels.rig_step_kernel(self.n_states), dim=lanes, device="cpu",
                           inputs=[*self._kernel_constants(),
                                   self.operator.kernel_params(self.period_s), self.period_s,
                                   target, tool_force, noise, plant, applied, grasp,
                                   *operator.buffers, sample], record_cmd=True)
        return RigState(plant.numpy(), applied.numpy(), grasp.numpy(), operator, rng,
                        target_m=target.numpy(), tool_force_N=tool_force.numpy(),
                        noise_N=noise.numpy(), sample=sample.numpy(), kernel=ReplayedLaunch(launch),
                        buffers=(target, tool_force, noise, plant, applied, grasp,
                                 sample))

    def step(self, state: RigState, target_m: np.ndarray, tool_force_N: np.ndarray) -> RigSample:
        """One SYNC: advance over the last period, apply ``target_m`` (lanes, 2), sample.

        A non-finite target is ignored per axis (the command applied stays), as a drive
        rejects it. ``tool_force_N`` (lanes, 2) is the tool force the operator feels (used
        by the force-regulating operator only).
        """
        state.target_m[...] = target_m
        state.tool_force_N[...] = tool_force_N
        values = self.step_inputs(state).copy()
        pairs = [values[:, 2 * i:2 * i + 2] for i in range(6)]
        return RigSample(*pairs)

    def step_inputs(self, state: RigState) -> np.ndarray:
        """One SYNC on the inputs already in ``state.target_m`` and ``state.tool_force_N``;
        returns ``state.sample`` (lanes, 12), a view the next step overwrites (columns in
        :data:`~haptic.master.simulated_rig.rig_kernels.SAMPLE_PAIRS` order)."""
        if self.force_noise_std_N > 0.0:
            state.noise_N[...] = self.force_noise_std_N * state.rng.standard_normal(
                state.noise_N.shape)
        state.kernel.launch()
        return state.sample

    def frequency_response(self, omega_rad_s: np.ndarray) -> np.ndarray:
        """The discretised plant's response from held command to sampled position,
        C (e^{j w Ts} I - A)^-1 B, shape (2, len(omega)) complex, per axis."""
        omega = np.atleast_1d(np.asarray(omega_rad_s, float))
        response = np.empty((2, omega.size), complex)
        identity = np.eye(self.n_states)
        for i, w in enumerate(omega):
            z = np.exp(1j * w * self.period_s)
            solved = np.linalg.solve(z * identity - self.A, self.B)
            response[:, i] = np.diag(self.position_C @ solved)
        return response
