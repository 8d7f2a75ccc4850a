"""Grid Markov localization: the histogram filter over (heading, y, x) on a map.

The belief is a tensor ``b[k, i, j]``: the probability that the robot is in
state cell (row i, column j) with heading bin k (heading ``k * 2 pi / K``),
rows along y and columns along x, as nav_msgs/OccupancyGrid stores a map
(row 0 at the map's origin). Probabilistic Robotics ch. 8 (grid localization)
with the odometry motion model (5.4) and the likelihood-field sensor model
(6.4); Fox, Burgard and Thrun 1999.

- ``predict``: each heading layer is shifted by the odometry displacement
  rotated into that heading (bilinear weights over the four nearest cells),
  the headings by the rotation (linear weights over the two nearest bins),
  then spread by Gaussian noise growing with the motion (AMCL's alphas);
  mass that lands on an occupied cell or off the map is dropped and the rest
  renormalized. O(states x kernel), no transition matrix.
- ``scan_log_likelihood``: for each beam and heading the end point is the
  same cell offset from every state cell, so the log likelihood of a beam
  over one heading layer is a shifted view of the log likelihood field.
- ``correct``: posterior and log evidence, as the 1-D filter's ``correct``.

Every public function checks its arguments and raises ``InvalidInputError``
(core/errors.py) naming the one that is wrong: a belief of another shape than
the model's or with values outside [0, 1], a number that is NaN or infinite,
a scan with a range that is no reading (see ``check_scan``). Results are finite.
The checks of a belief are two numpy reductions; the running localizer
(localization.py) checks its new inputs once and calls the unchecked steps
(underscored here) on the belief it holds.

The map's rotation (an OccupancyGrid origin with yaw) is not supported here:
the state grid refuses it (core/grid/likelihood_field.py).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from types import ModuleType
from typing import Any

import numpy as np

from estimation_nodes.core.compiled_loader import load_kernels
from estimation_nodes.core.errors import (
    InputSizeError,
    InvalidInputError,
    NonFiniteResultError,
    ZeroEvidenceError,
)
from estimation_nodes.core.validation import (
    FloatArray,
    as_real_array,
    check_covariance,
    check_finite,
    check_integer,
    check_non_negative,
    check_positive,
    check_probabilities,
    short,
)

TWO_PI = 2.0 * math.pi
#: Beliefs of at least this many states take the compiled kernels (grid/compiled.py)
#: when numba imports; smaller ones never import it.
COMPILED_MIN_STATES = 100_000
#: The widest Gaussian kernel listed tap by tap (``gaussian_taps``), in taps either side.
#: A blur along x or y never needs more taps than the axis has cells, nor one over the
#: headings more than the headings (see ``_reaching_taps`` and ``_heading_taps``).
MAX_TAPS_HALF_WIDTH = 1 << 20
#: How far (m) a map may reach from (0, 0): squares of distances on it stay finite.
MAX_MAP_EXTENT = 1e150
#: A scan's sum of log likelihoods stays within this (beams x the largest |log likelihood|
#: of the model), so it never overflows.
LOG_SUM_LIMIT = 1e300

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
    #: the published pose, or None: the pose is the belief's (steps.refined_pose).
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


@dataclass(frozen=True)
class OdometryNoise:
    """The odometry motion model's noise (Probabilistic Robotics 5.4; AMCL's alpha1..4).

    alpha1: rotation noise from rotation, alpha2: rotation from translation,
    alpha3: translation from translation, alpha4: translation from rotation;
    ``floor_m`` and ``floor_rad`` keep a little spread on every step, so a grid
    of finite resolution can follow a robot whose odometry is slightly off.
    """

    alpha1: float
    alpha2: float
    alpha3: float
    alpha4: float
    floor_m: float = 0.02
    floor_rad: float = 0.02

    def __post_init__(self) -> None:
        for name in ("alpha1", "alpha2", "alpha3", "alpha4", "floor_m", "floor_rad"):
            value = getattr(self, name)
            try:
                number = check_non_negative(name, value)
            except InvalidInputError:
                raise InvalidInputError(
                    f"{name}: expected a finite value >= 0, got {short(value)}") from None
            object.__setattr__(self, name, number)


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


def check_delta(delta: Any) -> tuple[float, float, float]:
    """(rot1, trans, rot2) of an odometry motion (Table 5.6, as ``odometry_delta`` gives
    it): finite, rot1 and rot2 in [-pi, pi], trans >= 0."""
    rot1, trans, rot2 = _numbers("delta", delta, ("rot1", "trans", "rot2"))
    if not (abs(rot1) <= math.pi and abs(rot2) <= math.pi and trans >= 0.0):
        raise InvalidInputError(f"delta: expected (rot1, trans, rot2) with rot1 and rot2 in "
                                f"[-pi, pi] and trans >= 0, got {short(delta)}")
    return rot1, trans, rot2


def check_scan(ranges: Any, angles: Any) -> tuple[FloatArray, FloatArray]:
    """The beams of a scan to score, checked: (ranges, angles), one angle (rad, from the
    robot's heading) per range (m), as float arrays.

    Every range given is scored as a reading that hit something at that distance. A
    laser's "no return" is not such a reading: REP 117's +inf (nothing within
    range_max), -inf (closer than range_min) and NaN (no valid measurement), a negative
    value, and a reading at or beyond the sensor's range_max (which the core does not
    know). The caller leaves those beams out first, as the nodes' ``scan_beams``
    (nodes/grid_messages.py) does; given one anyway, a NaN, infinite or negative range
    is refused (``InvalidInputError`` naming ``ranges`` and the beam) rather than
    silently dropped, so a caller that forgot to select its beams learns it at once
    instead of scoring fewer beams than it thinks. A finite range longer than the map
    ends off the map from every state cell (``log_outside``); the work and the memory
    do not grow with it. No beams at all are a scan that says nothing: the correction
    leaves the belief as it was.
    """
    r = as_real_array("ranges", ranges)
    a = as_real_array("angles", angles)
    if r.ndim != 1 or a.ndim != 1:
        raise InputSizeError(f"ranges and angles: expected two lists of numbers, got shapes "
                             f"{r.shape} and {a.shape}")
    if r.size != a.size:
        raise InputSizeError(f"ranges and angles: expected one angle per range, got "
                             f"{r.size} ranges and {a.size} angles")
    if r.size and not (r.min() >= 0.0 and r.max() < math.inf):   # NaN fails both
        beam = int(np.flatnonzero(~(r >= 0.0) | ~(r < math.inf))[0])
        raise InvalidInputError(
            f"ranges: expected finite readings >= 0, got {float(r[beam])!r} at beam {beam} "
            f"(leave out the beams of no return: NaN, inf, negative, at or beyond range_max)")
    if a.size and not np.isfinite(a).all():
        beam = int(np.flatnonzero(~np.isfinite(a))[0])
        raise InvalidInputError(
            f"angles: expected finite numbers, got {float(a[beam])!r} at beam {beam}")
    return r, a


def _covariance_3x3(covariance: Any) -> FloatArray:
    """A 3 x 3 covariance over (x, y, yaw), given as 3 x 3 or as 9 values (row-major)."""
    matrix = as_real_array("covariance", covariance)
    if matrix.size == 9:
        matrix = matrix.reshape(3, 3)
    return check_covariance("covariance", matrix, 3)


# --- models and priors ---------------------------------------------------------------------


def uniform_over_free(model: GridModel) -> FloatArray:
    """Not knowing where the robot is: equal probability on every free cell and heading."""
    _check_model(model)
    layer = model.free / float(np.count_nonzero(model.free) * model.shape[0])
    belief = np.empty(model.shape)
    belief[:] = layer     # one tensor, no temporary of its size
    return belief


def gaussian_prior(model: GridModel, x: float, y: float, yaw: float,
                   covariance: FloatArray) -> FloatArray:
    """A prior from a pose and its 3 x 3 covariance over (x, y, yaw), as RViz's "2D Pose
    Estimate" sends one, restricted to free cells; never all zero (the free states
    nearest in the Gaussian's metric take the mass when it covers none). A pose so far
    from the map that its distance to it overflows is refused (``NonFiniteResultError``)."""
    _check_model(model)
    x, y, yaw = check_pose("pose", (x, y, yaw))
    cov = _covariance_3x3(covariance)
    floor = np.diag([(model.resolution / 2) ** 2] * 2 + [(model.bin_width / 2) ** 2])
    try:
        information = np.linalg.inv(cov + floor)
    except np.linalg.LinAlgError:
        raise InvalidInputError(f"covariance: singular to rounding once the grid's own "
                                f"spread is added: {short(cov)}") from None
    exponent = _prior_exponent(model, (x, y, yaw), information)
    # Walls and unknown space out: inf there, exp() makes them 0.
    exponent[:, ~model.free] = np.inf
    lowest = exponent.min()
    if not math.isfinite(lowest):   # NaN or inf anywhere: min is NaN, or inf everywhere
        raise NonFiniteResultError(f"x, y, covariance: the pose ({x:g}, {y:g}) is too far "
                                   f"from the map (or the covariance too extreme) for a "
                                   f"finite prior")
    # In place, one tensor: a real building's prior is hundreds of MB. The most likely
    # free state gets exp(0) = 1, so the sum is never 0: where the Gaussian covers no free
    # cell, the free states nearest in its metric take the mass.
    exponent -= lowest
    exponent *= -0.5
    belief = np.exp(exponent, out=exponent)
    belief /= belief.sum()
    return belief


def _prior_exponent(model: GridModel, pose: tuple[float, float, float],
                    information: np.ndarray) -> FloatArray:
    """The Gaussian's exponent d' I d for every state, built a heading layer at a time
    (the temporaries are of one layer, not of the whole belief)."""
    x, y, yaw = pose
    xs, ys = model.cell_centres()
    exponent = np.empty(model.shape)
    with np.errstate(over="ignore", invalid="ignore"):
        dx = (xs - x)[None, :]
        dy = (ys - y)[:, None]
        planar = (information[0, 0] * dx * dx + information[1, 1] * dy * dy
                  + 2 * information[0, 1] * dx * dy)
        across = 2 * information[0, 2] * dx + 2 * information[1, 2] * dy
        for k, dyaw in enumerate(_wrap(model.headings() - yaw)):
            np.add(planar, dyaw * (information[2, 2] * dyaw + across), out=exponent[k])
    return exponent


def odometry_delta(previous: tuple[float, float, float],
                   current: tuple[float, float, float]) -> tuple[float, float, float]:
    """(rot1, trans, rot2) between two odometry poses (x, y, yaw): Probabilistic
    Robotics Table 5.6. A turn on the spot is all rot1. Poses so far apart that their
    difference overflows are refused (``NonFiniteResultError``)."""
    previous = check_pose("previous", previous)
    current = check_pose("current", current)
    dx, dy = current[0] - previous[0], current[1] - previous[1]
    turn = current[2] - previous[2]
    if not (math.isfinite(dx) and math.isfinite(dy) and math.isfinite(turn)):
        raise NonFiniteResultError("previous, current: their difference overflows: "
                                   f"{current} and {previous}")
    trans = math.hypot(dx, dy)
    rot1 = _wrap_scalar(math.atan2(dy, dx) - previous[2]) if trans > 1e-9 else 0.0
    rot2 = _wrap_scalar(turn - rot1)
    return rot1, trans, rot2


# --- prediction ----------------------------------------------------------------------------


def _compiled_kernels() -> ModuleType | None:
    return load_kernels("estimation_nodes.core.grid.compiled")


def compiled_kernels(states: int, allowed: bool = True) -> ModuleType | None:
    """The compiled kernels a belief of ``states`` states uses, or None for numpy's."""
    return _compiled_kernels() if allowed and states >= COMPILED_MIN_STATES else None


