"""The checks every model and filter step shares.

Each raises :class:`~estimation_nodes.core.errors.InvalidInputError` (a
``ValueError``) whose message starts with the argument's name, shows the bad
value and says what was expected, so a node can pass the message straight to
its user. The checks of large arrays (beliefs, likelihoods) are numpy
reductions, a pass or two over the array and no Python loop; only a refusal
looks closer, to say what is wrong.
"""

from __future__ import annotations

import math
import operator
import reprlib
from typing import Any

import numpy as np
import numpy.typing as npt

from estimation_nodes.core.errors import InputSizeError, InvalidInputError

FloatArray = npt.NDArray[np.float64]

#: How far a probability vector's sum may stray from 1 (rounding in YAML files).
SUM_TOLERANCE = 1e-9
#: How far above 1 a belief's value may be: the rounding of a normalization, not an error.
PROBABILITY_TOLERANCE = 1e-12
#: Relative tolerance for symmetry and for the smallest eigenvalue of a covariance.
MATRIX_TOLERANCE = 1e-9
#: numpy dtype kinds that are real numbers: bool, signed and unsigned int, float.
_REAL_KINDS = "biuf"
#: Up to this many values, a Python loop over them beats numpy's min and max, whose calls
#: cost microseconds each however small the array (the book's worlds have 5 to 20 cells).
SMALL_ARRAY = 16


def short(value: Any) -> str:
    """Show a value in an error message without flooding the log."""
    if isinstance(value, np.ndarray) and value.dtype.kind in _REAL_KINDS:
        text = np.array2string(value, threshold=12, precision=6)
        return text.replace("\n", "")
    return reprlib.repr(value)


def as_real_array(name: str, value: Any) -> FloatArray:
    """``value`` as a float64 array, the caller's own when it is one already (no copy).

    Refuses what is not real numbers: strings, None, complex numbers (which numpy would
    silently cut to their real part), lists of unequal lengths.
    """
    if isinstance(value, np.ndarray) and value.dtype == np.float64:
        return value
    if not isinstance(value, (str, bytes)):
        try:
            array = np.asarray(value)
        except (TypeError, ValueError):
            pass
        else:
            if array.dtype.kind in _REAL_KINDS:
                return array.astype(np.float64, copy=False)
    raise InvalidInputError(f"{name}: expected real numbers, got {short(value)}")


def as_finite_array(name: str, value: Any, ndim: int) -> FloatArray:
    """A read-only copy of ``value`` as a float array of ``ndim`` dimensions, all finite."""
    array = np.array(as_real_array(name, value), dtype=np.float64)
    if array.ndim != ndim:
        raise InputSizeError(
            f"{name}: expected a {ndim}-dimensional array, got shape {array.shape}"
        )
    if not np.all(np.isfinite(array)):
        raise InvalidInputError(f"{name}: expected finite numbers, got {short(array)}")
    array.setflags(write=False)
    return array


def as_finite_vector(name: str, value: Any, size: int) -> FloatArray:
    """``size`` finite numbers, of any shape (a number alone is one), as a flat float array.

    For the few values of a Kalman input or measurement: Python's isfinite over them
    beats a numpy ufunc call.
    """
    if isinstance(value, np.ndarray) and value.dtype == np.float64:
        vector = value.reshape(-1)
    else:
        vector = as_real_array(name, value).reshape(-1)
    if vector.size != size:
        raise InputSizeError(f"{name}: expected {size} values, got {vector.size}")
    if not all(map(math.isfinite, vector.tolist())):
        raise InvalidInputError(f"{name}: expected finite numbers, got {vector.tolist()}")
    return vector


def check_finite(name: str, value: Any) -> float:
    """Return ``value`` as a float if it is a finite number."""
    if isinstance(value, (str, bytes, np.ndarray)):
        raise InvalidInputError(f"{name}: expected a finite number, got {short(value)}")
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise InvalidInputError(f"{name}: expected a finite number, got {short(value)}") from None
    if not math.isfinite(number):
        raise InvalidInputError(f"{name}: expected a finite number, got {value!r}")
    return number


def check_positive(name: str, value: Any) -> float:
    """Return ``value`` as a float if it is finite and strictly positive."""
    number = check_finite(name, value)
    if number <= 0.0:
        raise InvalidInputError(f"{name}: expected a number > 0, got {value!r}")
    return number


def check_non_negative(name: str, value: Any) -> float:
    """Return ``value`` as a float if it is finite and >= 0."""
    number = check_finite(name, value)
    if number < 0.0:
        raise InvalidInputError(f"{name}: expected a number >= 0, got {value!r}")
    return number


def check_integer(name: str, value: Any) -> int:
    """Return ``value`` as a Python int if it is an integer (not a float, even a whole one:
    2.5 cells is no count, and 1e300 would be one only by accident of rounding)."""
    try:
        return operator.index(value)
    except TypeError:
        raise InvalidInputError(f"{name}: expected an integer, got {short(value)}") from None


