"""The tool's environment, chosen by name: ``clay`` (the Warp height-field workpiece) or
``linear`` (ft = Tt yt, the model's environment impedance, for comparison with the analysis).

Both give, per step and lane, the force ``ft`` the tool applies to its environment (N, the
environment pushes back with -ft) from the tool's motion over the step. The slave node
calls them the same way and never asks which one it has.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from haptic.common.config import ConfigError
from haptic.common.config.scenario import ENVIRONMENT_KINDS, Scenario
from haptic.common.model.teleop import TeleopModel, polynomial_degree
from haptic.slave_sim.clay.sim import ClayStepResult, make_clay


class LinearEnvironment:
    """ft = Tt yt per axis with Tt = c2 s^2 + c1 s + c0 (N/m): ft = c2 a + c1 v + c0 y.

    Positions are measured from the origin of the work area (the linearisation point), the
    acceleration is the tool's at the end of the step with the actuator force of the step
    held (exact for the ZOH tool plant). The result reports ``cutting`` true, engagement 1,
    no removed volume and ``damping_N_s_per_m`` = c1 of the x axis.
    """

    kind = "linear"

    def __init__(self, model: TeleopModel) -> None:
        coefficients = []
        for axis in model.axes:
            poly = np.asarray(axis.environment_impedance_tt_N_per_m, float)
            if polynomial_degree(poly) > 2:
                raise ConfigError(f"model.{axis.name}.environment_impedance_tt",
                                  "the linear environment takes Tt of degree 2 at most "
                                  "(mass, damping, stiffness)")
            coefficients.append(np.concatenate([np.zeros(3 - poly.size), poly])[-3:])
        #: (3, n_axes): rows are the s^2 (kg), s (N s/m) and 1 (N/m) coefficients.
        self.coefficients = np.array(coefficients).T.copy()
        #: per lane count, the result's constant columns (read-only, made once)
        self._constants: dict[int, tuple[np.ndarray, ...]] = {}

    def initial_state(self, lanes: int = 1) -> None:
        """The linear environment keeps no state."""
        return None

    def step(self, state: Any, previous_xy: np.ndarray, position_xy: np.ndarray,
             velocity_xy: np.ndarray, acceleration_xy: np.ndarray) -> ClayStepResult:
        """ft = Tt yt for every lane (inputs (lanes, 2): m, m/s, m/s^2)."""
        c = self.coefficients
        force = c[0] * acceleration_xy + c[1] * velocity_xy + c[2] * position_xy
        lanes = position_xy.shape[0]
        constants = self._constants.get(lanes)
        if constants is None:
            constants = (np.ones(lanes, bool), np.ones(lanes), np.zeros(lanes),
                         np.full(lanes, c[1, 0]))
            for column in constants:
                column.flags.writeable = False
            self._constants[lanes] = constants
        return ClayStepResult(force, *constants)


class ClayEnvironment:
    """The clay workpiece of a scenario (Warp kernels or the numpy reference)."""

    kind = "clay"

    def __init__(self, scenario: Scenario, sample_period_s: float, impl: str = "warp",
                 device: str = "auto") -> None:
        self.clay = make_clay(scenario, sample_period_s, impl, device)

    def initial_state(self, lanes: int = 1) -> Any:
        """Fresh workpieces for ``lanes`` lanes
        (a :class:`~haptic.slave_sim.clay.sim.ClayState`)."""
        return self.clay.initial_state(lanes)

    def step(self, state: Any, previous_xy: np.ndarray, position_xy: np.ndarray,
             velocity_xy: np.ndarray, acceleration_xy: np.ndarray) -> ClayStepResult:
        """Cut along the tool's move of this step; the acceleration is not used."""
        return self.clay.step(state, previous_xy, position_xy, velocity_xy)


def make_environment(kind: str, model: TeleopModel, scenario: Scenario, impl: str = "warp",
                     device: str = "auto") -> LinearEnvironment | ClayEnvironment:
    """The environment called ``kind`` ("clay" or "linear")."""
    if kind == "clay":
        return ClayEnvironment(scenario, model.sample_period_s, impl, device)
    if kind == "linear":
        return LinearEnvironment(model)
    raise ConfigError("scenario.environment",
                      f"must be one of {', '.join(ENVIRONMENT_KINDS)} (got {kind!r})")