def _states(model: GridModel) -> int:
    return model.free.size * model.heading_bins


def motion_noise(delta: tuple[float, float, float], noise: OdometryNoise,
                 model: GridModel) -> tuple[float, float]:
    """The spread of a motion: std in cells (x and y) and in heading bins."""
    if not isinstance(noise, OdometryNoise):
        raise InvalidInputError(f"noise: expected an OdometryNoise, got {type(noise).__name__}")
    sigma_cells, sigma_bins = _motion_noise(check_delta(delta), noise, _check_model(model))
    if not (math.isfinite(sigma_cells) and math.isfinite(sigma_bins)):
        raise NonFiniteResultError(f"delta, noise: the spread of {delta} overflows")
    return sigma_cells, sigma_bins


#: Below this translation (m) the direction of travel is odometry's jitter, not a turn:
#: the motion's noise is that of a turn on the spot (nav2_amcl's 0.01 m).
JITTER_M = 0.01


def _motion_noise(delta: tuple[float, float, float], noise: OdometryNoise,
                  model: GridModel) -> tuple[float, float]:
    """``motion_noise``: inf when the motion is so extreme that it overflows (the blurs
    take an infinite sigma as an even spread).

    The rotations' sizes are those of ``noise_rotations``: the motion itself is shifted
    exactly as odometry says, only its noise is AMCL's."""
    turned = noise_rotations(delta)
    trans = delta[1]
    sigma_m = noise.floor_m + noise.alpha3 * trans + noise.alpha4 * turned
    sigma_rad = noise.floor_rad + noise.alpha1 * turned + noise.alpha2 * trans
    return sigma_m / model.resolution, sigma_rad / model.bin_width


