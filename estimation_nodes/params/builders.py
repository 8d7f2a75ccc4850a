"""Builders from parameter values to validated core models, one per node.

Nothing here imports rclpy, so the same validation runs at start-up, on every
runtime parameter change, in offline tools and in plain unit tests. Every
error is a ``ValueError`` whose message starts with the parameter's name.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from estimation_nodes.core import histogram
from estimation_nodes.core.models import (
    FloatArray,
    GaussianState,
    HistogramModel,
    LinearGaussianModel,
    ScalarKalmanModel,
    as_finite_array,
    check_belief,
    check_finite,
    check_positive,
)
from estimation_nodes.params.specs import UNSET, WORLD_SPECS


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


def _matrix(name: str, flat: Any, rows: int) -> FloatArray:
    """Reshape a row-major flat list into ``rows`` rows, naming the parameter on error."""
    values = as_finite_array(name, as_list(name, flat), ndim=1)
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

    @property
    def mode(self) -> str:
        """'scalar' (the book's Algorithm 4) or 'matrix'."""
        return "scalar" if isinstance(self.model, ScalarKalmanModel) else "matrix"


def build_kalman_settings(values: Mapping[str, Any]) -> KalmanSettings:
    """Kalman model and initial state from parameter values.

    Both the scalar and the matrix parameters are validated whatever the mode,
    so a bad value is refused when it is set, not when the mode changes.
    """
    mode = values["kalman.mode"]
    x0 = check_finite("kalman.x0", values["kalman.x0"])
    P0 = check_positive("kalman.P0", values["kalman.P0"])
    scalar = ScalarKalmanModel(values["kalman.var_u"], values["kalman.var_z"])
    matrix_initial, matrix = _build_matrix_model(values, "kalman.matrix.")
    if mode == "scalar":
        return KalmanSettings(GaussianState(np.array([x0]), np.array([[P0]])), scalar)
    if mode == "matrix":
        return KalmanSettings(matrix_initial, matrix)
    raise ValueError(f"kalman.mode: expected 'scalar' or 'matrix', got {mode!r}")


def _build_matrix_model(
    values: Mapping[str, Any], prefix: str
) -> tuple[GaussianState, LinearGaussianModel]:
    """The matrix filter's initial state and model; errors name the full parameter."""
    try:
        x0 = as_finite_array("x0", as_list(prefix + "x0", values[prefix + "x0"]), ndim=1)
        n = x0.size
        initial = GaussianState(x0, _matrix("P0", values[prefix + "P0"], n))
        model = LinearGaussianModel(
            A=_matrix("A", values[prefix + "A"], n),
            B=_matrix("B", values[prefix + "B"], n),
            C=_matrix("C", values[prefix + "C"], 1),
            F=_matrix("F", values[prefix + "F"], n),
            Q=_square("Q", values[prefix + "Q"]),
            R=_square("R", values[prefix + "R"]),
        )
    except ValueError as error:
        message = str(error)
        raise ValueError(message if message.startswith(prefix) else prefix + message) from None
    if model.input_size != 1:
        raise ValueError(f"{prefix}B: expected n x 1 (u is one command), got {model.B.shape}")
    return initial, model


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


def build_estimator_settings(
    values: Mapping[str, Any],
    previous: tuple[Mapping[str, Any], EstimatorSettings] | None = None,
) -> EstimatorSettings:
    """Validate all estimator parameters together; ``ValueError`` names the first bad one.

    With ``previous`` (the values and settings last built), the histogram model
    and prior are reused when none of their parameters changed: a runtime change
    of a Kalman variance then does not re-read a world file or rebuild the
    likelihood tables of a million cells.
    """
    if previous is not None and all(
        values.get(key) == previous[0].get(key) for key in HISTOGRAM_KEYS
    ):
        model, initial_belief = previous[1].histogram, previous[1].initial_belief
    else:
        model = build_histogram_model(values)
        initial_belief = build_initial_belief(values, model.size)
    return EstimatorSettings(model, initial_belief, build_kalman_settings(values))


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
    noise_std = float(np.sqrt(check_positive(
        "measurement_variance", values["measurement_variance"])))
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


def build_commander_settings(values: Mapping[str, Any]) -> CommanderSettings:
    commands = tuple(int(c) for c in as_list("commands", values["commands"]))
    limit = values["max_commands"] or None
    if not values["repeat"]:
        limit = min(limit or len(commands), len(commands))
    return CommanderSettings(commands, limit)
