"""Transfer functions as the model uses them: coefficient lists (highest power first) cleaned
of rounding noise, SISO continuous-time systems built from them, their degrees and values."""

from __future__ import annotations

import control
import numpy as np

#: Coefficients smaller than this fraction of a polynomial's largest are rounding noise.
NEGLIGIBLE_COEFFICIENT = 1e-14


def clean_polynomial(coefficients: list[float] | np.ndarray) -> np.ndarray:
    """Coefficients (highest power first) with negligible ones set to zero and leading
    zeros dropped; the zero polynomial is [0.0]."""
    values = np.atleast_1d(np.asarray(coefficients, float)).copy()
    scale = float(np.max(np.abs(values))) if values.size else 0.0
    values[np.abs(values) < NEGLIGIBLE_COEFFICIENT * scale] = 0.0
    nonzero = np.flatnonzero(values)
    return np.array([0.0]) if nonzero.size == 0 else values[nonzero[0]:]


def tf(num: list[float] | np.ndarray, den: list[float] | np.ndarray) -> control.TransferFunction:
    """A SISO continuous-time transfer function from coefficient lists (highest power first)."""
    return control.tf(clean_polynomial(num), clean_polynomial(den))


def polynomial_degree(coefficients: np.ndarray) -> int:
    """Degree of a polynomial given highest power first; -1 for the zero polynomial."""
    nonzero = np.flatnonzero(np.asarray(coefficients) != 0.0)
    return -1 if nonzero.size == 0 else len(coefficients) - 1 - int(nonzero[0])


def tf_coefficients(system: control.TransferFunction) -> tuple[np.ndarray, np.ndarray]:
    """Numerator and denominator of a SISO transfer function, highest power first."""
    return (
        np.atleast_1d(np.asarray(system.num[0][0], float)),
        np.atleast_1d(np.asarray(system.den[0][0], float)),
    )


def relative_degree(system: control.TransferFunction) -> int | None:
    """deg(den) - deg(num); ``None`` for the zero transfer function."""
    num, den = tf_coefficients(system)
    num_degree = polynomial_degree(num)
    return None if num_degree < 0 else polynomial_degree(den) - num_degree


def evaluate_tf(system: control.TransferFunction, points: np.ndarray) -> np.ndarray:
    """Evaluate a SISO transfer function at complex points (s or z)."""
    num, den = tf_coefficients(system)
    return np.polyval(num, points) / np.polyval(den, points)