def noise_rotations(delta: tuple[float, float, float]) -> float:
    """|rot1| + |rot2| as the motion noise takes them (nav2_amcl's differential model):

    - driving backwards is rot1 near pi, then rot2 near -pi, and is as certain as driving
      forwards: each rotation counts as its distance to 0 or to pi, the nearer;
    - a translation below JITTER_M is jitter (a robot turning on the spot, its odometry
      a few mm off to any side): the motion counts as the turn alone.

    Taken at face value, either made a turn of 0.1 rad count as 2 pi, and the blur spread
    a tracked belief by metres (seen on a steady laser: a wandering robot turning on the
    spot, every scan an update)."""
    rot1, trans, rot2 = delta
    if trans < JITTER_M:
        return abs(math.remainder(rot1 + rot2, TWO_PI))
    return sum(min(abs(rotation), math.pi - abs(rotation)) for rotation in (rot1, rot2))


def layer_shifts(model: GridModel, rot1: float, trans: float) -> tuple[FloatArray, FloatArray]:
    """How far (rows, columns) each heading layer moves: the displacement seen from it."""
    _check_model(model)
    rot1, trans = check_finite("rot1", rot1), check_finite("trans", trans)
    shift_rows, shift_cols = _layer_shifts(model, rot1, trans)
    if not (np.isfinite(shift_rows).all() and np.isfinite(shift_cols).all()):
        raise NonFiniteResultError(f"trans: {trans:g} m overflows in cells of "
                                   f"{model.resolution:g} m")
    return shift_rows, shift_cols


def _layer_shifts(model: GridModel, rot1: float, trans: float) -> tuple[FloatArray, FloatArray]:
    angles = model.headings() + rot1
    with np.errstate(over="ignore"):
        return (trans * np.sin(angles) / model.resolution,
                trans * np.cos(angles) / model.resolution)


def _bounded_shifts(model: GridModel, rot1: float,
                    trans: float) -> tuple[FloatArray, FloatArray]:
    """``layer_shifts`` cut to the grid's size plus one cell: a shift that long already
    moves every cell off the grid, so the result is the same (all lost), and the kernels
    take whole cells as exact int64s."""
    rows, cols = model.free.shape
    shift_rows, shift_cols = _layer_shifts(model, rot1, trans)
    return (np.clip(shift_rows, -(rows + 1), rows + 1),
            np.clip(shift_cols, -(cols + 1), cols + 1))


def predict(belief: FloatArray, model: GridModel, delta: tuple[float, float, float],
            noise: OdometryNoise, compiled: bool = True) -> FloatArray:
    """The belief after a motion (rot1, trans, rot2) measured by odometry (``check_delta``).

    A motion that moves all the belief off the free cells (a long one, off the map) is
    refused with ``ZeroEvidenceError`` naming ``delta``.
    """
    _check_model(model)
    if not isinstance(noise, OdometryNoise):
        raise InvalidInputError(f"noise: expected an OdometryNoise, got {type(noise).__name__}")
    return _predict(check_belief(belief, model), model, check_delta(delta), noise, compiled)


def _predict(belief: FloatArray, model: GridModel, delta: tuple[float, float, float],
             noise: OdometryNoise, compiled: bool = True) -> FloatArray:
    """``predict`` of arguments already checked."""
    return _normalized(*_spread(belief, model, delta, noise, compiled))


