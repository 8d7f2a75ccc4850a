"""Bad configuration raises ValueError naming the field, the value and what was expected."""

import numpy as np
import pytest

from estimation_nodes.core.kalman.models import (
    GaussianState,
    LinearGaussianModel,
    ScalarKalmanModel,
)
from estimation_nodes.core.tiles.models import (
    BOOK_CLASSES,
    BOOK_KERNEL,
    BOOK_SENSOR_MODEL,
    BOOK_WORLD,
    HistogramModel,
    MotionKernel,
    SensorModel,
    check_belief,
)


def histogram_model(**changes):
    kwargs = dict(world=BOOK_WORLD, classes=BOOK_CLASSES, sensor_model=BOOK_SENSOR_MODEL,
                  kernel=BOOK_KERNEL)
    kwargs.update(changes)
    return HistogramModel.from_lists(**kwargs)


@pytest.mark.parametrize("changes, message", [
    (dict(kernel=[0.1, -0.2, 1.1]), r"motion_kernel: expected probabilities in \[0, 1\]"),
    (dict(kernel=[0.5, 0.5]), "motion_kernel: expected an odd number"),
    (dict(kernel=[0.1, 0.8, 0.2]), "motion_kernel: expected probabilities summing to 1"),
    (dict(kernel=[]), "motion_kernel: expected at least one"),
    (dict(kernel=[0.1, float("nan"), 0.9]), "motion_kernel: expected finite"),
    (dict(sensor_model=[[0.8, 0.3], [0.4, 0.6]]),
     "sensor_model \\(row of true class 'bright'\\): expected probabilities summing to 1"),
    (dict(sensor_model=[[1.2, -0.2], [0.4, 0.6]]), "sensor_model .*in \\[0, 1\\]"),
    (dict(sensor_model=[0.8, 0.2, 0.4]), "sensor_model: expected a 2-dimensional"),
    (dict(sensor_model=[[0.8, 0.2, 0.0], [0.4, 0.6, 0.0]]), "sensor_model: expected 2x2"),
    (dict(world=["bright", "grey"]), r"world: cells name classes \['grey'\]"),
    (dict(world=[]), "world: expected at least one cell"),
    (dict(classes=["bright", "bright"]), "classes: expected distinct names"),
    (dict(classes=[]), "classes: expected at least one class"),
])
def test_histogram_model_errors_name_the_field(changes, message):
    with pytest.raises(ValueError, match=message):
        histogram_model(**changes)


def test_flat_sensor_model_is_accepted_row_major():
    model = histogram_model(sensor_model=[0.8, 0.2, 0.4, 0.6])
    np.testing.assert_array_equal(model.sensor.probabilities, BOOK_SENSOR_MODEL)


def test_unknown_observation_names_the_known_classes():
    with pytest.raises(ValueError, match=r"unknown tile class 'grey', expected one of"):
        HistogramModel.book().likelihood("grey")


@pytest.mark.parametrize("belief, message", [
    ([0.2] * 4, "initial_belief: expected 5 values"),
    ([0.5, -0.1, 0.2, 0.2, 0.2], "initial_belief: expected non-negative"),
    ([0.0] * 5, "initial_belief: expected values with a positive sum"),
    ([0.2, 0.2, np.inf, 0.2, 0.2], "initial_belief: expected finite"),
])
def test_belief_errors(belief, message):
    with pytest.raises(ValueError, match=message):
        check_belief("initial_belief", belief, 5)


def test_belief_is_normalized():
    np.testing.assert_allclose(check_belief("b", [1, 1, 2, 2, 2], 5), [0.125, 0.125, 0.25,
                                                                        0.25, 0.25])


