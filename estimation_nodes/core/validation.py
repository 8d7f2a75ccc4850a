"""Validated, immutable models for the filters.

Every model checks itself on construction and raises ``ValueError`` whose
message starts with the field's name, shows the bad value and says what was
expected, so a node can pass the message straight to its user.

The models are data only; the filter steps that use them live in
:mod:`estimation_nodes.core.tiles.histogram` and :mod:`estimation_nodes.core.kalman.linear`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

#: How far a probability vector's sum may stray from 1 (rounding in YAML files).
SUM_TOLERANCE = 1e-9
#: Relative tolerance for symmetry and for the smallest eigenvalue of a covariance.
MATRIX_TOLERANCE = 1e-9

# The book's world of Examples 6.8 to 6.14, sensor model and motion kernel:
# defaults for users who give nothing, and the reason a bare estimator is the book's.
BOOK_WORLD = ("bright", "bright", "dark", "dark", "bright")
BOOK_CLASSES = ("bright", "dark")
BOOK_SENSOR_MODEL = ((0.8, 0.2), (0.4, 0.6))  # rows: true class, columns: observed class
BOOK_KERNEL = (0.1, 0.8, 0.1)


def _short(value: Any) -> str:
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
        raise ValueError(f"{name}: expected finite numbers, got {_short(array)}")
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
        raise ValueError(f"{name}: expected probabilities in [0, 1], got {_short(vector)}")
    total = float(vector.sum())
    if abs(total - 1.0) > SUM_TOLERANCE:
        raise ValueError(
            f"{name}: expected probabilities summing to 1, got {_short(vector)} (sum {total:.12g})"
        )
    return vector


def check_covariance(name: str, value: Any, size: int) -> FloatArray:
    """A ``size`` x ``size`` symmetric positive semi-definite matrix."""
    matrix = as_finite_array(name, value, ndim=2)
    if matrix.shape != (size, size):
        raise ValueError(f"{name}: expected shape ({size}, {size}), got {matrix.shape}")
    scale = max(1.0, float(np.max(np.abs(matrix))))
    if not np.allclose(matrix, matrix.T, rtol=0.0, atol=MATRIX_TOLERANCE * scale):
        raise ValueError(f"{name}: expected a symmetric matrix, got {_short(matrix)}")
    smallest = float(np.min(np.linalg.eigvalsh(matrix)))
    if smallest < -MATRIX_TOLERANCE * scale:
        raise ValueError(
            f"{name}: expected a positive semi-definite matrix, got {_short(matrix)} "
            f"(smallest eigenvalue {smallest:.6g})"
        )
    return matrix


@dataclass(frozen=True)
class MotionKernel:
    """Probabilities of landing at offsets around the commanded move.

    ``weights[i]`` is the probability of landing ``i - len(weights) // 2`` cells
    away from the target; the book's kernel is ``(0.1, 0.8, 0.1)``.
    """

    weights: FloatArray

    def __post_init__(self) -> None:
        weights = check_probability_vector("motion_kernel", self.weights)
        if weights.size % 2 == 0:
            raise ValueError(
                f"motion_kernel: expected an odd number of weights centred on the target, "
                f"got {weights.size}: {_short(weights)}"
            )
        object.__setattr__(self, "weights", weights)

    @property
    def half_width(self) -> int:
        """How many cells the kernel reaches on either side of the target."""
        return self.weights.size // 2

    @property
    def offsets(self) -> npt.NDArray[np.int64]:
        """The offset from the target that each weight stands for."""
        return np.arange(-self.half_width, self.half_width + 1)


@dataclass(frozen=True)
class SensorModel:
    """p(observed class | true class) for a finite set of tile classes.

    ``probabilities[t, o]`` is the probability of observing ``classes[o]`` on
    a tile of class ``classes[t]``; each row sums to 1.
    """

    classes: tuple[str, ...]
    probabilities: FloatArray

    def __post_init__(self) -> None:
        classes = tuple(str(name) for name in self.classes)
        if not classes:
            raise ValueError("classes: expected at least one class name, got an empty list")
        if any(not name for name in classes):
            raise ValueError(f"classes: expected non-empty names, got {list(classes)}")
        if len(set(classes)) != len(classes):
            raise ValueError(f"classes: expected distinct names, got {list(classes)}")
        matrix = as_finite_array("sensor_model", self.probabilities, ndim=2)
        if matrix.shape != (len(classes), len(classes)):
            raise ValueError(
                f"sensor_model: expected {len(classes)}x{len(classes)} probabilities "
                f"(one row per true class in {list(classes)}), got shape {matrix.shape}"
            )
        for row, name in zip(matrix, classes):
            check_probability_vector(f"sensor_model (row of true class '{name}')", row)
        object.__setattr__(self, "classes", classes)
        object.__setattr__(self, "probabilities", matrix)

    def index_of(self, name: str) -> int:
        """The index of a class name; ``ValueError`` naming the known classes otherwise."""
        try:
            return self.classes.index(name)
        except ValueError:
            raise ValueError(
                f"observation: unknown tile class {name!r}, expected one of {list(self.classes)}"
            ) from None


@dataclass(frozen=True)
class HistogramModel:
    """A cyclic world of tiles with a sensor model and a motion kernel.

    The likelihood vector of every observable class is computed once here, so
    a correction step is a single multiply and sum over the cells.
    """

    world: tuple[str, ...]
    sensor: SensorModel
    kernel: MotionKernel
    _world_index: npt.NDArray[np.intp] = field(init=False, repr=False, compare=False)
    _likelihoods: FloatArray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        # Each cell refers to the sensor model's own name object where it can: a
        # million cells read from a file then hold pointers, not a million strings.
        canonical = {name: name for name in self.sensor.classes}
        world = tuple(canonical.get(name, name) for name in map(str, self.world))
        if not world:
            raise ValueError("world: expected at least one cell, got an empty list")
        lookup = {name: index for index, name in enumerate(self.sensor.classes)}
        unknown = sorted(set(world) - set(lookup))
        if unknown:
            raise ValueError(
                f"world: cells name classes {unknown} that the sensor model lacks, "
                f"expected only {list(self.sensor.classes)}"
            )
        world_index = np.fromiter((lookup[name] for name in world), np.intp, len(world))
        # Row o holds p(z = class o | x) for every cell x.
        likelihoods = np.ascontiguousarray(self.sensor.probabilities[world_index].T)
        likelihoods.setflags(write=False)
        object.__setattr__(self, "world", world)
        object.__setattr__(self, "_world_index", world_index)
        object.__setattr__(self, "_likelihoods", likelihoods)

    @property
    def size(self) -> int:
        """Number of cells in the world."""
        return len(self.world)

    def likelihood(self, observed: str) -> FloatArray:
        """p(z = observed | x) for every cell x (read-only)."""
        return self._likelihoods[self.sensor.index_of(observed)]

    def cell_class_index(self, cell: int) -> int:
        """Index in ``sensor.classes`` of the true class of a cell (taken modulo the size)."""
        return int(self._world_index[cell % self.size])

    @classmethod
    def from_lists(
        cls,
        world: Sequence[str],
        classes: Sequence[str],
        sensor_model: Any,
        kernel: Sequence[float],
    ) -> HistogramModel:
        """Build from plain lists; ``sensor_model`` may be flat (row-major) or nested."""
        matrix = np.asarray(sensor_model, dtype=np.float64)
        if matrix.ndim == 1 and matrix.size == len(classes) ** 2:
            matrix = matrix.reshape(len(classes), len(classes))
        sensor = SensorModel(tuple(classes), matrix)
        return cls(tuple(world), sensor, MotionKernel(np.asarray(kernel, dtype=np.float64)))

    @classmethod
    def book(cls) -> HistogramModel:
        """The world, sensor model and motion kernel of Examples 6.8 to 6.14."""
        return cls.from_lists(BOOK_WORLD, BOOK_CLASSES, BOOK_SENSOR_MODEL, BOOK_KERNEL)


def check_belief(name: str, value: Any, size: int) -> FloatArray:
    """A distribution over ``size`` cells: non-negative, finite, with a positive sum.

    The vector is normalized, so ``[1, 1, 2, 2, 1]`` is accepted as a prior.
    """
    vector = as_finite_array(name, value, ndim=1)
    if vector.size != size:
        raise ValueError(f"{name}: expected {size} values (one per cell), got {vector.size}")
    if np.any(vector < 0.0):
        raise ValueError(f"{name}: expected non-negative values, got {_short(vector)}")
    total = float(vector.sum())
    if total <= 0.0:
        raise ValueError(f"{name}: expected values with a positive sum, got {_short(vector)}")
    normalized = vector / total
    normalized.setflags(write=False)
    return normalized


@dataclass(frozen=True)
class ScalarKalmanModel:
    """The scalar filter of the book's Algorithm 4: x' = x + u, z = x + v.

    ``var_u`` is the variance of the executed move, ``var_z`` that of a measurement.
    """

    var_u: float
    var_z: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "var_u", check_positive("var_u", self.var_u))
        object.__setattr__(self, "var_z", check_positive("var_z", self.var_z))


@dataclass(frozen=True)
class LinearGaussianModel:
    """x(k+1) = A x(k) + B u(k) + F w(k),  z(k) = C x(k) + v(k),  Q = cov(w), R = cov(v).

    The book's symbols: F is the noise-input matrix (not the transition matrix,
    which filterpy calls F and the book calls A).
    """

    A: FloatArray
    B: FloatArray
    C: FloatArray
    F: FloatArray
    Q: FloatArray
    R: FloatArray
    #: F Q F', the process noise in state space.
    process_noise: FloatArray = field(init=False, repr=False, compare=False)
    #: The n x n identity, for the Joseph form.
    identity: FloatArray = field(init=False, repr=False, compare=False)
    #: A' / 2, contiguous: the prediction's symmetric product (see kalman.predict).
    half_A_transposed: FloatArray = field(init=False, repr=False, compare=False)
    #: C', contiguous, for the gain.
    C_transposed: FloatArray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        A = as_finite_array("A", self.A, ndim=2)
        n = A.shape[0]
        if A.shape != (n, n):
            raise ValueError(f"A: expected a square matrix, got shape {A.shape}")
        B = as_finite_array("B", self.B, ndim=2)
        C = as_finite_array("C", self.C, ndim=2)
        F = as_finite_array("F", self.F, ndim=2)
        for name, matrix in (("B", B), ("F", F)):
            if matrix.shape[0] != n:
                raise ValueError(
                    f"{name}: expected {n} rows to match A ({n}x{n}), got shape {matrix.shape}"
                )
        if C.shape[1] != n:
            raise ValueError(
                f"C: expected {n} columns to match A ({n}x{n}), got shape {C.shape}"
            )
        Q = check_covariance("Q", self.Q, F.shape[1])
        R = check_covariance("R", self.R, C.shape[0])
        for name, matrix in (("A", A), ("B", B), ("C", C), ("F", F), ("Q", Q), ("R", R)):
            object.__setattr__(self, name, matrix)
        # Fixed per model, so computed once rather than at every step.
        process_noise = F @ Q @ F.T
        process_noise = 0.5 * (process_noise + process_noise.T)
        process_noise.setflags(write=False)
        identity = np.eye(n)
        identity.setflags(write=False)
        object.__setattr__(self, "process_noise", process_noise)
        object.__setattr__(self, "identity", identity)
        # Halving is exact in binary floating point, so products with A'/2 are
        # bit for bit half the products with A'.
        for name, matrix in (("half_A_transposed", 0.5 * A.T), ("C_transposed", C.T)):
            matrix = np.ascontiguousarray(matrix)
            matrix.setflags(write=False)
            object.__setattr__(self, name, matrix)

    @property
    def state_size(self) -> int:
        """Dimension of the state x."""
        return int(self.A.shape[0])

    @property
    def input_size(self) -> int:
        """Dimension of the input u."""
        return int(self.B.shape[1])

    @property
    def measurement_size(self) -> int:
        """Dimension of the measurement z."""
        return int(self.C.shape[0])

    @classmethod
    def scalar(cls, var_u: float, var_z: float) -> LinearGaussianModel:
        """A = B = C = F = 1: the matrix form of Algorithm 4."""
        one = np.ones((1, 1))
        return cls(one, one, one, one, np.array([[var_u]]), np.array([[var_z]]))


@dataclass(frozen=True)
class GaussianState:
    """A mean and its covariance, checked: finite, matching shapes, P symmetric PSD."""

    x: FloatArray
    P: FloatArray

    def __post_init__(self) -> None:
        x = as_finite_array("x0", self.x, ndim=1)
        P = check_covariance("P0", self.P, x.size)
        object.__setattr__(self, "x", x)
        object.__setattr__(self, "P", P)
