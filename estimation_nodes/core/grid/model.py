"""The grid filter's model: the state grid and likelihood field of one map (``GridModel``),
the argument checks the steps share, and the choice of compiled kernels.

The belief is a tensor ``b[k, i, j]``: the probability that the robot is in
state cell (row i, column j) with heading bin k (heading ``k * 2 pi / K``),
rows along y and columns along x, as nav_msgs/OccupancyGrid stores a map
(row 0 at the map's origin). Probabilistic Robotics ch. 8 (grid localization)
with the odometry motion model (5.4) and the likelihood-field sensor model
(6.4); Fox, Burgard and Thrun 1999.

The steps over it, one module per part of the algorithm: motion.py (the odometry motion
model, ``predict``), laser.py (the likelihood-field sensor model, ``scan_log_likelihood``
and ``correct_scan``), correction.py (``correct``), priors.py, belief.py (what the
belief says).

Every public function checks its arguments and raises ``InvalidInputError``
(core/errors.py) naming the one that is wrong: a belief of another shape than
the model's or with values outside [0, 1], a number that is NaN or infinite,
a scan with a range that is no reading (see ``laser.check_scan``). Results are finite.
The checks of a belief are two numpy reductions; the running localizer
(localization.py) checks its new inputs once and calls the unchecked steps
(underscored, beside each public one) on the belief it holds.

The map's rotation (an OccupancyGrid origin with yaw) is not supported here:
the state grid refuses it (core/grid/likelihood_field.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import ModuleType
from typing import Any

import numpy as np

from estimation_nodes.core.compiled_loader import load_kernels
from estimation_nodes.core.errors import InputSizeError, InvalidInputError
from estimation_nodes.core.validation import (
    FloatArray,
    as_real_array,
    check_finite,
    check_integer,
    check_positive,
    check_probabilities,
    short,
)

TWO_PI = 2.0 * math.pi
#: Beliefs of at least this many states take the compiled kernels (grid/compiled.py)
#: when numba imports; smaller ones never import it.
COMPILED_MIN_STATES = 100_000
#: How far (m) a map may reach from (0, 0): squares of distances on it stay finite.
MAX_MAP_EXTENT = 1e150

Pose = tuple[float, float, float]


@dataclass(frozen=True)
class GridModel:
    """The state grid and the likelihood field of one map.

    ``free``: (H, W) bool, the cells the robot may be in; ``log_field``: (H, W) log
    likelihood of a beam ending in each cell; ``log_outside``: that of a beam ending
    off the map; ``resolution`` in m per cell; ``origin`` the (x, y) of cell (0, 0)'s
    corner; ``heading_bins`` K.
    """

    free: np.ndarray
    log_field: FloatArray
    log_outside: float
    resolution: float
    origin: tuple[float, float]
    heading_bins: int
    #: The laser's mounting pose on the robot (x m, y m, yaw rad): a beam starts there.
    laser_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: The largest |log likelihood| one beam can score (in the field or outside it).
    log_bound: float = field(init=False, repr=False, compare=False)
    #: The field at the map's own resolution (grid/scan_fit.py's FitField) that refines
    #: the published pose, or None: the pose is the belief's (belief.refined_pose).
    scan_fit: Any = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        free = _booleans("free", self.free)
        log_field = as_real_array("log_field", self.log_field)
        if free.ndim != 2 or free.shape != log_field.shape:
            raise InputSizeError(f"free and log_field: expected two arrays of one (H, W) "
                                 f"shape, got {free.shape} and {log_field.shape}")
        if not free.any():
            raise InvalidInputError("free: the map has no free cell")
        resolution = check_positive("resolution", self.resolution)
        origin = _numbers("origin", self.origin, ("x", "y"))
        heading_bins = check_integer("heading_bins", self.heading_bins)
        if heading_bins < 1:
            raise InvalidInputError(f"heading_bins: expected >= 1, got {heading_bins}")
        if not np.isfinite(log_field).all():
            raise InvalidInputError("log_field: expected finite log likelihoods")
        log_outside = check_finite("log_outside", self.log_outside)
        if not resolution * max(free.shape) + max(map(abs, origin)) < MAX_MAP_EXTENT:
            raise InvalidInputError(
                f"resolution, origin: a map of {free.shape[1]} x {free.shape[0]} cells of "
                f"{resolution:g} m at {origin} reaches past {MAX_MAP_EXTENT:g} m")
        for name, value in (("free", free), ("log_field", log_field), ("log_outside", log_outside),
                            ("resolution", resolution), ("origin", origin),
                            ("heading_bins", heading_bins),
                            ("laser_pose", mounting_pose(self.laser_pose))):
            object.__setattr__(self, name, value)
        object.__setattr__(self, "log_bound",
                           max(float(np.abs(log_field).max()), abs(log_outside)))

    @property
    def shape(self) -> tuple[int, int, int]:
        """(K, H, W): the belief tensor's shape."""
        return (self.heading_bins, *self.free.shape)

    @property
    def bin_width(self) -> float:
        return TWO_PI / self.heading_bins

    def headings(self) -> FloatArray:
        """The heading of each bin (rad), bin k at k * 2 pi / K."""
        return np.arange(self.heading_bins, dtype=np.float64) * self.bin_width

    def cell_centres(self) -> tuple[FloatArray, FloatArray]:
        """x of each column's centre, y of each row's centre (m)."""
        rows, cols = self.free.shape
        x = self.origin[0] + (np.arange(cols, dtype=np.float64) + 0.5) * self.resolution
        y = self.origin[1] + (np.arange(rows, dtype=np.float64) + 0.5) * self.resolution
        return x, y