@pytest.mark.parametrize("var_u, var_z, message", [
    (0.0, 4.0, "var_u: expected a number > 0, got 0.0"),
    (-1.0, 4.0, "var_u: expected a number > 0"),
    (2.0, float("nan"), "var_z: expected a finite number"),
    (2.0, float("inf"), "var_z: expected a finite number"),
    ("two", 4.0, "var_u: expected a finite number, got 'two'"),
])
def test_scalar_kalman_errors(var_u, var_z, message):
    with pytest.raises(ValueError, match=message):
        ScalarKalmanModel(var_u, var_z)


def matrices(**changes):
    kwargs = dict(A=np.eye(2), B=np.ones((2, 1)), C=np.array([[1.0, 0.0]]), F=np.eye(2),
                  Q=np.eye(2), R=np.array([[4.0]]))
    kwargs.update(changes)
    return kwargs


@pytest.mark.parametrize("changes, message", [
    (dict(A=np.ones((2, 3))), "A: expected a square matrix"),
    (dict(B=np.ones((3, 1))), r"B: expected 2 rows to match A"),
    (dict(F=np.ones((1, 2))), r"F: expected 2 rows to match A"),
    (dict(C=np.ones((1, 3))), r"C: expected 2 columns to match A"),
    (dict(Q=np.eye(3)), r"Q: expected shape \(2, 2\)"),
    (dict(Q=np.array([[1.0, 0.5], [0.0, 1.0]])), "Q: expected a symmetric matrix"),
    (dict(Q=np.array([[1.0, 2.0], [2.0, 1.0]])), "Q: expected a positive semi-definite"),
    (dict(R=np.array([[-1.0]])), "R: expected a positive semi-definite"),
    (dict(A=np.array([[np.nan, 0], [0, 1]])), "A: expected finite"),
])
def test_matrix_model_errors_name_the_field(changes, message):
    with pytest.raises(ValueError, match=message):
        LinearGaussianModel(**matrices(**changes))


def test_gaussian_state_errors():
    with pytest.raises(ValueError, match=r"P0: expected shape \(2, 2\)"):
        GaussianState(np.zeros(2), np.eye(3))
    with pytest.raises(ValueError, match="P0: expected a positive semi-definite"):
        GaussianState(np.zeros(1), np.array([[-100.0]]))


def test_models_are_immutable():
    kernel = MotionKernel(np.array(BOOK_KERNEL))
    with pytest.raises(ValueError):
        kernel.weights[0] = 0.5
    with pytest.raises(AttributeError):
        kernel.weights = np.array([1.0])  # type: ignore[misc]
    sensor = SensorModel(BOOK_CLASSES, np.array(BOOK_SENSOR_MODEL))
    with pytest.raises(ValueError):
        sensor.probabilities[0, 0] = 1.0


def test_world_file_replaces_world(tmp_path):
    from estimation_nodes.params.models import build_histogram_model
    from estimation_nodes.params.specs import ESTIMATOR_SPECS, spec_defaults

    path = tmp_path / "world.txt"
    path.write_text("dark bright\nbright  dark\n")
    values = spec_defaults(ESTIMATOR_SPECS) | {"world_file": str(path)}
    model = build_histogram_model(values)
    assert model.world == ("dark", "bright", "bright", "dark")
    # Cells share the class-name objects of the sensor model.
    assert model.world[0] is model.sensor.classes[1]


@pytest.mark.parametrize("content, message", [
    (None, "is not a file"),
    ("", "names no cells"),
    ("dark purple", r"world: cells name classes \['purple'\]"),
    (b"\xff\xfe", "cannot read"),
])
def test_world_file_errors(tmp_path, content, message):
    from estimation_nodes.params.models import build_histogram_model
    from estimation_nodes.params.specs import ESTIMATOR_SPECS, spec_defaults

    path = tmp_path / "world.txt"
    if isinstance(content, bytes):
        path.write_bytes(content)
    elif content is not None:
        path.write_text(content)
    with pytest.raises(ValueError, match=message):
        build_histogram_model(spec_defaults(ESTIMATOR_SPECS) | {"world_file": str(path)})