def _spread(belief: FloatArray, model: GridModel, delta: tuple[float, float, float],
            noise: OdometryNoise, compiled: bool = True,
            grid_states: int | None = None) -> tuple[FloatArray, float]:
    """The prediction before it is normalized, and its sum (the probability left on free
    cells): a belief held in several windows (grid/window.py) is normalized over all.
    ``grid_states``: the states of the grid a window is cut from, which choose the
    compiled kernels or numpy's (``compiled_kernels``) as for the whole grid."""
    kernels = compiled_kernels(grid_states or belief.size, compiled)
    if kernels is not None:
        return _spread_compiled(kernels, belief, model, delta, noise)
    rot1, trans, rot2 = delta
    shift_rows, shift_cols = _bounded_shifts(model, rot1, trans)
    shifted = np.empty_like(belief)
    for k in range(model.heading_bins):
        shifted[k] = _shift_bilinear(belief[k], shift_cols[k], shift_rows[k])
    turned = _shift_headings(shifted, (rot1 + rot2) / model.bin_width)
    sigma_cells, sigma_bins = _motion_noise(delta, noise, model)
    rows, cols = model.free.shape
    spread = _blur_cyclic(turned, _heading_taps(sigma_bins, model.heading_bins), axis=0)
    spread = _blur(spread, _reaching_taps(sigma_cells, rows), axis=1)
    spread = _blur(spread, _reaching_taps(sigma_cells, cols), axis=2)
    spread *= model.free[None, :, :]
    return spread, float(spread.sum())


def _spread_compiled(kernels: ModuleType, belief: FloatArray, model: GridModel,
                     delta: tuple[float, float, float],
                     noise: OdometryNoise) -> tuple[FloatArray, float]:
    rot1, trans, rot2 = delta
    shift_rows, shift_cols = _bounded_shifts(model, rot1, trans)
    sigma_cells, sigma_bins = _motion_noise(delta, noise, model)
    rows, cols = model.free.shape
    first, second = np.empty_like(belief), np.empty_like(belief)
    kernels.shift_motion(belief, shift_rows, shift_cols, (rot1 + rot2) / model.bin_width, first)
    taps = _heading_taps(sigma_bins, model.heading_bins)
    if not _identity(taps):
        kernels.blur_headings(first, taps, second)
        first, second = second, first
    taps = _reaching_taps(sigma_cells, rows)
    if not _identity(taps):
        kernels.blur_rows(first, taps, second)
        first, second = second, first
    total = kernels.blur_cols_masked(first, _reaching_taps(sigma_cells, cols), model.free,
                                     second)
    return second, float(total)


def _normalized(belief: FloatArray, total: float) -> FloatArray:
    if not total > 0:
        raise ZeroEvidenceError("delta: the motion left no probability on a free cell")
    belief /= total
    return belief


# --- correction ----------------------------------------------------------------------------


def beam_endpoints(model: GridModel, ranges: FloatArray, angles: FloatArray) -> np.ndarray:
    """(K, beams, 2) integer (row, column) offsets of each beam's end point from the
    state cell, for each heading bin: the cell the end point falls in, measured from
    the state cell's centre. Offsets are cut to the map's size (rows, columns): an end
    point that far is off the map from every state cell, however far it is."""
    return _beam_endpoints(_check_model(model), *check_scan(ranges, angles))


def _beam_endpoints(model: GridModel, ranges: FloatArray, angles: FloatArray) -> np.ndarray:
    rows, cols = model.free.shape
    headings = model.headings()
    mount_x, mount_y, mount_yaw = model.laser_pose
    theta = (headings + mount_yaw)[:, None] + angles[None, :]
    # Where the laser sits, in cells from the state cell's centre, for each heading (0 for
    # a laser at the centre: the sums below are then the same bits as without it).
    mount_rows = ((mount_x * np.sin(headings) + mount_y * np.cos(headings))
                  / model.resolution)[:, None]
    mount_cols = ((mount_x * np.cos(headings) - mount_y * np.sin(headings))
                  / model.resolution)[:, None]
    # A beam of rows + cols cells or more is longer than the map's diagonal: it ends off
    # the map from every state cell, as it does at that length, which keeps the products
    # finite (a range of 1e300 m in cells may overflow, and inf * sin(0) is NaN).
    with np.errstate(over="ignore"):
        r = np.minimum(ranges[None, :] / model.resolution, float(rows + cols))
    ends = np.stack([np.clip(np.floor(0.5 + (mount_rows + r * np.sin(theta))), -rows, rows),
                     np.clip(np.floor(0.5 + (mount_cols + r * np.cos(theta))), -cols, cols)],
                    axis=-1)
    return ends.astype(np.int64)


def scan_log_likelihood(model: GridModel, ranges: FloatArray, angles: FloatArray,
                        compiled: bool = True) -> FloatArray:
    """Sum over the beams of log p(beam | state), for every state: (K, H, W).

    ``ranges`` and ``angles`` are the beams to use, without the readings of no return
    (``check_scan`` says which and what happens to them).
    """
    _check_model(model)
    return _scan_log_likelihood(model, *check_scan(ranges, angles), compiled)


