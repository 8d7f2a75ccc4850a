"""The checks every model and filter step shares.

Each raises ``ValueError`` whose message starts with the argument's name, shows
the bad value and says what was expected, so a node can pass the message
straight to its user.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

#: How far a probability vector's sum may stray from 1 (rounding in YAML files).
SUM_TOLERANCE = 1e-9
#: Relative tolerance for symmetry and for the smallest eigenvalue of a covariance.
MATRIX_TOLERANCE = 1e-9


def short(value: Any) -> str:
    """Show a value in an error message without flooding the log."""
    text = np.array2string(np.asarray(value), threshold=12, precision=6)
    return text.replace("\n", "")


def as_finite_array(name: str, value: Any, ndim: int) -> FloatArray:
    """Convert ``value`` to a read-only float array of ``ndim`` dimensions, all finite."""
    try:
        array = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected numbers, got {value!r}") from None
    if array.ndim != ndim:
        raise ValueError(
            f"{name}: expected a {ndim}-dimensional array, got shape {array.shape}"
        )
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name}: expected finite numbers, got {short(array)}")
    array.setflags(write=False)
    return array


def check_finite(name: str, value: float) -> float:
    """Return ``value`` as a float if it is a finite number."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a finite number, got {value!r}") from None
    if not np.isfinite(number):
        raise ValueError(f"{name}: expected a finite number, got {value!r}")
    return number


def check_positive(name: str, value: float) -> float:
    """Return ``value`` as a float if it is finite and strictly positive."""
    number = check_finite(name, value)
    if number <= 0.0:
        raise ValueError(f"{name}: expected a number > 0, got {value!r}")
    return number


def check_probability_vector(name: str, value: Any) -> FloatArray:
    """A non-empty vector of probabilities in [0, 1] that sums to 1."""
    vector = as_finite_array(name, value, ndim=1)
    if vector.size == 0:
        raise ValueError(f"{name}: expected at least one probability, got an empty list")
    if np.any(vector < 0.0) or np.any(vector > 1.0):
        raise ValueError(f"{name}: expected probabilities in [0, 1], got {short(vector)}")
    total = float(vector.sum())
    if abs(total - 1.0) > SUM_TOLERANCE:
        raise ValueError(
            f"{name}: expected probabilities summing to 1, got {short(vector)} (sum {total:.12g})"
        )
    return vector


def check_covariance(name: str, value: Any, size: int) -> FloatArray:
    """A ``size`` x ``size`` symmetric positive semi-definite matrix."""
    matrix = as_finite_array(name, value, ndim=2)
    if matrix.shape != (size, size):
        raise ValueError(f"{name}: expected shape ({size}, {size}), got {matrix.shape}")
    scale = max(1.0, float(np.max(np.abs(matrix))))
    if not np.allclose(matrix, matrix.T, rtol=0.0, atol=MATRIX_TOLERANCE * scale):
        raise ValueError(f"{name}: expected a symmetric matrix, got {short(matrix)}")
    smallest = float(np.min(np.linalg.eigvalsh(matrix)))
    if smallest < -MATRIX_TOLERANCE * scale:
        raise ValueError(
            f"{name}: expected a positive semi-definite matrix, got {short(matrix)} "
            f"(smallest eigenvalue {smallest:.6g})"
        )
    return matrix
