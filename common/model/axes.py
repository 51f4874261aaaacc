"""The model's data: one :class:`AxisModel` per axis (handle, operator, tool, environment) and
the :class:`TeleopModel` holding both with the sampling period and Ch1 (SI units in the field
names). Built from a configuration by :func:`haptic.common.model.teleop.model_from_config`."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import control
import numpy as np

from haptic.common.model.errors import ConfigError
from haptic.common.model.transfer import tf

AXES = ("x", "y")


@dataclass(frozen=True)
class AxisModel:
    """One axis of the handle-operator-tool-environment model (units in the field names)."""

    name: str
    handle_actuator_gh: control.TransferFunction  # position command (m) -> position (m)
    handle_compliance_sh: control.TransferFunction  # m/N
    tool_compliance_st: control.TransferFunction  # m/N
    operator_impedance_th_N_per_m: np.ndarray  # polynomial in s
    environment_impedance_tt_N_per_m: np.ndarray  # polynomial in s
    tool_mass_kg: float
    tool_damping_N_s_per_m: float
    tool_stiffness_N_per_m: float
    position_ratio_ah1: float  # yt = Ah1 yh, dimensionless
    force_ratio_ah2: float  # ft = Ah2 fh^e, dimensionless
    #: Denominator of a rational Tt (polynomial in s; [1]: Tt is the polynomial above), e.g.
    #: the clay's contact linearised about steady cutting (common/model/clay_contact.py).
    environment_impedance_den: np.ndarray = field(default_factory=lambda: np.ones(1))

    @property
    def tool_actuator_gt(self) -> control.TransferFunction:
        """Gt = 1/(Mt s^2 + Bt s + Kt), actuator force (N) -> tool position (m) (eq 5)."""
        return tf([1.0], [self.tool_mass_kg, self.tool_damping_N_s_per_m,
                          self.tool_stiffness_N_per_m])

    def with_environment(self, impedance_N_per_m: np.ndarray,
                         denominator: np.ndarray | None = None) -> AxisModel:
        """A copy with another environment impedance Tt (e.g. the clay as B s): the
        polynomial ``impedance_N_per_m`` over ``denominator`` (default 1)."""
        return replace(self, environment_impedance_tt_N_per_m=np.asarray(impedance_N_per_m, float),
                       environment_impedance_den=np.ones(1) if denominator is None
                       else np.asarray(denominator, float))


@dataclass(frozen=True)
class TeleopModel:
    """The whole model: the sampling period, the master compensator Ch1 and both axes."""

    sample_period_s: float
    ch1_gain_k: float
    ch1_num: np.ndarray
    ch1_den: np.ndarray
    axes: tuple[AxisModel, ...]

    @property
    def ch1(self) -> control.TransferFunction:
        """Ch1 = k num/den: handle force (N) -> handle position command (m), m/N."""
        return tf(self.ch1_gain_k * self.ch1_num, self.ch1_den)

    def with_gain(self, gain_k: float) -> TeleopModel:
        """A copy with another Ch1 gain k."""
        if not gain_k > 0.0 or not np.isfinite(gain_k):
            raise ConfigError("model.ch1.gain_k", f"must be a finite number > 0 (got {gain_k})")
        return replace(self, ch1_gain_k=float(gain_k))

    def axis(self, name: str) -> AxisModel:
        """The axis called ``name`` ("x" or "y")."""
        for axis in self.axes:
            if axis.name == name:
                return axis
        raise KeyError(name)