def _scan_log_likelihood(model: GridModel, ranges: FloatArray, angles: FloatArray,
                         compiled: bool = True,
                         box: tuple[int, int, int, int] | None = None) -> FloatArray:
    """The scan's log likelihood over every state, or over the states of the window
    ``box`` (first row, row past the last, first column, column past the last; see
    grid/window.py): (K, rows, columns) of the box. The compiled kernels or numpy's are
    chosen by the grid's states, not the box's: numpy's cost a pass per heading and
    beam, whatever the box's size."""
    if ranges.size * model.log_bound > LOG_SUM_LIMIT:
        raise InvalidInputError(f"ranges: {ranges.size} beams over log likelihoods as large "
                                f"as {model.log_bound:g} would overflow their sum")
    offsets = _beam_endpoints(model, ranges, angles)
    padded, pad_rows, pad_cols = _padded_field(model, offsets)
    r0, r1, c0, c1 = box if box is not None else (0, model.free.shape[0], 0,
                                                  model.free.shape[1])
    # The window's cell (i, j) is the map's (r0 + i, c0 + j): the same field, read
    # from further in.
    pad_rows, pad_cols = pad_rows + r0, pad_cols + c0
    rows, cols = r1 - r0, c1 - c0
    shape = (model.heading_bins, rows, cols)
    kernels = compiled_kernels(_states(model), compiled)
    if kernels is not None:
        out = np.empty(shape)      # the kernel writes every element
        kernels.scan_log_likelihood(padded, pad_rows, pad_cols, offsets, model.heading_bins,
                                    rows, cols, out)
        return out
    total = np.zeros(shape)
    for k in range(model.heading_bins):
        layer = total[k]
        for dr, dc in offsets[k]:
            layer += padded[pad_rows + dr:pad_rows + dr + rows, pad_cols + dc:pad_cols + dc + cols]
    return total


def _scan_log_likelihood_strided(model: GridModel, ranges: FloatArray, angles: FloatArray,
                                 step: int, compiled: bool = True,
                                 cells: np.ndarray | None = None) -> FloatArray:
    """The scan's log likelihood at every ``step``-th heading, row and column: the
    states (step k, step i, step j) of ``_scan_log_likelihood``, in its order of sums;
    0 at the lattice's cells that are not free, or not in ``cells`` (a mask over the
    lattice's cells, at most its free ones) where given: only those are scored."""
    offsets = np.ascontiguousarray(_beam_endpoints(model, ranges, angles)[::step])
    padded, pad_rows, pad_cols = _padded_field(model, offsets)
    lattice_free = model.free[::step, ::step] if cells is None else cells
    shape = (offsets.shape[0], *lattice_free.shape)
    kernels = compiled_kernels(_states(model), compiled)   # as the grid's other steps
    if kernels is not None:
        out = np.empty(shape)
        rows, columns = np.nonzero(lattice_free)
        row_starts = np.searchsorted(rows, np.arange(shape[1] + 1))
        # nonzero's arrays are strided views: contiguous ones are what warm_up compiled for.
        kernels.scan_log_likelihood_strided(padded, pad_rows, pad_cols, offsets, step,
                                            row_starts, np.ascontiguousarray(columns), out)
        return out
    total = np.zeros(shape)
    rows, cols = shape[1:]
    for k in range(shape[0]):
        layer = total[k]
        for dr, dc in offsets[k]:
            layer += padded[pad_rows + dr:pad_rows + dr + step * rows:step,
                            pad_cols + dc:pad_cols + dc + step * cols:step]
    total *= lattice_free
    return total


def _padded_field(model: GridModel, offsets: np.ndarray) -> tuple[FloatArray, int, int]:
    """The log field with a border of ``log_outside`` wide enough for every offset: at
    most (3 H + 2) x (3 W + 2) values, since the offsets are cut to the map's size."""
    pad_rows = int(np.abs(offsets[..., 0]).max(initial=0)) + 1
    pad_cols = int(np.abs(offsets[..., 1]).max(initial=0)) + 1
    padded = np.pad(model.log_field, ((pad_rows, pad_rows), (pad_cols, pad_cols)),
                    constant_values=model.log_outside)
    return padded, pad_rows, pad_cols


def correct_scan(belief: FloatArray, model: GridModel, ranges: FloatArray, angles: FloatArray,
                 compiled: bool = True,
                 independent_beams: int | None = None) -> tuple[FloatArray, float]:
    """``correct`` with a scan: posterior and log evidence. (A compiled kernel that also
    weighted each row as soon as its beams were summed measured slower: numba's scalar exp
    costs more than the pass numpy's vectorized one needs.)

    ``independent_beams`` K: the scan counts as K independent beams, not N (see
    ``scan_weight``); None: every beam is independent of the others."""
    _check_model(model)
    belief = check_belief(belief, model)
    ranges, angles = check_scan(ranges, angles)
    weight = 1.0 if independent_beams is None else scan_weight(independent_beams, ranges.size)
    return _correct_scan(belief, model, ranges, angles, compiled, weight)


def scan_weight(independent_beams: int, beams: int) -> float:
    """min(1, K / N): the power the likelihood of N beams is raised to when they carry the
    information of K independent ones (a tempered likelihood). Neighbouring beams' errors
    are correlated (the same grid's heading and position quantization, the same odometry
    error, the same unmapped object), so the product of N beam likelihoods is far sharper
    than what the scan tells; AMCL's beam skipping and Thrun et al.'s advice to use a
    subset of beams are the same remedy."""
    independent_beams = check_integer("independent_beams", independent_beams)
    if independent_beams < 1:
        raise InvalidInputError(f"independent_beams: expected >= 1, got {independent_beams}")
    return min(1.0, independent_beams / beams) if beams else 1.0


def _correct_scan(belief: FloatArray, model: GridModel, ranges: FloatArray, angles: FloatArray,
                  compiled: bool = True, weight: float = 1.0,
                  box: tuple[int, int, int, int] | None = None) -> tuple[FloatArray, float]:
    """``correct_scan`` of arguments already checked; with ``box``, ``belief`` is the
    window's (grid/window.py), zero outside it."""
    def log_likelihood() -> FloatArray:
        total = _scan_log_likelihood(model, ranges, angles, compiled, box)
        if weight != 1.0:
            np.multiply(total, weight, out=total)
        return total

    return _correct_in(log_likelihood(), belief, log_likelihood)


