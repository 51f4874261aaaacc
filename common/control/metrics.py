"""The benchmark's figures of a run, as functions over recorded arrays (docs/architectures.md).

Positions and forces are (samples,) or (samples, axes) in SI units; the master's and the
slave's records are in the same coordinates (the caller maps the tool's into the handle's).
A non-finite sample makes a figure non-finite: an unbounded run has no such figure.
"""

from __future__ import annotations

import numpy as np


def _rows(values: np.ndarray) -> np.ndarray:
    """``values`` as (samples, axes)."""
    array = np.asarray(values, float)
    return array[:, None] if array.ndim == 1 else array


def rms_position_error_m(master_m: np.ndarray, slave_m: np.ndarray) -> float:
    """The root mean square of the distance between the two sides' positions, m."""
    gap = _rows(master_m) - _rows(slave_m)
    return float(np.sqrt(np.mean(np.sum(gap * gap, axis=1))))


def rms_force_error_N(operator_force_N: np.ndarray, environment_force_N: np.ndarray) -> float:
    """The root mean square of the difference between the force the operator feels and the
    force at the environment (both in the same sense), N."""
    error = _rows(operator_force_N) - _rows(environment_force_N)
    return float(np.sqrt(np.mean(np.sum(error * error, axis=1))))


def final_position_gap_m(master_m: np.ndarray, slave_m: np.ndarray,
                         final_samples: int = 1) -> float:
    """The distance between the sides' mean positions over the last ``final_samples``, m."""
    if final_samples < 1:
        raise ValueError("final_samples must be >= 1")
    gap = _rows(master_m)[-final_samples:] - _rows(slave_m)[-final_samples:]
    return float(np.linalg.norm(np.mean(gap, axis=0)))


def impact_overshoot_ratio(contact_force_N: np.ndarray, steady_fraction: float = 0.25) -> float:
    """How far the contact force's peak exceeds its settled value, as a share of it:
    ``(max |f| - mean |f| over the last steady_fraction) / that mean``, over a record that
    starts at the impact; NaN when the settled force is 0."""
    if not 0.0 < steady_fraction <= 1.0:
        raise ValueError("steady_fraction must be in (0, 1]")
    magnitude = np.abs(np.asarray(contact_force_N, float))
    if magnitude.ndim > 1:
        magnitude = np.linalg.norm(magnitude, axis=1)
    tail = max(1, int(round(magnitude.size * steady_fraction)))
    steady = float(np.mean(magnitude[-tail:]))
    if steady == 0.0:
        return float("nan")
    return float((np.max(magnitude) - steady) / steady)


def perceived_stiffness_ratio(handle_position_m: np.ndarray, handle_force_N: np.ndarray,
                              wall_stiffness_N_per_m: float, in_contact: np.ndarray) -> float:
    """The stiffness the operator feels over the wall's: the slope of the operator's force
    against the handle's position along the wall's normal (least squares with an offset,
    over the samples ``in_contact``) divided by ``wall_stiffness_N_per_m``. 1 is transparent;
    NaN with fewer than two distinct contact positions or a non-finite contact sample."""
    position = np.asarray(handle_position_m, float)[np.asarray(in_contact, bool)]
    force = np.asarray(handle_force_N, float)[np.asarray(in_contact, bool)]
    if (position.size < 2 or not np.all(np.isfinite(position)) or
            not np.all(np.isfinite(force)) or np.ptp(position) == 0.0):
        return float("nan")
    centred = position - position.mean()
    slope = float(np.sum(centred * (force - force.mean())) / np.sum(centred * centred))
    return abs(slope) / wall_stiffness_N_per_m


__all__ = ["final_position_gap_m", "impact_overshoot_ratio", "perceived_stiffness_ratio",
           "rms_force_error_N", "rms_position_error_m"]
