"""The virtual cutting tool's actuator plant, both axes, discretised by zero-order hold.

Per axis, Gt = 1/(Mt s^2 + Bt s + Kt) (paper eq 5): actuator force vt (N) -> tool position
yt (m), with the clay's nominal viscous damping Bt inside. St = 0 (non-back-drivable), so the
clay force does not move the tool directly. The continuous state [yt, dyt/dt] per axis is
sampled with ZOH (the actuator force is held over each period), which makes the position and
the velocity exact at the sample instants for a force held over the step.
"""

from __future__ import annotations

import control
import numpy as np

from haptic.common.config import ConfigError
from haptic.common.model.lti import DiscreteLTI
from haptic.common.model.teleop import TeleopModel

#: Tool state columns: x position (m), x velocity (m/s), y position (m), y velocity (m/s).
TOOL_STATE_NAMES = ("yt_x", "dyt_x", "yt_y", "dyt_y")
POSITION_COLUMNS = [0, 2]
VELOCITY_COLUMNS = [1, 3]


def tool_plant(model: TeleopModel) -> DiscreteLTI:
    """The ZOH tool plant of both axes: inputs (vt_x, vt_y) N; states and outputs
    (yt_x, dyt_x, yt_y, dyt_y) in m and m/s (C = I, D = 0: no feedthrough)."""
    n_axes = len(model.axes)
    A = np.zeros((2 * n_axes, 2 * n_axes))
    B = np.zeros((2 * n_axes, n_axes))
    for index, axis in enumerate(model.axes):
        if axis.tool_mass_kg <= 0.0:
            raise ConfigError(f"model.{axis.name}.tool_mass_kg",
                              "the slave's tool plant needs a mass > 0 kg (Gt of second order)")
        mass = axis.tool_mass_kg
        continuous = control.ss(
            [[0.0, 1.0], [-axis.tool_stiffness_N_per_m / mass,
                          -axis.tool_damping_N_s_per_m / mass]],
            [[0.0], [1.0 / mass]], np.eye(2), np.zeros((2, 1)),
        )
        sampled = control.sample_system(continuous, model.sample_period_s, method="zoh")
        rows = slice(2 * index, 2 * index + 2)
        A[rows, rows] = np.asarray(sampled.A, float)
        B[rows, index] = np.asarray(sampled.B, float)[:, 0]
    return DiscreteLTI(
        A=A, B=B, C=np.eye(2 * n_axes), D=np.zeros((2 * n_axes, n_axes)),
        period_s=model.sample_period_s,
        input_names=tuple(f"vt_{a.name}" for a in model.axes),
        output_names=TOOL_STATE_NAMES[: 2 * n_axes],
    )


def tool_constants(model: TeleopModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Mt kg, Bt N s/m, Kt N/m) per axis, shape (n_axes,) each."""
    return (np.array([a.tool_mass_kg for a in model.axes]),
            np.array([a.tool_damping_N_s_per_m for a in model.axes]),
            np.array([a.tool_stiffness_N_per_m for a in model.axes]))