def _correct_in(log_likelihood: FloatArray, belief: FloatArray,
                again: Callable[[], FloatArray]) -> tuple[FloatArray, float]:
    """``correct``, the posterior written over ``log_likelihood`` (an array of ours): a
    tensor of millions of states allocated anew costs more than the arithmetic.

    The weights are taken relative to the largest log likelihood. When that is of a state
    the belief rules out and so far above the others that every weight underflows, the
    log likelihood is made ``again`` and weighed relative to the largest among the states
    the belief allows: the evidence was not zero, only too small for that scale.
    """
    peak = float(log_likelihood.max())
    if not peak < math.inf:   # NaN anywhere makes the maximum NaN
        raise InvalidInputError(f"log_likelihood: expected numbers below inf, got "
                                f"{'NaN' if math.isnan(peak) else peak}")
    if peak == -math.inf:
        raise ZeroEvidenceError("every state rules the scan out (log likelihood -inf)")
    weighted, total = _weighted(log_likelihood, peak, belief)
    if not total > 0:
        possible = belief > 0
        if possible.any():
            log_likelihood = again()
            log_likelihood[~possible] = -math.inf   # exp(+huge) * 0 would be NaN
            peak = float(log_likelihood.max())
            if peak > -math.inf:
                weighted, total = _weighted(log_likelihood, peak, belief)
    if not total > 0:
        raise ZeroEvidenceError("every state with probability rules the scan out")
    weighted /= total
    return weighted, peak + math.log(total)


def _weighted(log_likelihood: FloatArray, peak: float,
              belief: FloatArray) -> tuple[FloatArray, float]:
    """belief * exp(log_likelihood - peak), written over log_likelihood, and its sum."""
    weighted = np.subtract(log_likelihood, peak, out=log_likelihood)
    np.exp(weighted, out=weighted)
    np.multiply(weighted, belief, out=weighted)
    return weighted, float(weighted.sum())


def correct(belief: FloatArray, log_likelihood: FloatArray) -> tuple[FloatArray, float]:
    """Posterior and log evidence log p(z) = log sum(belief * exp(log_likelihood)).

    ``log_likelihood`` of the belief's shape, below inf (-inf: that state is ruled out).
    """
    belief = _any_belief(belief, ndim=None)
    given = as_real_array("log_likelihood", log_likelihood)
    if given.shape != belief.shape:
        raise InputSizeError(f"belief, log_likelihood: expected one shape, got "
                             f"{belief.shape} and {given.shape}")
    return _correct_in(np.array(given, dtype=np.float64), belief,
                       lambda: np.array(given, dtype=np.float64))


# --- what the belief says ------------------------------------------------------------------


def most_likely_state(belief: FloatArray) -> tuple[int, int, int]:
    return _most_likely_state(_any_belief(belief))


def _most_likely_state(belief: FloatArray) -> tuple[int, int, int]:
    k, i, j = np.unravel_index(int(np.argmax(belief)), belief.shape)
    return int(k), int(i), int(j)


def pose_of(model: GridModel, state: tuple[int, int, int]) -> tuple[float, float, float]:
    """(x, y, yaw) of a state cell's centre."""
    _check_model(model)
    try:
        k, i, j = (check_integer("state", v) for v in state)
    except (TypeError, ValueError):
        raise InvalidInputError(f"state: expected (k, i, j) integers, got {short(state)}") \
            from None
    if not all(0 <= v < n for v, n in zip((k, i, j), model.shape)):
        raise InvalidInputError(f"state: expected (k, i, j) within {model.shape}, got "
                                f"{(k, i, j)}")
    return _pose_of(model, (k, i, j))


def _centres(model: GridModel,
             box: tuple[int, int, int, int] | None) -> tuple[FloatArray, FloatArray]:
    """The cell centres of the map, or of the window ``box`` (grid/window.py) of it: the
    map's own, so that a window's distances are the dense filter's to the last bit."""
    xs, ys = model.cell_centres()
    if box is None:
        return xs, ys
    r0, r1, c0, c1 = box
    return xs[c0:c1], ys[r0:r1]


def _pose_of(model: GridModel, state: tuple[int, int, int],
             box: tuple[int, int, int, int] | None = None) -> tuple[float, float, float]:
    """With ``box``, ``state`` is of the window's belief."""
    k, i, j = state
    xs, ys = _centres(model, box)
    return float(xs[j]), float(ys[i]), float(_wrap_scalar(k * model.bin_width))


def refined_pose(belief: FloatArray, model: GridModel,
                 state: tuple[int, int, int]) -> tuple[float, float, float]:
    """The belief's mean over ``state`` and its neighbours (one cell and one heading bin
    each way, headings cyclic): a pose finer than the grid, near the mode."""
    _check_model(model)
    pose_of(model, state)     # validates the state
    return _refined_pose(check_belief(belief, model), model, state)


def _refined_pose(belief: FloatArray, model: GridModel, state: tuple[int, int, int],
                  box: tuple[int, int, int, int] | None = None) -> tuple[float, float, float]:
    """With ``box``, ``state`` is of the window's belief. The cell centres of a
    neighbourhood weighted by their probability; a mode whose neighbours have none is its
    own centre."""
    k, i, j = state
    xs, ys = _centres(model, box)
    rows = slice(max(i - 1, 0), i + 2)
    cols = slice(max(j - 1, 0), j + 2)
    bins = (k + np.arange(-1, 2)) % belief.shape[0]
    near = belief[bins][:, rows, cols]
    total = float(near.sum())
    if not total > 0:
        return _pose_of(model, state, box)
    x = float(near.sum(axis=(0, 1)) @ xs[cols]) / total
    y = float(near.sum(axis=(0, 2)) @ ys[rows]) / total
    # Offsets of -1, 0, +1 bins from the mode's heading: no wrap within the neighbourhood.
    shift = float(near.sum(axis=(1, 2)) @ np.arange(-1.0, 2.0)) / total
    return x, y, float(_wrap_scalar((k + shift) * model.bin_width))


