"""Core models from parameter values: the tile world and the linear Gaussian system, shared
by the estimator and the simulators that must agree with it."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from estimation_nodes.core.kalman.models import GaussianState, LinearGaussianModel
from estimation_nodes.core.tiles import histogram
from estimation_nodes.core.tiles.models import HistogramModel, check_belief
from estimation_nodes.core.validation import FloatArray
from estimation_nodes.params.specs import UNSET
from estimation_nodes.params.values import (
    as_list,
    entries,
    positive_definite,
    shaped,
    with_columns,
    with_rows,
)


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

def build_matrix_model(
    values: Mapping[str, Any], prefix: str
) -> tuple[GaussianState, LinearGaussianModel]:
    """The matrix filter's initial state and model (the book's Eq. 6.34), any sizes.

    n comes from x0, the input size m from B (n x m), the noise size q from F
    (n x q) and the measurement size p from C (p x n); every other matrix is
    checked against them. Errors name the full parameter, the shape it got and
    the shape it needs.
    """
    def given(name: str) -> FloatArray:
        return entries(prefix + name, values[prefix + name])

    x0 = given("x0")
    n = x0.size
    B = with_rows(prefix + "B", given("B"), n, "n x m: a row per state component, n = len(x0)")
    F = with_rows(prefix + "F", given("F"), n, "n x q: a row per state component")
    C = with_columns(prefix + "C", given("C"), n, "p x n: a column per state component")
    p, q = C.shape[0], F.shape[1]
    try:
        initial = GaussianState(x0, shaped(prefix + "P0", given("P0"), n, n, "n x n"))
        model = LinearGaussianModel(
            A=shaped(prefix + "A", given("A"), n, n, "n x n"),
            B=B, C=C, F=F,
            Q=shaped(prefix + "Q", given("Q"), q, q, "q x q, q = columns of F"),
            R=shaped(prefix + "R", given("R"), p, p, "p x p, p = rows of C"),
        )
    except ValueError as error:
        message = str(error)
        raise ValueError(message if message.startswith(prefix) else prefix + message) from None
    positive_definite(prefix + "R", model.R)
    return initial, model
