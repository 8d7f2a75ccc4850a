"""The matrix filter's parameters with several inputs and outputs (the book's Eq. 6.34)."""

import numpy as np
import pytest

from estimation_nodes.core.kalman.models import LinearGaussianModel
from estimation_nodes.core.sim import draws as simulation
from estimation_nodes.params.estimator import build_kalman_settings
from estimation_nodes.params.simulators import (
    build_commander_settings,
    build_linear_system_settings,
)
from estimation_nodes.params.specs import COMMANDER_SPECS, ESTIMATOR_SPECS, spec_defaults

# x = (x, y, vx, vy), u = (ax, ay), z = (x, y): n = 4, m = 2, q = 2, p = 2.
TRACKING = {
    "kalman.mode": "matrix",
    "kalman.matrix.x0": [0.0, 0.0, 1.0, 0.0],
    "kalman.matrix.P0": [float(v) for v in np.eye(4).ravel()],
    "kalman.matrix.A": [1.0, 0.0, 0.5, 0.0, 0.0, 1.0, 0.0, 0.5,
                        0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0],
    "kalman.matrix.B": [0.125, 0.0, 0.0, 0.125, 0.5, 0.0, 0.0, 0.5],
    "kalman.matrix.F": [0.125, 0.0, 0.0, 0.125, 0.5, 0.0, 0.0, 0.5],
    "kalman.matrix.Q": [0.04, 0.0, 0.0, 0.04],
    "kalman.matrix.C": [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0],
    "kalman.matrix.R": [0.25, 0.0, 0.0, 0.25],
    "kalman.pose_components": [0, 1],
}


def values(**changes):
    merged = {**spec_defaults(ESTIMATOR_SPECS), **TRACKING}
    merged.update({f"kalman.{k.replace('__', '.')}": v for k, v in changes.items()})
    return merged


def test_sizes_are_inferred_from_x0_b_c_and_f():
    settings = build_kalman_settings(values())
    model = settings.model
    assert isinstance(model, LinearGaussianModel)
    assert (model.state_size, model.input_size, model.measurement_size) == (4, 2, 2)
    assert model.Q.shape == (2, 2) and model.R.shape == (2, 2)
    assert settings.pose_components == (0, 1)


@pytest.mark.parametrize("name, value, message", [
    ("matrix__C", [1, 0, 0, 0, 0, 1], "kalman.matrix.C: expected k x 4 values (p x n"),
    ("matrix__B", [1, 0, 0], "kalman.matrix.B: expected 4 x k values (n x m"),
    ("matrix__R", [0.25, 0, 0, 0, 0.25, 0, 0, 0, 0.25],
     "kalman.matrix.R: expected 2 x 2 (p x p, p = rows of C), got 9 values"),
    ("matrix__Q", [0.04], "kalman.matrix.Q: expected 2 x 2 (q x q, q = columns of F), got 1"),
    ("matrix__A", [1, 0, 0, 1], "kalman.matrix.A: expected 4 x 4 (n x n), got 4 values"),
    ("matrix__P0", [1.0] * 9, "kalman.matrix.P0: expected 4 x 4 (n x n), got 9 values"),
    ("matrix__R", [0.25, 0.0, 0.0, 0.0], "kalman.matrix.R: expected a positive definite"),
    ("pose_components", [0, 4], "kalman.pose_components: expected state indices below n = 4"),
    ("pose_components", [0, 1, 2, 3, -1, -1, 0], "kalman.pose_components: expected up to 6"),
])
def test_a_shape_error_names_the_parameter_what_it_got_and_what_it_needs(name, value, message):
    with pytest.raises(ValueError, match=r"^" + message.replace("(", r"\(").replace(")", r"\)")):
        build_kalman_settings(values(**{name: value}))


def test_the_commander_sends_input_vectors_row_by_row():
    given = {**spec_defaults(COMMANDER_SPECS), "input_vectors": [1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
             "input_size": 2}
    settings = build_commander_settings(given)
    assert settings.vectors == ((1.0, 2.0), (3.0, 4.0), (5.0, 6.0)) and settings.limit == 3
    with pytest.raises(ValueError, match="input_vectors: expected k x 4"):
        build_commander_settings({**given, "input_size": 4})


def test_the_simulated_system_follows_eq_6_34_exactly_without_noise():
    noisy = build_kalman_settings(values()).model
    model = LinearGaussianModel(noisy.A, noisy.B, noisy.C, noisy.F, np.zeros((2, 2)),
                                np.zeros((2, 2)))
    x, u = np.array([1.0, 2.0, 0.5, -0.5]), np.array([0.2, -0.4])
    x_next, z = simulation.linear_system_step(x, u, model, np.random.default_rng(0))
    np.testing.assert_allclose(x_next, model.A @ x + model.B @ u, atol=1e-15)
    np.testing.assert_allclose(z, model.C @ x_next, atol=1e-15)


def test_the_simulated_system_starts_from_its_own_truth():
    given = {**values(), "true_initial_state": [0.3, -0.2, 1.0, 0.2], "seed": 5}
    np.testing.assert_array_equal(build_linear_system_settings(given).initial_state,
                                  [0.3, -0.2, 1.0, 0.2])
    with pytest.raises(ValueError, match="true_initial_state: expected 4 values"):
        build_linear_system_settings({**given, "true_initial_state": [0.0]})
