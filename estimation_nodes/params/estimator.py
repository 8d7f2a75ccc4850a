"""The estimator's settings: the histogram model and prior, the Kalman filter, validated as
one at start-up and group by group on a runtime change.

Nothing here imports rclpy, so the same validation runs at start-up, on every
runtime parameter change, in offline tools and in plain unit tests. Every
error is a ``ValueError`` whose message starts with the parameter's name.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from estimation_nodes.core.kalman.models import (
    GaussianState,
    LinearGaussianModel,
    ScalarKalmanModel,
)
from estimation_nodes.core.tiles.models import HistogramModel, MotionKernel, check_belief
from estimation_nodes.core.validation import (
    FloatArray,
    check_covariance,
    check_probability_vector,
)
from estimation_nodes.params.models import (
    build_histogram_model,
    build_initial_belief,
    build_matrix_model,
)
from estimation_nodes.params.specs import MATRIX_SPECS, UNSET, WORLD_SPECS
from estimation_nodes.params.values import (
    as_list,
    bounded,
    entries,
    non_empty_text,
    positive_definite,
    square,
)


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
        x0 = bounded("kalman.x0", values["kalman.x0"])
        P0, var_u, var_z = (bounded(name, values[name])
                            for name in ("kalman.P0", "kalman.var_u", "kalman.var_z"))
        initial = GaussianState(np.array([x0]), np.array([[P0]]))
        model: ScalarKalmanModel | LinearGaussianModel = ScalarKalmanModel(var_u, var_z)
    else:
        for name in SCALAR_NAMES:
            check_estimator_value(name, values[name])
        initial, model = build_matrix_model(values, "kalman.matrix.")
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
    non_empty_text("frame_id", values["frame_id"])
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
    non_empty_text("frame_id", values["frame_id"])
    return EstimatorUpdate(EstimatorSettings(model, prior, kalman), dict(histogram_values),
                           tuple(held))

def _class_names(name: str, value: Any) -> None:
    for item in as_list(name, value):
        non_empty_text(name, item)

def _stochastic_square(name: str, value: Any) -> None:
    """k x k probabilities, each row summing to 1 (k is the number of classes, set apart)."""
    matrix = square(name, value)
    for index, row in enumerate(matrix):
        check_probability_vector(f"{name} (row {index})", row)

def _covariance(name: str, value: Any) -> None:
    matrix = square(name, value)
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
    "kalman.x0": bounded,
    "kalman.P0": bounded,
    "kalman.var_u": bounded,
    "kalman.var_z": bounded,
    "kalman.matrix.x0": entries,
    "kalman.matrix.P0": _covariance,
    "kalman.matrix.A": square,
    "kalman.matrix.B": entries,
    "kalman.matrix.C": entries,
    "kalman.matrix.F": entries,
    "kalman.matrix.Q": _covariance,
    "kalman.matrix.R": lambda name, value: positive_definite(name, square(name, value)),
    "kalman.pose_components": _pose_components,
    "frame_id": non_empty_text,
}

def check_estimator_value(name: str, value: Any) -> None:
    """Raise ValueError if one parameter's value is wrong whatever the others are."""
    check = _ALONE.get(name)
    if check is not None:
        check(name, value)

#: Bytes one reorder-history entry costs besides its saved belief and Kalman state.
REORDER_ENTRY_OVERHEAD = 512

def reorder_max_events(memory_mb: float, cells: int, state_size: int) -> int:
    """How many events the reorder history may keep within ``memory_mb``: each saves one
    belief (cells doubles) and one Kalman state (x and P)."""
    per_event = 8 * (cells + state_size + state_size * state_size) + REORDER_ENTRY_OVERHEAD
    return max(1, int(memory_mb * 2**20) // per_event)
