"""The time-domain verdict of a run: bounded or growing, from the force and its energy.

Per lane and axis, over windows of the run (:class:`~haptic.lockstep.simulator.WindowStats`):

- the oscillation amplitude of the handle force in a window, (max - min) / 2 (N): its mean
  does not count, so a steady cutting force is not mistaken for growth;
- the oscillation energy: the variance of the handle force over the window about its
  straight-line trend (N^2), so neither a steady force nor a slow ramp (an operator
  settling on a cutting force) counts as oscillation.

The growth ratios compare the last window with a reference window taken after the
excitation (``reference_start_s``): the amplitude ratio (reported) and the square root of
the energy ratio (the verdict). A lane grows when the energy ratio, on either axis, exceeds
``threshold`` (1: anything that does not decay), or when its signals left the finite
numbers. For a linear loop the ratios are
e^(sigma T) of the dominant mode (sigma its real part, T the time between the windows), so
the threshold 1 puts the verdict exactly on the stability boundary; only a mode so close to
the boundary that it changes by less than rounding over the run can be misjudged.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from haptic.lockstep.simulator import LockstepResult

GROWTH_THRESHOLD = 1.0


@dataclass(frozen=True)
class Verdict:
    """Per lane: ``growing`` (lanes,), the worst ``amplitude_ratio`` and ``energy_ratio``
    over the axes (lanes,), dimensionless."""

    growing: np.ndarray
    amplitude_ratio: np.ndarray
    energy_ratio: np.ndarray


def growth_verdict(result: LockstepResult, reference_start_s: float = 0.25,
                   threshold: float = GROWTH_THRESHOLD) -> Verdict:
    """Bounded or growing for every lane of ``result`` (see the module docstring)."""
    stats = result.stats
    window = stats.window_samples
    counts = np.full(stats.handle_force_sum_N.shape[0], float(window))
    counts[-1] = result.steps - window * (counts.size - 1)
    reference = min(int(round(reference_start_s / (window * result.sample_period_s))),
                    counts.size - 2)
    if reference < 0:
        raise ValueError("the run needs at least two windows")
    last = counts.size - 1
    if counts[last] < window / 2 and last - 1 > reference:
        last -= 1  # a short tail window would understate the amplitude
    amplitude = (stats.handle_force_max_N - stats.handle_force_min_N) / 2.0
    mean = stats.handle_force_sum_N / counts[:, None, None]
    n = counts[:, None, None]
    variance = stats.handle_force_sumsq_N2 / n - mean ** 2
    # Remove the least-squares line over the window's sample index i = 0..n-1.
    index_mean = (n - 1.0) / 2.0
    index_variance = (n * n - 1.0) / 12.0
    covariance = stats.handle_force_moment_N / n - index_mean * mean
    variance = np.maximum(variance - covariance ** 2 / np.maximum(index_variance, 1e-300), 0.0)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        amplitude_ratio = amplitude[last] / np.maximum(amplitude[reference], 1e-300)
        energy_ratio = np.sqrt(variance[last] / np.maximum(variance[reference], 1e-300))
    amplitude_ratio = np.nan_to_num(amplitude_ratio, nan=np.inf).max(axis=1)
    energy_ratio = np.nan_to_num(energy_ratio, nan=np.inf).max(axis=1)
    growing = result.diverged | (energy_ratio > threshold)
    return Verdict(growing, amplitude_ratio, energy_ratio)
