"""Exact stability of one axis under a round-trip delay, by the argument principle.

``Delta(s, tau) = A(s) + B(s) e^(-s tau)`` is evaluated with the exact delay factor (no Pade
approximation). The number of zeros of Delta in the right half-plane is the number of
clockwise turns Delta makes around the origin while s walks up the line s = sigma + j w
(sigma > 0 tiny, so the integrators at s = 0 stay outside) and back around a large arc in the
right half-plane. The open loop has no right-half-plane poles (the synthesis refuses designs
with any), so the loop is stable iff that count is zero. B is strictly proper here, so the
delay term vanishes at high frequency (a retarded system) and the arc adds nothing new.

Delay margin: roots can cross the imaginary axis only at frequencies where
``|A(jw)| = |B(jw)|``; at such a crossing w_c the delays
``tau = (-arg(-A/B) mod 2 pi + 2 pi m)/w_c``
put a root on the axis. The smallest of these after which the count is non-zero is
the margin. If |A| > |B| at every frequency and the loop is stable without delay, no delay can
destabilise it (delay-independent stability).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from haptic.common.analysis.loop import CONTOUR_SHIFT_1_PER_S, AxisLoop

#: Largest phase step (rad) allowed between neighbouring contour points before refining.
MAX_PHASE_STEP_RAD = 0.5
#: Relative step past a crossing delay at which the root count is re-checked.
CROSSING_CHECK_STEP = 1e-3
#: Lowest frequency of the crossing search, rad/s; below it A and B both grow like 1/w^2
#: with |A| > |B| (docs/model.md, section 5).
LOWEST_FREQUENCY_RAD_S = 1e-3


@dataclass(frozen=True)
class DelayMargin:
    """Delay margin of one axis: the smallest round-trip delay (s) that destabilises the
    loop, ``None`` when no delay up to ``searched_up_to_s`` does."""

    delay_margin_s: float | None
    crossing_frequency_rad_s: float | None
    stable_without_delay: bool
    delay_independent: bool
    searched_up_to_s: float


@dataclass(frozen=True)
class FrequencyGrid:
    """The frequency points (rad/s) on which one axis is analysed."""

    upper_rad_s: float
    points_per_decade: int = 400

    def log_points(self, lower_rad_s: float = 1e-4) -> np.ndarray:
        decades = np.log10(self.upper_rad_s) - np.log10(lower_rad_s)
        return np.logspace(np.log10(lower_rad_s), np.log10(self.upper_rad_s),
                           int(decades * self.points_per_decade) + 1)


def _upper_frequency(loop: AxisLoop, max_frequency_rad_s: float) -> float:
    nyquist = loop.max_frequency_rad_s
    return max_frequency_rad_s if nyquist is None else min(max_frequency_rad_s, nyquist)


def _refined_arg_change(
    evaluate: Callable[[np.ndarray], np.ndarray], parameter: np.ndarray, rounds: int = 16
) -> float:
    """Total change of arg f along a path sampled at ``parameter``, refining where the phase
    jumps by more than MAX_PHASE_STEP_RAD between neighbours. NaN if f hits zero."""
    values = evaluate(parameter)
    for _ in range(rounds):
        if np.any(values == 0) or not np.all(np.isfinite(values)):
            return float("nan")
        steps = np.angle(values[1:] / values[:-1])
        coarse = np.abs(steps) > MAX_PHASE_STEP_RAD
        if not coarse.any():
            return float(np.sum(steps))
        middle = 0.5 * (parameter[:-1][coarse] + parameter[1:][coarse])
        parameter = np.concatenate([parameter, middle])
        values = np.concatenate([values, evaluate(middle)])
        order = np.argsort(parameter, kind="stable")
        parameter, values = parameter[order], values[order]
    steps = np.angle(values[1:] / values[:-1])
    return float(np.sum(steps))


def _delay_grid(loop: AxisLoop, round_trip_delay_s: float, grid: FrequencyGrid) -> np.ndarray:
    """Log grid, plus a linear grid fine enough to follow e^(-j w tau) wherever the delayed
    term is not negligible."""
    points = grid.log_points()
    if round_trip_delay_s <= 0.0:
        return points
    terms = loop.terms(points, CONTOUR_SHIFT_1_PER_S)
    relevant = np.abs(terms.b) > 1e-9 * np.maximum(np.abs(terms.a), 1e-300)
    if not relevant.any():
        return points
    upper = float(points[np.flatnonzero(relevant)[-1]])
    count = min(int(upper * round_trip_delay_s / 0.2) + 2, 2_000_000)
    return np.union1d(points, np.linspace(0.0, upper, count))


def unstable_root_count(
    loop: AxisLoop, round_trip_delay_s: float, grid: FrequencyGrid
) -> int:
    """Number of zeros of Delta(s, tau) in the right half-plane (or outside the unit circle
    for the sampled loop); -1 if a zero sits on the contour (marginal)."""
    upper = _upper_frequency(loop, grid.upper_rad_s)
    bounded = FrequencyGrid(upper, grid.points_per_decade)
    omega = np.concatenate([[0.0], _delay_grid(loop, round_trip_delay_s, bounded)])
    omega = omega[omega <= upper]
    if loop.sampled and omega[-1] < upper:
        omega = np.append(omega, upper)

    def along_axis(w: np.ndarray) -> np.ndarray:
        return loop.terms(w, CONTOUR_SHIFT_1_PER_S).characteristic(round_trip_delay_s)

    change = _refined_arg_change(along_axis, omega)
    if not loop.sampled:
        def along_arc(angle: np.ndarray) -> np.ndarray:
            s = upper * np.exp(-1j * angle)  # angle -pi/2 -> 0 walks j W -> W clockwise
            return loop.terms_at(s).characteristic(round_trip_delay_s)

        change += _refined_arg_change(along_arc, np.linspace(-np.pi / 2, 0.0, 200))
    if not np.isfinite(change):
        return -1
    # The lower half of the contour mirrors the upper half (real coefficients): double it.
    return int(round(-2.0 * change / (2.0 * np.pi)))


def is_stable(loop: AxisLoop, round_trip_delay_s: float, grid: FrequencyGrid) -> bool:
    """True when the loop has no zero in the right half-plane (marginal counts as unstable)."""
    return unstable_root_count(loop, round_trip_delay_s, grid) == 0


def _magnitude_gap(loop: AxisLoop, omega: np.ndarray) -> np.ndarray:
    terms = loop.terms(omega)
    return np.log(np.abs(terms.b)) - np.log(np.abs(terms.a))


def crossing_frequencies(loop: AxisLoop, grid: FrequencyGrid) -> np.ndarray:
    """Frequencies (rad/s) where |A(jw)| = |B(jw)|: the only places a root can cross."""
    upper = _upper_frequency(loop, grid.upper_rad_s)
    omega = FrequencyGrid(upper, grid.points_per_decade).log_points(LOWEST_FREQUENCY_RAD_S)
    with np.errstate(divide="ignore"):
        gap = _magnitude_gap(loop, omega)
    finite = np.isfinite(gap)
    omega, gap = omega[finite], gap[finite]
    changes = np.flatnonzero(np.sign(gap[:-1]) != np.sign(gap[1:]))
    roots = []
    for index in changes:
        low, high = omega[index], omega[index + 1]
        roots.append(brentq(lambda w: float(_magnitude_gap(loop, np.array([w]))[0]), low, high,
                            xtol=1e-12, rtol=1e-12))
    return np.array(roots)


def max_delayed_ratio(loop: AxisLoop, grid: FrequencyGrid) -> tuple[float, float]:
    """The largest |B/A| over frequency and where (rad/s); below 1 means no delay can move a
    root across the imaginary axis."""
    upper = _upper_frequency(loop, grid.upper_rad_s)
    omega = FrequencyGrid(upper, grid.points_per_decade).log_points(LOWEST_FREQUENCY_RAD_S)
    terms = loop.terms(omega)
    ratio = np.abs(terms.b) / np.abs(terms.a)
    worst = int(np.argmax(ratio))
    return float(ratio[worst]), float(omega[worst])


def delay_margin(loop: AxisLoop, max_delay_s: float, grid: FrequencyGrid) -> DelayMargin:
    """The round-trip delay margin of one axis (see the module docstring)."""
    if not is_stable(loop, 0.0, grid):
        return DelayMargin(0.0, None, False, False, max_delay_s)
    crossings = crossing_frequencies(loop, grid)
    if crossings.size == 0:
        return DelayMargin(None, None, True, True, max_delay_s)
    candidates: list[tuple[float, float]] = []
    for omega_c in crossings:
        terms = loop.terms(np.array([omega_c]))
        phase = float(np.angle(-terms.a[0] / terms.b[0]))
        first = np.mod(-phase, 2.0 * np.pi) / omega_c
        period = 2.0 * np.pi / omega_c
        repeats = int(max(0.0, max_delay_s - first) / period) + 1
        candidates.extend((first + m * period, float(omega_c)) for m in range(min(repeats, 200)))
    for tau_c, omega_c in sorted(candidates):
        if tau_c > max_delay_s:
            break
        if not is_stable(loop, tau_c * (1.0 + CROSSING_CHECK_STEP), grid):
            return DelayMargin(float(tau_c), omega_c, True, False, max_delay_s)
    return DelayMargin(None, None, True, False, max_delay_s)