def covariance_around(belief: FloatArray, model: GridModel,
                      pose: tuple[float, float, float]) -> FloatArray:
    """The 3 x 3 second moment of (x, y, yaw) about ``pose`` under the belief (yaw
    differences wrapped to (-pi, pi]), plus the grid's own quantization variance."""
    _check_model(model)
    pose = check_pose("pose", pose)
    cov = _covariance_around(check_belief(belief, model), model, pose)
    if not np.isfinite(cov).all():
        raise NonFiniteResultError(f"pose: {pose} is too far from the map for a finite "
                                   f"second moment")
    return cov


def _covariance_around(belief: FloatArray, model: GridModel,
                       pose: tuple[float, float, float],
                       box: tuple[int, int, int, int] | None = None) -> FloatArray:
    xs, ys = _centres(model, box)
    px = belief.sum(axis=(0, 1))
    py = belief.sum(axis=(0, 2))
    pk = belief.sum(axis=(1, 2))
    dx, dy = xs - pose[0], ys - pose[1]
    dyaw = _wrap(model.headings() - pose[2])
    pxy = belief.sum(axis=0)
    cov = np.empty((3, 3))
    with np.errstate(over="ignore", invalid="ignore"):
        cov[0, 0] = px @ (dx * dx)
        cov[1, 1] = py @ (dy * dy)
        cov[2, 2] = pk @ (dyaw * dyaw)
        cov[0, 1] = cov[1, 0] = float(dy @ pxy @ dx)
        cov[0, 2] = cov[2, 0] = float(dyaw @ belief.sum(axis=1) @ dx)
        cov[1, 2] = cov[2, 1] = float(dyaw @ belief.sum(axis=2) @ dy)
    quantization = np.diag([model.resolution ** 2 / 12] * 2 + [model.bin_width ** 2 / 12])
    return cov + quantization


def mass_near(belief: FloatArray, model: GridModel, pose: tuple[float, float, float],
              radius: float, angle: float) -> float:
    """The belief's probability within ``radius`` (m) and ``angle`` (rad) of ``pose``:
    how sure the robot is of that pose (1: certain, near 0: lost)."""
    _check_model(model)
    pose = check_pose("pose", pose)
    radius, angle = check_non_negative("radius", radius), check_non_negative("angle", angle)
    return _mass_near(check_belief(belief, model), model, pose, radius, angle)


def _mass_near(belief: FloatArray, model: GridModel, pose: tuple[float, float, float],
               radius: float, angle: float,
               box: tuple[int, int, int, int] | None = None) -> float:
    xs, ys = _centres(model, box)
    dx, dy = xs[None, :] - pose[0], ys[:, None] - pose[1]
    if radius < 1e150:
        with np.errstate(over="ignore"):   # a pose that far is near no cell: inf > r^2
            near_xy = (dx ** 2 + dy ** 2) <= radius ** 2
    else:   # r^2 would overflow (an OverflowError of Python's floats): compare distances
        near_xy = np.hypot(dx, dy) <= radius
    near_k = np.abs(_wrap(model.headings() - pose[2])) <= angle
    return float(belief[near_k][:, near_xy].sum())


def belief_map(belief: FloatArray) -> np.ndarray:
    """The belief's maximum over headings scaled to 0..100 (int8), the largest 100: the
    picture an OccupancyGrid display draws."""
    return _belief_map(_any_belief(belief))


def _belief_map(belief: FloatArray) -> np.ndarray:
    top = belief.max(axis=0)
    peak = top.max()
    scaled = np.rint(100.0 * top / peak) if peak > 0 else np.zeros_like(top)
    return scaled.astype(np.int8)


def entropy_bits(belief: FloatArray) -> float:
    return _entropy_bits(_any_belief(belief, ndim=None))


def _entropy_bits(belief: FloatArray) -> float:
    positive = belief[belief > 0]
    return float(-(positive * np.log2(positive)).sum()) + 0.0


# --- the steps' pieces ---------------------------------------------------------------------


def _wrap(angles: FloatArray) -> FloatArray:
    """Angles to (-pi, pi]."""
    return np.pi - np.mod(np.pi - np.asarray(angles, dtype=np.float64), TWO_PI)


def _wrap_scalar(angle: float) -> float:
    return math.pi - (math.pi - angle) % TWO_PI


def _shift_bilinear(layer: FloatArray, shift_cols: float, shift_rows: float) -> FloatArray:
    """``layer`` moved by a fractional number of columns and rows: each cell's mass split
    over the four nearest target cells by bilinear weights; what leaves the grid is lost."""
    base_c, base_r = math.floor(shift_cols), math.floor(shift_rows)
    frac_c, frac_r = shift_cols - base_c, shift_rows - base_r
    out = np.zeros_like(layer)
    for dr, wr in ((0, 1.0 - frac_r), (1, frac_r)):
        for dc, wc in ((0, 1.0 - frac_c), (1, frac_c)):
            weight = wr * wc
            if weight > 0:
                _add_shifted(out, layer, base_r + dr, base_c + dc, weight)
    return out


