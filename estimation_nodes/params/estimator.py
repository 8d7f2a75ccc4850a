"""Builders from parameter values to validated core models, one per node.

Nothing here imports rclpy, so the same validation runs at start-up, on every
runtime parameter change, in offline tools and in plain unit tests. Every
error is a ``ValueError`` whose message starts with the parameter's name.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from estimation_nodes.core.kalman.models import (
    GaussianState,
    LinearGaussianModel,
    ScalarKalmanModel,
)
from estimation_nodes.core.tiles import histogram
from estimation_nodes.core.tiles.models import HistogramModel, MotionKernel, check_belief
from estimation_nodes.core.validation import (
    FloatArray,
    as_finite_array,
    check_covariance,
    check_finite,
    check_probability_vector,
)
from estimation_nodes.params.specs import (
    MATRIX_SPECS,
    MAX_STATE,
    MAX_VARIANCE,
    MIN_VARIANCE,
    UNSET,
    WORLD_SPECS,
)


def as_list(name: str, value: Any) -> list:
    """A parameter that must be a list; an empty or unset one arrives as None or bytes."""
    if value is UNSET or isinstance(value, (str, bytes)) or not hasattr(value, "__len__"):
        raise ValueError(f"{name}: expected a non-empty list, got {value!r}")
    return list(value)


def read_world_file(path_text: str) -> list[str]:
    """The class names in a world file; ValueError with a one-line reason otherwise."""
    path = Path(path_text).expanduser()
    if not path.is_file():
        raise ValueError(f"world_file: {path_text!r} is not a file")
    try:
        names = path.read_text(encoding="utf-8").split()
    except (OSError, UnicodeDecodeError) as error:
        raise ValueError(f"world_file: cannot read {path_text!r}: {error}") from None
    if not names:
        raise ValueError(f"world_file: {path_text!r} names no cells")
    return names


def build_histogram_model(values: Mapping[str, Any]) -> HistogramModel:
    """The world, sensor model and motion kernel from parameter values."""
    world_file = values.get("world_file") or ""
    world = read_world_file(world_file) if world_file else as_list("world", values["world"])
    return HistogramModel.from_lists(
        world=world,
        classes=as_list("classes", values["classes"]),
        sensor_model=as_list("sensor_model", values["sensor_model"]),
        kernel=as_list("motion_kernel", values["motion_kernel"]),
    )


def build_initial_belief(values: Mapping[str, Any], size: int) -> FloatArray:
    """The prior: the given initial_belief, or uniform when it is unset."""
    given = values.get("initial_belief")
    if given is UNSET or (hasattr(given, "__len__") and len(given) == 0):
        return histogram.uniform(size)
    return check_belief("initial_belief", as_list("initial_belief", given), size)


def _within(name: str, value: Any, low: float, high: float) -> float:
    """A finite number in [low, high] (the bounds the parameter's descriptor states)."""
    number = check_finite(name, value)
    if not low <= number <= high:
        raise ValueError(f"{name}: expected a number in [{low:g}, {high:g}], got {value!r}")
    return number


def _entries(name: str, flat: Any) -> FloatArray:
    """A flat list of finite numbers within +-MAX_STATE."""
    values = as_finite_array(name, as_list(name, flat), ndim=1)
    if values.size and float(np.max(np.abs(values))) > MAX_STATE:
        raise ValueError(f"{name}: expected entries within +-{MAX_STATE:g}, "
                         f"got {float(np.max(np.abs(values))):g}")
    return values


def _matrix(name: str, flat: Any, rows: int) -> FloatArray:
    """Reshape a row-major flat list into ``rows`` rows, naming the parameter on error."""
    values = _entries(name, flat)
    if rows < 1 or values.size == 0 or values.size % rows != 0:
        raise ValueError(
            f"{name}: expected a row-major matrix with {rows} rows, got {values.size} values"
        )
    return values.reshape(rows, -1)


@dataclass(frozen=True)
class KalmanSettings:
    """Which Kalman filter the estimator runs (the model's type says) and where it starts."""

    initial: GaussianState
    model: ScalarKalmanModel | LinearGaussianModel
    #: State index shown as pose x, y, z, roll, pitch, yaw (-1: none), up to six.
    pose_components: tuple[int, ...] = (0,)

    @property
    def mode(self) -> str:
        """'scalar' (the book's Algorithm 4) or 'matrix'."""
        return "scalar" if isinstance(self.model, ScalarKalmanModel) else "matrix"


def build_kalman_settings(values: Mapping[str, Any]) -> KalmanSettings:
    """Kalman model and initial state from parameter values.

    The mode's own parameters must agree with each other; the other mode's are
    checked one by one only (the mode is read-only, so they never run), so a
    matrix value that does not fit the rest yet never holds up the scalar filter.
    """
    mode = _kalman_mode("kalman.mode", values["kalman.mode"])
    components = _pose_components("kalman.pose_components", values["kalman.pose_components"])
    if mode == "scalar":
        for name in MATRIX_NAMES:
            check_estimator_value(name, values[name])
        x0 = _within("kalman.x0", values["kalman.x0"], -MAX_STATE, MAX_STATE)
        P0, var_u, var_z = (_within(name, values[name], MIN_VARIANCE, MAX_VARIANCE)
                            for name in ("kalman.P0", "kalman.var_u", "kalman.var_z"))
        initial = GaussianState(np.array([x0]), np.array([[P0]]))
        model: ScalarKalmanModel | LinearGaussianModel = ScalarKalmanModel(var_u, var_z)
    else:
        for name in SCALAR_NAMES:
            check_estimator_value(name, values[name])
        initial, model = _build_matrix_model(values, "kalman.matrix.")
    n = initial.x.size
    if max(components) >= n:
        raise ValueError(f"kalman.pose_components: expected state indices below n = {n} "
                         f"(or -1), got {list(components)}")
    return KalmanSettings(initial, model, components)


SCALAR_NAMES = ("kalman.x0", "kalman.P0", "kalman.var_u", "kalman.var_z")
MATRIX_NAMES = tuple(spec.name for spec in MATRIX_SPECS)


def _pose_components(name: str, value: Any) -> tuple[int, ...]:
    components = tuple(int(c) for c in as_list(name, value))
    if len(components) > 6 or min(components) < -1:
        raise ValueError(f"{name}: expected up to 6 state indices (-1 for none), "
                         f"got {list(components)}")
    return components


def _kalman_mode(name: str, value: Any) -> str:
    if value not in ("scalar", "matrix"):
        raise ValueError(f"{name}: expected 'scalar' or 'matrix', got {value!r}")
    return value


def _build_matrix_model(
    values: Mapping[str, Any], prefix: str
) -> tuple[GaussianState, LinearGaussianModel]:
    """The matrix filter's initial state and model (the book's Eq. 6.34), any sizes.

    n comes from x0, the input size m from B (n x m), the noise size q from F
    (n x q) and the measurement size p from C (p x n); every other matrix is
    checked against them. Errors name the full parameter, the shape it got and
    the shape it needs.
    """
    def given(name: str) -> FloatArray:
        return _entries(prefix + name, values[prefix + name])

    x0 = given("x0")
    n = x0.size
    B = _with_rows(prefix + "B", given("B"), n, "n x m: a row per state component, n = len(x0)")
    F = _with_rows(prefix + "F", given("F"), n, "n x q: a row per state component")
    C = _with_columns(prefix + "C", given("C"), n, "p x n: a column per state component")
    p, q = C.shape[0], F.shape[1]
    try:
        initial = GaussianState(x0, _shaped(prefix + "P0", given("P0"), n, n, "n x n"))
        model = LinearGaussianModel(
            A=_shaped(prefix + "A", given("A"), n, n, "n x n"),
            B=B, C=C, F=F,
            Q=_shaped(prefix + "Q", given("Q"), q, q, "q x q, q = columns of F"),
            R=_shaped(prefix + "R", given("R"), p, p, "p x p, p = rows of C"),
        )
    except ValueError as error:
        message = str(error)
        raise ValueError(message if message.startswith(prefix) else prefix + message) from None
    _positive_definite(prefix + "R", model.R)
    return initial, model


def _positive_definite(name: str, matrix: FloatArray) -> None:
    """A measurement without noise would make S = C P C' + R singular once P is."""
    if float(np.min(np.linalg.eigvalsh(matrix))) <= 0.0:
        raise ValueError(f"{name}: expected a positive definite matrix (every measurement "
                         f"has some noise), got {matrix.tolist()}")


def _shaped(name: str, values: FloatArray, rows: int, columns: int, needs: str) -> FloatArray:
    if values.size != rows * columns:
        raise ValueError(f"{name}: expected {rows} x {columns} ({needs}), "
                         f"got {values.size} values")
    return values.reshape(rows, columns)


def _with_rows(name: str, values: FloatArray, rows: int, needs: str) -> FloatArray:
    """``rows`` rows, as many columns as the values give (at least one)."""
    if values.size == 0 or values.size % rows:
        raise ValueError(f"{name}: expected {rows} x k values ({needs}), "
                         f"got {values.size} values")
    return values.reshape(rows, -1)


def _with_columns(name: str, values: FloatArray, columns: int, needs: str) -> FloatArray:
    """``columns`` columns, as many rows as the values give (at least one)."""
    if values.size == 0 or values.size % columns:
        raise ValueError(f"{name}: expected k x {columns} values ({needs}), "
                         f"got {values.size} values")
    return values.reshape(-1, columns)


def _square(name: str, flat: Any) -> FloatArray:
    flat = as_list(name, flat)
    size = int(round(np.sqrt(len(flat))))
    if size * size != len(flat):
        raise ValueError(f"{name}: expected a square matrix (k*k values), got {len(flat)} values")
    return _matrix(name, flat, size)


@dataclass(frozen=True)
class EstimatorSettings:
    """Everything the estimator's filters need, validated as one."""

    histogram: HistogramModel
    initial_belief: FloatArray
    kalman: KalmanSettings


#: The parameters the histogram model and the prior are built from.
HISTOGRAM_KEYS = tuple(spec.name for spec in WORLD_SPECS) + ("initial_belief",)


def build_estimator_settings(values: Mapping[str, Any]) -> EstimatorSettings:
    """Validate all estimator parameters together; ``ValueError`` names the first bad one."""
    model = build_histogram_model(values)
    initial_belief = build_initial_belief(values, model.size)
    _non_empty_text("frame_id", values["frame_id"])
    return EstimatorSettings(model, initial_belief, build_kalman_settings(values))


@dataclass(frozen=True)
class EstimatorUpdate:
    """What a set of parameter values changes: the settings to run on, and why a group is
    held (its parameters do not agree yet, so it keeps its settings in force)."""

    settings: EstimatorSettings
    #: The histogram parameters the settings' histogram model was built from.
    histogram_values: dict[str, Any]
    held: tuple[str, ...]


def update_estimator_settings(
    values: Mapping[str, Any], current: EstimatorSettings, histogram_values: Mapping[str, Any]
) -> EstimatorUpdate:
    """New settings from ``values``, group by group: the histogram (world, classes, sensor
    model, kernel, prior) and the Kalman filter each take the new values when those agree,
    and keep ``current``'s part otherwise, reported as held. So a change that needs several
    parameters waits for its last one without holding up the other group, and a Kalman
    variance change never re-reads a world file or rebuilds the likelihood tables of a
    million cells (``histogram_values``: what built the current histogram model).
    """
    held = []
    wanted = {key: values.get(key) for key in HISTOGRAM_KEYS}
    model, prior = current.histogram, current.initial_belief
    if wanted != {key: histogram_values.get(key) for key in HISTOGRAM_KEYS}:
        try:
            model = build_histogram_model(values)
            prior = build_initial_belief(values, model.size)
            histogram_values = wanted
        except ValueError as error:
            held.append(str(error))
            model, prior = current.histogram, current.initial_belief
    try:
        kalman = build_kalman_settings(values)
    except ValueError as error:
        held.append(str(error))
        kalman = current.kalman
    _non_empty_text("frame_id", values["frame_id"])
    return EstimatorUpdate(EstimatorSettings(model, prior, kalman), dict(histogram_values),
                           tuple(held))


def _non_empty_text(name: str, value: Any) -> str:
    if not isinstance(value, str) or not value.strip():
        raise ValueError(f"{name}: expected a non-empty name, got {value!r}")
    return value


def _class_names(name: str, value: Any) -> None:
    for item in as_list(name, value):
        _non_empty_text(name, item)


def _stochastic_square(name: str, value: Any) -> None:
    """k x k probabilities, each row summing to 1 (k is the number of classes, set apart)."""
    matrix = _square(name, value)
    for index, row in enumerate(matrix):
        check_probability_vector(f"{name} (row {index})", row)


def _covariance(name: str, value: Any) -> None:
    matrix = _square(name, value)
    check_covariance(name, matrix, matrix.shape[0])


def _prior(name: str, value: Any) -> None:
    if value is not UNSET and len(value):
        check_belief(name, as_list(name, value), len(value))


#: What can be said of one estimator parameter's value without the others. A change
#: that passes this is accepted; whether it fits the other parameters (the sensor
#: model's size, the prior's length, the matrices' shapes) is the whole set's
#: question, answered by build_estimator_settings.
_ALONE: dict[str, Callable[[str, Any], object]] = {
    "world": _class_names,
    "classes": _class_names,
    "sensor_model": _stochastic_square,
    "motion_kernel": lambda name, value: MotionKernel(np.asarray(as_list(name, value), float)),
    "initial_belief": _prior,
    "kalman.mode": _kalman_mode,
    "kalman.x0": lambda name, value: _within(name, value, -MAX_STATE, MAX_STATE),
    "kalman.P0": lambda name, value: _within(name, value, MIN_VARIANCE, MAX_VARIANCE),
    "kalman.var_u": lambda name, value: _within(name, value, MIN_VARIANCE, MAX_VARIANCE),
    "kalman.var_z": lambda name, value: _within(name, value, MIN_VARIANCE, MAX_VARIANCE),
    "kalman.matrix.x0": _entries,
    "kalman.matrix.P0": _covariance,
    "kalman.matrix.A": _square,
    "kalman.matrix.B": _entries,
    "kalman.matrix.C": _entries,
    "kalman.matrix.F": _entries,
    "kalman.matrix.Q": _covariance,
    "kalman.matrix.R": lambda name, value: _positive_definite(name, _square(name, value)),
    "kalman.pose_components": _pose_components,
    "frame_id": _non_empty_text,
}


def check_estimator_value(name: str, value: Any) -> None:
    """Raise ValueError if one parameter's value is wrong whatever the others are."""
    check = _ALONE.get(name)
    if check is not None:
        check(name, value)


@dataclass(frozen=True)
class SensorSettings:
    """The simulated sensor's world and noise, and its script when it replays one."""

    model: HistogramModel
    noise_std: float
    scripted_observations: tuple[str, ...]
    scripted_measurements: tuple[float, ...]

    @property
    def scripted(self) -> bool:
        """Whether the sensor replays a script instead of sampling."""
        return bool(self.scripted_observations or self.scripted_measurements)


def build_sensor_settings(values: Mapping[str, Any]) -> SensorSettings:
    """The tile sensor's settings; scripted classes must be classes of the model."""
    model = build_histogram_model(values)
    noise_std = float(np.sqrt(_within("measurement_variance", values["measurement_variance"],
                                      MIN_VARIANCE, MAX_VARIANCE)))
    observations = tuple(values["scripted_observations"] or ())
    for name in observations:
        try:
            model.sensor.index_of(name)
        except ValueError as error:
            raise ValueError(f"scripted_observations: {error}") from None
    measurements = tuple(check_finite("scripted_measurements", z)
                         for z in values["scripted_measurements"] or ())
    return SensorSettings(model, noise_std, observations, measurements)


@dataclass(frozen=True)
class CommanderSettings:
    """The motion commander's sequence and how many commands a run sends."""

    commands: tuple[int, ...]
    #: Commands to send in all; None repeats without end.
    limit: int | None
    #: When given, the sequence is these input vectors (kalman_input) instead of commands.
    vectors: tuple[tuple[float, ...], ...] = ()
    #: Nodes that must be matched subscribers before a command goes out.
    required_nodes: tuple[str, ...] = ()

    @property
    def length(self) -> int:
        return len(self.vectors or self.commands)


#: motion_cmd is std_msgs/Int32.
INT32_RANGE = (-(2**31), 2**31 - 1)


def build_commander_settings(values: Mapping[str, Any]) -> CommanderSettings:
    vectors = _input_vectors(values)
    given = values["commands"]
    if not vectors and (given is UNSET or not hasattr(given, "__len__")
                        or isinstance(given, (str, bytes)) or len(given) == 0):
        raise ValueError("commands: expected a list of at least one integer, got none")
    commands = tuple(int(c) for c in given or ())
    low, high = INT32_RANGE
    outside = [c for c in commands if not low <= c <= high]
    if outside:
        raise ValueError(f"commands: {outside[0]} does not fit motion_cmd (std_msgs/Int32: "
                         f"{low}..{high})")
    length = len(vectors or commands)
    limit = values["max_commands"] or None
    if not values["repeat"]:
        limit = min(limit or length, length)
    return CommanderSettings(commands, limit, vectors, _required_nodes(values, bool(vectors)))


#: Who must hear the commander, unless told: the estimator and the simulator it drives.
DEFAULT_REQUIRED_NODES = {False: ("estimator", "tile_sensor"),
                          True: ("estimator", "linear_system")}


def _required_nodes(values: Mapping[str, Any], vectors: bool) -> tuple[str, ...]:
    if not values["required_subscribers"]:
        return ()
    given = values.get("required_nodes", UNSET)
    if given is UNSET:
        return DEFAULT_REQUIRED_NODES[vectors]
    names = tuple(str(name).strip() for name in given)
    return tuple(name for name in names if name)


def _input_vectors(values: Mapping[str, Any]) -> tuple[tuple[float, ...], ...]:
    given = values.get("input_vectors")
    if given is UNSET or len(given) == 0:
        return ()
    flat = _entries("input_vectors", given)
    size = int(values["input_size"])
    rows = _with_columns("input_vectors", flat, size, f"input_size = {size} values a command")
    return tuple(tuple(float(v) for v in row) for row in rows)


@dataclass(frozen=True)
class LinearSystemSettings:
    """The simulated system of Eq. 6.34 and its true initial state."""

    model: LinearGaussianModel
    initial_state: FloatArray


def build_linear_system_settings(values: Mapping[str, Any]) -> LinearSystemSettings:
    initial, model = _build_matrix_model(values, "kalman.matrix.")
    given = values.get("true_initial_state")
    if given is UNSET or len(given) == 0:
        return LinearSystemSettings(model, initial.x)
    state = _entries("true_initial_state", given)
    if state.size != model.state_size:
        raise ValueError(f"true_initial_state: expected {model.state_size} values (n), "
                         f"got {state.size}")
    return LinearSystemSettings(model, state)


#: Bytes one reorder-history entry costs besides its saved belief and Kalman state.
REORDER_ENTRY_OVERHEAD = 512


def reorder_max_events(memory_mb: float, cells: int, state_size: int) -> int:
    """How many events the reorder history may keep within ``memory_mb``: each saves one
    belief (cells doubles) and one Kalman state (x and P)."""
    per_event = 8 * (cells + state_size + state_size * state_size) + REORDER_ENTRY_OVERHEAD
    return max(1, int(memory_mb * 2**20) // per_event)
