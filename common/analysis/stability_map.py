"""Stability over a grid of gains k and round-trip delays, and the analytic boundary."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from haptic.common.analysis.report import AnalysisSettings, axis_loop
from haptic.common.analysis.stability import delay_margin, is_stable
from haptic.common.model.teleop import TeleopModel


@dataclass(frozen=True)
class StabilityMap:
    """Verdicts on a (k, delay) grid: ``stable[i, j]`` for ``gains_k[i]`` and
    ``delays_s[j]`` (every axis stable), and the delay margin per gain (s; inf when no
    delay up to the search limit destabilises it)."""

    gains_k: np.ndarray
    delays_s: np.ndarray
    stable: np.ndarray
    delay_margin_s: np.ndarray


def delay_margin_curve(model: TeleopModel, gains_k: np.ndarray,
                       settings: AnalysisSettings) -> np.ndarray:
    """The round-trip delay margin (s, worst axis) for each gain; inf where none."""
    margins = np.full(len(gains_k), np.inf)
    for index, gain in enumerate(gains_k):
        for axis in model.axes:
            margin = delay_margin(axis_loop(model, axis, float(gain), settings),
                                  settings.max_delay_s, settings.grid).delay_margin_s
            if margin is not None:
                margins[index] = min(margins[index], margin)
    return margins


def stability_map(model: TeleopModel, gains_k: np.ndarray, delays_s: np.ndarray,
                  settings: AnalysisSettings) -> StabilityMap:
    """Evaluate every cell with the argument principle (not only the boundary)."""
    stable = np.ones((len(gains_k), len(delays_s)), bool)
    for i, gain in enumerate(gains_k):
        loops = [axis_loop(model, axis, float(gain), settings) for axis in model.axes]
        for j, delay in enumerate(delays_s):
            stable[i, j] = all(is_stable(loop, float(delay), settings.grid) for loop in loops)
    return StabilityMap(np.asarray(gains_k, float), np.asarray(delays_s, float), stable,
                        delay_margin_curve(model, gains_k, settings))