def _add_shifted(out: FloatArray, layer: FloatArray, rows: int, cols: int,
                 weight: float) -> None:
    """out[i + rows, j + cols] += weight * layer[i, j], where both are inside."""
    height, width = layer.shape
    if abs(rows) >= height or abs(cols) >= width:
        return
    src_r = slice(max(0, -rows), min(height, height - rows))
    dst_r = slice(max(0, rows), min(height, height + rows))
    src_c = slice(max(0, -cols), min(width, width - cols))
    dst_c = slice(max(0, cols), min(width, width + cols))
    out[dst_r, dst_c] += weight * layer[src_r, src_c]


def _shift_headings(belief: FloatArray, shift_bins: float) -> FloatArray:
    """Headings turned by a fractional number of bins (cyclic, linear weights)."""
    base = math.floor(shift_bins)
    frac = shift_bins - base
    out = (1.0 - frac) * np.roll(belief, base, axis=0)
    if frac > 0:
        out += frac * np.roll(belief, base + 1, axis=0)
    return out


def _half_width(sigma: float) -> int:
    """How many taps either side ``gaussian_taps`` lists (3 sigma), or one more than it
    may (MAX_TAPS_HALF_WIDTH + 1) for a wider, or infinite, sigma."""
    three = 3.0 * sigma
    return math.ceil(three) if three <= MAX_TAPS_HALF_WIDTH else MAX_TAPS_HALF_WIDTH + 1


def gaussian_taps(sigma: float) -> FloatArray:
    """A normalized Gaussian kernel of std ``sigma`` (in cells) over -3 sigma..3 sigma;
    [1] when sigma is too small to spread. At most MAX_TAPS_HALF_WIDTH taps either side:
    a wider sigma is refused (the steps cut theirs to the axis, see ``_reaching_taps``)."""
    sigma = check_non_negative("sigma", sigma)
    half = _half_width(sigma)
    if half > MAX_TAPS_HALF_WIDTH:
        raise InvalidInputError(f"sigma: {sigma:g} cells needs more than "
                                f"{MAX_TAPS_HALF_WIDTH} taps either side")
    return _gaussian_taps(sigma, half)


def _gaussian_taps(sigma: float, half: int) -> FloatArray:
    if half == 0:
        return np.ones(1)
    offsets = np.arange(-half, half + 1)
    taps = np.exp(-0.5 * (offsets / sigma) ** 2)
    return taps / taps.sum()


def _identity(taps: FloatArray) -> bool:
    return taps.size == 1 and taps[0] == 1.0


def _reaching_taps(sigma: float, length: int) -> FloatArray:
    """The taps of a blur of std ``sigma`` along an axis of ``length`` cells (not cyclic).

    Taps more than length - 1 away reach only the zeros beyond the edge, so they are cut:
    the blur is the same, bit for bit, and its cost and memory follow the axis, not
    sigma. A sigma too wide to list its taps (beyond MAX_TAPS_HALF_WIDTH) gets those within
    reach normalized among themselves: the prediction is normalized at its end, so only
    the taps' ratios matter (an infinite sigma spreads evenly).
    """
    half = _half_width(sigma)
    reach = length - 1
    if half <= reach:
        return _gaussian_taps(sigma, half)
    if half <= MAX_TAPS_HALF_WIDTH:
        return _gaussian_taps(sigma, half)[half - reach:half + reach + 1]
    offsets = np.arange(-reach, reach + 1)
    taps = np.exp(-0.5 * (offsets / sigma) ** 2)
    return taps / taps.sum()


def _heading_taps(sigma: float, bins: int) -> FloatArray:
    """The taps of the cyclic blur of std ``sigma`` over ``bins`` headings.

    Up to 3 sigma of four turns (4 K taps either side) they are ``gaussian_taps``, the
    blur passing over the headings once per tap. A wider kernel is folded around the
    circle (the taps of each heading offset modulo K summed), so the blur takes at most
    K + 1 passes whatever sigma: the same blur, to rounding. Beyond MAX_TAPS_HALF_WIDTH
    taps (a std of over 349,000 bins, an infinite one included) the spread is uniform:
    the folded kernel differs from even by less than 0.005 K / sigma there.
    """
    half = _half_width(sigma)
    if half <= 4 * bins:
        return _gaussian_taps(sigma, half)
    if half > MAX_TAPS_HALF_WIDTH:
        return np.full(bins, 1.0 / bins)
    folded = np.bincount(np.arange(-half, half + 1) % bins, weights=_gaussian_taps(sigma, half),
                         minlength=bins)
    # Centred taps for offsets -(K // 2)..K // 2: each residue once (for an even K the
    # last offset, K / 2, is the first one again and gets nothing).
    centre = bins // 2
    return np.concatenate([folded[np.arange(-centre, bins - centre) % bins],
                           np.zeros(1 - bins % 2)])


def _blur(belief: FloatArray, taps: FloatArray, axis: int) -> FloatArray:
    """Spread along ``axis`` (not cyclic: what spreads past the edge is lost)."""
    if _identity(taps):
        return belief
    half = taps.size // 2
    moved = np.moveaxis(belief, axis, -1)
    padded = np.pad(moved, [(0, 0)] * (moved.ndim - 1) + [(half, half)])
    out = np.zeros_like(moved)
    n = moved.shape[-1]
    for index, tap in enumerate(taps):
        out += tap * padded[..., index:index + n]
    return np.moveaxis(out, -1, axis)


def _blur_cyclic(belief: FloatArray, taps: FloatArray, axis: int) -> FloatArray:
    """Spread along a cyclic ``axis`` (the headings)."""
    if _identity(taps):
        return belief
    half = taps.size // 2
    out = np.zeros_like(belief)
    for index, tap in enumerate(taps):
        out += tap * np.roll(belief, index - half, axis=axis)
    return out
