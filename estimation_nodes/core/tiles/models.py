"""The tile world's models: the world map, the sensor model and the motion kernel.

Validated and immutable: each checks itself on construction (see
:mod:`estimation_nodes.core.validation`); the filter steps over them are in
:mod:`estimation_nodes.core.tiles.histogram`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from estimation_nodes.core.errors import InvalidInputError
from estimation_nodes.core.validation import (
    FloatArray,
    as_finite_array,
    as_real_array,
    check_integer,
    check_probability_vector,
    short,
)

# The book's world of Examples 6.8 to 6.14, sensor model and motion kernel:
# defaults for users who give nothing, and the reason a bare estimator is the book's.
BOOK_WORLD = ("bright", "bright", "dark", "dark", "bright")
BOOK_CLASSES = ("bright", "dark")
BOOK_SENSOR_MODEL = ((0.8, 0.2), (0.4, 0.6))  # rows: true class, columns: observed class
BOOK_KERNEL = (0.1, 0.8, 0.1)


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
            raise InvalidInputError(
                f"motion_kernel: expected an odd number of weights centred on the target, "
                f"got {weights.size}: {short(weights)}"
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
        classes = _names("classes", self.classes)
        if not classes:
            raise InvalidInputError("classes: expected at least one class name, got an empty list")
        if any(not name for name in classes):
            raise InvalidInputError(f"classes: expected non-empty names, got {list(classes)}")
        if len(set(classes)) != len(classes):
            raise InvalidInputError(f"classes: expected distinct names, got {list(classes)}")
        matrix = as_finite_array("sensor_model", self.probabilities, ndim=2)
        if matrix.shape != (len(classes), len(classes)):
            raise InvalidInputError(
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
            raise InvalidInputError(
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
        if not isinstance(self.sensor, SensorModel):
            raise InvalidInputError(f"sensor: expected a SensorModel, got {short(self.sensor)}")
        if not isinstance(self.kernel, MotionKernel):
            raise InvalidInputError(f"kernel: expected a MotionKernel, got {short(self.kernel)}")
        canonical = {name: name for name in self.sensor.classes}
        world = tuple(canonical.get(name, name) for name in _names("world", self.world))
        if not world:
            raise InvalidInputError("world: expected at least one cell, got an empty list")
        lookup = {name: index for index, name in enumerate(self.sensor.classes)}
        unknown = sorted(set(world) - set(lookup))
        if unknown:
            raise InvalidInputError(
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
        return int(self._world_index[check_integer("cell", cell) % self.size])

    @classmethod
    def from_lists(
        cls,
        world: Sequence[str],
        classes: Sequence[str],
        sensor_model: Any,
        kernel: Sequence[float],
    ) -> HistogramModel:
        """Build from plain lists; ``sensor_model`` may be flat (row-major) or nested."""
        names = _names("classes", classes)
        matrix = as_real_array("sensor_model", sensor_model)
        if matrix.ndim == 1 and matrix.size == len(names) ** 2:
            matrix = matrix.reshape(len(names), len(names))
        sensor = SensorModel(names, matrix)
        weights = as_real_array("motion_kernel", kernel)
        return cls(_names("world", world), sensor, MotionKernel(weights))

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
        raise InvalidInputError(
            f"{name}: expected {size} values (one per cell), got {vector.size}")
    if np.any(vector < 0.0):
        raise InvalidInputError(f"{name}: expected non-negative values, got {short(vector)}")
    total = float(vector.sum())
    if total <= 0.0:
        raise InvalidInputError(
            f"{name}: expected values with a positive sum, got {short(vector)}")
    if not np.isfinite(total):   # huge weights: their sum overflows, their ratios do not
        vector = vector / vector.max()
        total = float(vector.sum())
    normalized = vector / total
    normalized.setflags(write=False)
    return normalized


def _names(name: str, values: Any) -> tuple[str, ...]:
    """A list of names (tile classes, the world's cells) as a tuple of strings."""
    if isinstance(values, (str, bytes)):
        raise InvalidInputError(f"{name}: expected a list of names, got the string {values!r}")
    try:
        return tuple(map(str, values))
    except TypeError:
        raise InvalidInputError(f"{name}: expected a list of names, got {short(values)}") \
            from None
