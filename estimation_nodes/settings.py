"""The nodes' parameters: one table of specs, and builders from values to core models.

Nothing here imports rclpy, so the same validation runs at start-up, on every
runtime parameter change, in offline tools and in plain unit tests.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from estimation_nodes.core import GaussianState, HistogramModel, LinearGaussianModel, histogram
from estimation_nodes.core.config import (
    BOOK_CLASSES,
    BOOK_KERNEL,
    BOOK_SENSOR_MODEL,
    BOOK_WORLD,
    FloatArray,
    ScalarKalmanModel,
    as_finite_array,
    check_belief,
    check_finite,
    check_positive,
)

#: Marks a parameter with no default: declared by type, unset means "not given".
UNSET = None


@dataclass(frozen=True)
class ParamSpec:
    """One parameter: name, default (or the type name when it has none), description."""

    name: str
    default: Any
    description: str
    read_only: bool = False
    #: For parameters without a default: one of "string_array", "double_array".
    type_name: str = ""
    #: Inclusive bounds shown by `ros2 param describe` (numbers only).
    min_value: float | None = None
    max_value: float | None = None


WORLD_SPECS = (
    ParamSpec("world", list(BOOK_WORLD),
              "Class name of each cell of the cyclic world, in order (index 0 first)."),
    ParamSpec("world_file", "",
              "Path of a UTF-8 text file with the class name of each cell, separated by white "
              "space; when set it replaces 'world' (for large worlds).", read_only=True),
    ParamSpec("classes", list(BOOK_CLASSES), "Names of the tile classes the sensor reports."),
    ParamSpec("sensor_model", [p for row in BOOK_SENSOR_MODEL for p in row],
              "p(observed class | true class), row-major: one row per true class in the "
              "order of 'classes', one column per observed class; rows sum to 1."),
    ParamSpec("motion_kernel", list(BOOK_KERNEL),
              "Probabilities of landing at offsets -k..k around the commanded target "
              "(odd length, centred, sums to 1)."),
)

ESTIMATOR_SPECS = WORLD_SPECS + (
    ParamSpec("initial_belief", UNSET,
              "Prior over the cells (normalized); leave unset for a uniform prior.",
              type_name="double_array"),
    ParamSpec("kalman.mode", "scalar",
              "'scalar': the book's Algorithm 4 with kalman.x0/P0/var_u/var_z; 'matrix': "
              "the matrix filter with kalman.matrix.*.", read_only=True),
    ParamSpec("kalman.x0", 0.0, "Initial position estimate (cells) of the scalar filter."),
    ParamSpec("kalman.P0", 100.0, "Initial variance of the scalar filter (> 0).",),
    ParamSpec("kalman.var_u", 2.0, "Variance of an executed move (> 0)."),
    ParamSpec("kalman.var_z", 4.0, "Variance of a position measurement (> 0)."),
    ParamSpec("kalman.matrix.x0", [0.0], "Matrix mode: initial state; its length n sets the "
              "state size. Component 0 is published as the position."),
    ParamSpec("kalman.matrix.P0", [100.0], "Matrix mode: initial covariance, n x n row-major."),
    ParamSpec("kalman.matrix.A", [1.0], "Matrix mode: transition matrix A, n x n row-major."),
    ParamSpec("kalman.matrix.B", [1.0], "Matrix mode: input matrix B, n x 1 (u is the "
              "motion command)."),
    ParamSpec("kalman.matrix.C", [1.0], "Matrix mode: measurement matrix C, 1 x n."),
    ParamSpec("kalman.matrix.F", [1.0], "Matrix mode: noise-input matrix F, n x q row-major."),
    ParamSpec("kalman.matrix.Q", [2.0], "Matrix mode: process noise covariance, q x q."),
    ParamSpec("kalman.matrix.R", [4.0], "Matrix mode: measurement noise variance, 1 x 1."),
    ParamSpec("frame_id", "map", "frame_id of kalman_estimate_stamped."),
    ParamSpec("history_depth", 100,
              "How many past estimates each output topic keeps for late subscribers "
              "(transient_local). Lower it for very large worlds.", read_only=True,
              min_value=1, max_value=100000),
    ParamSpec("diagnostics_period", 1.0, "Seconds between /diagnostics messages.",
              read_only=True, min_value=0.01, max_value=3600.0),
    ParamSpec("compiled_kernels", False,
              "Worlds of 65,536 cells or more: run the histogram steps as numba-compiled "
              "kernels (a 1e6-cell step in about half the CPU time) at the price of 100 to "
              "150 MB of resident memory for numba and LLVM and 0.5 s more start-up. Off by "
              "default: a step through DDS at 1e6 cells is dominated by moving the two "
              "belief messages, so the node's end-to-end rate does not change measurably.",
              read_only=True),
)


def spec_defaults(specs: tuple[ParamSpec, ...]) -> dict[str, Any]:
    """Every parameter's default, by name (UNSET for those without one)."""
    return {spec.name: spec.default for spec in specs}


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
    """Which Kalman filter the estimator runs and from where it starts."""

    mode: str
    initial: GaussianState
    scalar: ScalarKalmanModel | None
    matrix: LinearGaussianModel | None


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
        initial = GaussianState(np.array([x0]), np.array([[P0]]))
        return KalmanSettings(mode, initial, scalar, None)
    if mode == "matrix":
        return KalmanSettings(mode, matrix_initial, None, matrix)
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