# --- argument checks -----------------------------------------------------------------------


#: The farthest a laser may sit from the robot's centre (m): further is a unit mistake.
MAX_MOUNTING_OFFSET = 100.0


def mounting_pose(value: Any) -> tuple[float, float, float]:
    """A sensor's (x, y, yaw) on the robot: finite, within MAX_MOUNTING_OFFSET."""
    x, y, yaw = _numbers("laser_pose", value, ("x", "y", "yaw"))
    if math.hypot(x, y) > MAX_MOUNTING_OFFSET:
        raise InvalidInputError(f"laser_pose: expected the laser within "
                                f"{MAX_MOUNTING_OFFSET:g} m of the robot's centre, got "
                                f"({x:g}, {y:g})")
    return x, y, yaw


def _numbers(name: str, value: Any, parts: tuple[str, ...]) -> tuple[float, ...]:
    """``value`` as len(parts) finite floats (a pose, an origin), or InvalidInputError."""
    try:
        numbers = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        numbers = ()
    if len(numbers) != len(parts) or not all(map(math.isfinite, numbers)) \
            or isinstance(value, (str, bytes)):
        raise InvalidInputError(
            f"{name}: expected finite numbers ({', '.join(parts)}), got {short(value)}")
    return numbers


def _booleans(name: str, value: Any) -> np.ndarray:
    """``value`` as a bool array, the caller's own when it is one (no 0/1 numbers: ``~``
    of those is no mask)."""
    try:
        array = np.asarray(value)
    except (TypeError, ValueError):
        array = np.zeros(0)
    if array.dtype != np.bool_:
        raise InvalidInputError(f"{name}: expected an (H, W) array of booleans, got "
                                f"{short(value)}")
    return array


def check_pose(name: str, value: Any) -> Pose:
    """``value`` as a pose (x, y, yaw) of three finite floats."""
    x, y, yaw = _numbers(name, value, ("x", "y", "yaw"))
    return x, y, yaw


def _check_model(model: Any) -> GridModel:
    if not isinstance(model, GridModel):
        raise InvalidInputError(f"model: expected a GridModel, got {type(model).__name__}")
    return model


def check_belief(belief: Any, model: GridModel) -> FloatArray:
    """``belief`` as a C-contiguous float array of the model's (K, H, W) shape, values in
    [0, 1] (not necessarily summing to 1); the caller's own array when it is one."""
    return check_probabilities("belief", belief, model.shape)


def _any_belief(belief: Any, ndim: int | None = 3) -> FloatArray:
    """A belief of ``ndim`` dimensions (any, for None) of values in [0, 1]."""
    array = as_real_array("belief", belief)
    if ndim is not None and array.ndim != ndim:
        raise InputSizeError(f"belief: expected a {ndim}-dimensional array, got shape "
                             f"{array.shape}")
    return check_probabilities("belief", array, array.shape)


# --- the compiled kernels or numpy's, and angles -------------------------------------------


def _compiled_kernels() -> ModuleType | None:
    return load_kernels("estimation_nodes.core.grid.compiled")


def compiled_kernels(states: int, allowed: bool = True) -> ModuleType | None:
    """The compiled kernels a belief of ``states`` states uses, or None for numpy's."""
    return _compiled_kernels() if allowed and states >= COMPILED_MIN_STATES else None


def _states(model: GridModel) -> int:
    return model.free.size * model.heading_bins


def _wrap(angles: FloatArray) -> FloatArray:
    """Angles to (-pi, pi]."""
    return np.pi - np.mod(np.pi - np.asarray(angles, dtype=np.float64), TWO_PI)


def _wrap_scalar(angle: float) -> float:
    return math.pi - (math.pi - angle) % TWO_PI
