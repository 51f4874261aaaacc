"""The benchmark's task environments as pure functions over lanes (docs/architectures.md):
a stiff wall for contact and a free-motion sine reference. Arrays are (lanes, 2) or
(samples, 2): x and y, SI units."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class StiffWall:
    """A one-sided spring and damper wall normal to ``axis`` (0: x, 1: y), its surface at
    ``surface_m``; ``side`` +1: the wall fills the larger coordinates, -1: the smaller ones.
    Inside (penetration ``p = side (x - surface) > 0``) it pushes the tool back with
    ``max(0, k p + b side v)``: it never pulls."""

    surface_m: float
    stiffness_N_per_m: float
    damping_N_s_per_m: float = 0.0
    axis: int = 0
    side: float = 1.0

    def __post_init__(self) -> None:
        if self.stiffness_N_per_m < 0.0 or self.damping_N_s_per_m < 0.0:
            raise ValueError("the wall's stiffness and damping must be >= 0")
        if self.axis not in (0, 1) or self.side not in (1.0, -1.0):
            raise ValueError("axis must be 0 or 1 and side +1 or -1")

    def penetration_m(self, position_m: np.ndarray) -> np.ndarray:
        """How deep the tool is in the wall (0 outside), m, per row of ``position_m``."""
        depth = self.side * (np.asarray(position_m, float)[..., self.axis] - self.surface_m)
        return np.where(np.isfinite(depth), np.maximum(depth, 0.0), 0.0)

    def force_N(self, position_m: np.ndarray, velocity_m_per_s: np.ndarray) -> np.ndarray:
        """The force the wall applies to the tool, N, shaped like ``position_m``; a row with
        a non-finite position or velocity gets none."""
        position = np.asarray(position_m, float)
        rate = self.side * np.asarray(velocity_m_per_s, float)[..., self.axis]
        depth = self.penetration_m(position)
        push = np.where(depth > 0.0, np.maximum(
            self.stiffness_N_per_m * depth + self.damping_N_s_per_m * rate, 0.0), 0.0)
        push = np.where(np.isfinite(push) & np.isfinite(position[..., self.axis]), push, 0.0)
        force = np.zeros_like(position)
        force[..., self.axis] = -self.side * push
        return force


def free_motion_sine(time_s: np.ndarray, amplitude_m: float, frequency_hz: float,
                     axis: int = 0, centre_m: tuple[float, float] = (0.0, 0.0)
                     ) -> tuple[np.ndarray, np.ndarray]:
    """The free-motion task's reference at ``time_s`` (samples,): (position m, velocity m/s),
    each (samples, 2), a sine of ``amplitude_m`` at ``frequency_hz`` along ``axis`` about
    ``centre_m``, starting at the centre and at rest in the other axis."""
    t = np.asarray(time_s, float)
    w = 2.0 * np.pi * frequency_hz
    position = np.tile(np.asarray(centre_m, float), (t.size, 1))
    velocity = np.zeros((t.size, 2))
    position[:, axis] += amplitude_m * np.sin(w * t)
    velocity[:, axis] = amplitude_m * w * np.cos(w * t)
    return position, velocity


__all__ = ["StiffWall", "free_motion_sine"]