def check_probability_vector(name: str, value: Any) -> FloatArray:
    """A non-empty vector of probabilities in [0, 1] that sums to 1."""
    vector = as_finite_array(name, value, ndim=1)
    if vector.size == 0:
        raise InvalidInputError(f"{name}: expected at least one probability, got an empty list")
    if np.any(vector < 0.0) or np.any(vector > 1.0):
        raise InvalidInputError(
            f"{name}: expected probabilities in [0, 1], got {short(vector)}"
        )
    total = float(vector.sum())
    if abs(total - 1.0) > SUM_TOLERANCE:
        raise InvalidInputError(
            f"{name}: expected probabilities summing to 1, got {short(vector)} (sum {total:.12g})"
        )
    return vector


def _shaped(name: str, value: Any, shape: tuple[int, ...]) -> FloatArray:
    """A C-contiguous float64 array of ``shape``, the caller's own when it is one."""
    array = np.ascontiguousarray(as_real_array(name, value))
    if array.shape != shape:
        raise InputSizeError(f"{name}: expected shape {shape}, got {array.shape}")
    if array.size == 0:
        raise InputSizeError(f"{name}: expected at least one value, got none")
    return array


def values_within(array: FloatArray, lowest: float, highest: float) -> bool:
    """Whether every value of ``array`` is in [lowest, highest]; NaN is not."""
    if array.size <= SMALL_ARRAY:
        return all(lowest <= v <= highest for v in array.ravel().tolist())
    if highest == math.inf:   # one pass: the min is NaN where any value is
        return bool(array.min() >= lowest)
    return bool(array.min() >= lowest and array.max() <= highest)   # NaN fails both


def _what_is_wrong(array: FloatArray, lowest: float, highest: float) -> str:
    """The values of ``array`` outside [lowest, highest], counted by kind (a refusal only)."""
    nan = int(np.isnan(array).sum())
    below = int((array < lowest).sum())
    above = int((array > highest).sum())
    parts = [f"{count} {what}" for count, what in
             ((nan, "NaN"), (below, f"below {lowest:g}"), (above, f"above {highest:g}"))
             if count]
    return ", ".join(parts) + f" among {array.size} values"


def check_probabilities(name: str, value: Any, shape: tuple[int, ...]) -> FloatArray:
    """A belief: values in [0, 1] (not necessarily summing to 1; PROBABILITY_TOLERANCE
    above 1 for rounding), of ``shape``; C-contiguous float64, the caller's own array when
    it is one. Two passes (min and max)."""
    array = _shaped(name, value, shape)
    highest = 1.0 + PROBABILITY_TOLERANCE
    if not values_within(array, 0.0, highest):
        raise InvalidInputError(f"{name}: expected probabilities in [0, 1], got "
                                f"{_what_is_wrong(array, 0.0, highest)}")
    return array


def check_non_negative_array(name: str, value: Any, shape: tuple[int, ...]) -> FloatArray:
    """A likelihood: finite values >= 0 of ``shape``; C-contiguous float64, the caller's
    own array when it is one. Two passes (min and max)."""
    array = _shaped(name, value, shape)
    if not values_within(array, 0.0, _LARGEST):
        raise InvalidInputError(f"{name}: expected finite numbers >= 0, got "
                                f"{_what_is_wrong(array, 0.0, _LARGEST)}")
    return array


#: The largest finite float: a value at most this is not inf.
_LARGEST = float(np.finfo(np.float64).max)


def check_covariance(name: str, value: Any, size: int) -> FloatArray:
    """A ``size`` x ``size`` symmetric positive semi-definite matrix (0 x 0 for size 0)."""
    matrix = as_finite_array(name, value, ndim=2)
    if matrix.shape != (size, size):
        raise InputSizeError(f"{name}: expected shape ({size}, {size}), got {matrix.shape}")
    if size == 0:
        return matrix
    scale = max(1.0, float(np.max(np.abs(matrix))))
    if not np.allclose(matrix, matrix.T, rtol=0.0, atol=MATRIX_TOLERANCE * scale):
        raise InvalidInputError(f"{name}: expected a symmetric matrix, got {short(matrix)}")
    with np.errstate(over="ignore", invalid="ignore"):
        eigenvalues = np.linalg.eigvalsh(matrix)
    smallest = float(np.min(eigenvalues))
    if not np.all(np.isfinite(eigenvalues)):
        raise InvalidInputError(
            f"{name}: its entries are too large for its eigenvalues to be finite: "
            f"{short(matrix)}")
    if smallest < -MATRIX_TOLERANCE * scale:
        raise InvalidInputError(
            f"{name}: expected a positive semi-definite matrix, got {short(matrix)} "
            f"(smallest eigenvalue {smallest:.6g})"
        )
    return matrix
