"""Reading parameter values: the checks every node's settings builder shares.

Each raises ``ValueError`` whose message starts with the parameter's name;
bounds come from the spec table (params/specs.py), never from here.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from estimation_nodes.core.validation import FloatArray, as_finite_array, check_finite
from estimation_nodes.params.specs import MAX_STATE, UNSET, ParamSpec, spec_named


def as_list(name: str, value: Any) -> list:
    """A parameter that must be a list; an empty or unset one arrives as None or bytes."""
    if value is UNSET or isinstance(value, (str, bytes)) or not hasattr(value, "__len__"):
        raise ValueError(f"{name}: expected a non-empty list, got {value!r}")
    return list(value)


def bounded(name: str, value: Any, specs: tuple[ParamSpec, ...] | None = None) -> float:
    """A finite number within the bounds the spec table gives parameter ``name`` (those its
    descriptor states to `ros2 param describe`): in ``specs`` when given, a node's own
    (two nodes may bound one name differently)."""
    spec = spec_named(name, specs)
    low, high = spec.min_value, spec.max_value
    number = check_finite(name, value)
    if low is not None and high is not None and not low <= number <= high:
        raise ValueError(f"{name}: expected a number in [{low:g}, {high:g}], got {value!r}")
    return number


def entries(name: str, flat: Any) -> FloatArray:
    """A flat list of finite numbers within +-MAX_STATE."""
    values = as_finite_array(name, as_list(name, flat), ndim=1)
    if values.size and float(np.max(np.abs(values))) > MAX_STATE:
        raise ValueError(f"{name}: expected entries within +-{MAX_STATE:g}, "
                         f"got {float(np.max(np.abs(values))):g}")
    return values

def matrix(name: str, flat: Any, rows: int) -> FloatArray:
    """Reshape a row-major flat list into ``rows`` rows, naming the parameter on error."""
    values = entries(name, flat)
    if rows < 1 or values.size == 0 or values.size % rows != 0:
        raise ValueError(
            f"{name}: expected a row-major matrix with {rows} rows, got {values.size} values"
        )
    return values.reshape(rows, -1)

def shaped(name: str, values: FloatArray, rows: int, columns: int, needs: str) -> FloatArray:
    if values.size != rows * columns:
        raise ValueError(f"{name}: expected {rows} x {columns} ({needs}), "
                         f"got {values.size} values")
    return values.reshape(rows, columns)

def with_rows(name: str, values: FloatArray, rows: int, needs: str) -> FloatArray:
    """``rows`` rows, as many columns as the values give (at least one)."""
    if values.size == 0 or values.size % rows:
        raise ValueError(f"{name}: expected {rows} x k values ({needs}), "
                         f"got {values.size} values")
    return values.reshape(rows, -1)

def with_columns(name: str, values: FloatArray, columns: int, needs: str) -> FloatArray:
    """``columns`` columns, as many rows as the values give (at least one)."""
    if values.size == 0 or values.size % columns:
        raise ValueError(f"{name}: expected k x {columns} values ({needs}), "
                         f"got {values.size} values")
    return values.reshape(-1, columns)

def square(name: str, flat: Any) -> FloatArray:
    flat = as_list(name, flat)
    size = int(round(np.sqrt(len(flat))))
    if size * size != len(flat):
        raise ValueError(f"{name}: expected a square matrix (k*k values), got {len(flat)} values")
    return matrix(name, flat, size)

def non_empty_text(name: str, value: Any) -> str:
    if not isinstance(value, str) or not value.strip():
        raise ValueError(f"{name}: expected a non-empty name, got {value!r}")
    return value

def positive_definite(name: str, matrix: FloatArray) -> None:
    """A measurement without noise would make S = C P C' + R singular once P is."""
    if float(np.min(np.linalg.eigvalsh(matrix))) <= 0.0:
        raise ValueError(f"{name}: expected a positive definite matrix (every measurement "
                         f"has some noise), got {matrix.tolist()}")
