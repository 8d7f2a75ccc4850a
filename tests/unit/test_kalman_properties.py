"""Invariants of the matrix Kalman filter."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimation_nodes.core.kalman import linear as kalman
from estimation_nodes.core.kalman.models import LinearGaussianModel


def spd(rng, size):
    root = rng.normal(size=(size, size))
    return root @ root.T + 0.1 * np.eye(size)


def random_model(rng, n, m, p, q):
    return LinearGaussianModel(
        A=rng.normal(scale=0.5, size=(n, n)) + np.eye(n), B=rng.normal(size=(n, m)),
        C=rng.normal(size=(p, n)), F=rng.normal(size=(n, q)), Q=spd(rng, q), R=spd(rng, p))


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 5), p=st.integers(1, 3))
def test_joseph_form_equals_short_form_at_optimal_gain(seed, n, p):
    rng = np.random.default_rng(seed)
    model = random_model(rng, n, 1, p, n)
    x, P = rng.normal(size=n), spd(rng, n)
    z = rng.normal(size=p)
    _, P_joseph, K = kalman.correct(x, P, z, model)
    P_short = P - K @ model.C @ P
    np.testing.assert_allclose(P_joseph, P_short, atol=1e-8 * max(1.0, np.abs(P).max()))


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 4))
def test_covariance_stays_symmetric_psd_over_long_runs(seed, n):
    rng = np.random.default_rng(seed)
    model = random_model(rng, n, 2, 2, n)
    # A spectral radius at most 1 keeps a long run from overflowing.
    A = model.A / max(1.0, np.max(np.abs(np.linalg.eigvals(model.A))))
    model = LinearGaussianModel(A, model.B, model.C, model.F, model.Q, model.R)
    x, P = np.zeros(n), np.eye(n)
    for _ in range(500):
        x, P = kalman.predict(x, P, rng.normal(size=2), model)
        x, P, _ = kalman.correct(x, P, rng.normal(size=2), model)
        np.testing.assert_array_equal(P, P.T)
        assert np.min(np.linalg.eigvalsh(P)) >= -1e-12 * np.abs(P).max()
    assert np.all(np.isfinite(x))


def test_scalar_and_matrix_paths_agree_on_random_sequences():
    rng = np.random.default_rng(7)
    model = LinearGaussianModel.scalar(var_u=0.7, var_z=2.5)
    xs, vs = 1.0, 50.0
    xm, Pm = np.array([1.0]), np.array([[50.0]])
    for _ in range(200):
        u, z = rng.normal(), rng.normal(scale=5.0)
        xs, vs = kalman.predict_scalar(xs, vs, u, 0.7)
        xs, vs, _ = kalman.correct_scalar(xs, vs, z, 2.5)
        xm, Pm = kalman.predict(xm, Pm, [u], model)
        xm, Pm, _ = kalman.correct(xm, Pm, [z], model)
        np.testing.assert_allclose([xm[0], Pm[0, 0]], [xs, vs], rtol=1e-12)


def test_nan_measurement_is_rejected_and_inputs_untouched():
    model = LinearGaussianModel.scalar(2.0, 4.0)
    x, P = np.array([1.0]), np.array([[3.0]])
    for bad in (np.nan, np.inf, -np.inf):
        with pytest.raises(ValueError, match="z: expected finite"):
            kalman.correct(x, P, [bad], model)
        with pytest.raises(ValueError, match="z: expected a finite"):
            kalman.correct_scalar(1.0, 3.0, bad, 4.0)
    np.testing.assert_array_equal(x, [1.0])
    np.testing.assert_array_equal(P, [[3.0]])


def test_normalized_innovation_squared_scalar():
    model = LinearGaussianModel.scalar(2.0, 4.0)
    nis = kalman.normalized_innovation_squared(np.array([1.0]), np.array([[5.0]]), [4.0], model)
    np.testing.assert_allclose(nis, 9.0 / 9.0)


def reference_gain(P, model):
    S = model.C @ P @ model.C.T + model.R
    return np.linalg.solve(S, model.C @ P).T


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), p=st.integers(1, 3))
def test_gain_matches_a_lapack_solve_for_one_to_three_measurements(seed, p):
    # One and two measurements take a closed-form inverse; three take LAPACK.
    rng = np.random.default_rng(seed)
    model = random_model(rng, 4, 1, p, 4)
    P = spd(rng, 4)
    _, _, K = kalman.correct(np.zeros(4), P, np.zeros(p), model)
    np.testing.assert_allclose(K, reference_gain(P, model), rtol=1e-9, atol=1e-12)


def test_gain_with_a_nearly_singular_innovation_covariance():
    # Two almost parallel measurement rows and a tiny R: S is nearly singular
    # (condition about 1e13), where the closed form would lose digits, so the
    # gain must be LAPACK's solve, the same to rounding.
    C = np.array([[1.0, 0.0], [1.0, 1e-9]])
    model = LinearGaussianModel(np.eye(2), np.eye(2), C, np.eye(2), np.eye(2), np.eye(2) * 1e-14)
    P = np.array([[2.0, 0.3], [0.3, 1.0]])
    _, P_new, K = kalman.correct(np.zeros(2), P, np.array([1.0, 1.0]), model)
    np.testing.assert_allclose(K, reference_gain(P, model), rtol=1e-12)
    assert np.all(np.isfinite(P_new))


@pytest.mark.parametrize("p", [1, 2, 3])
def test_the_correction_s_nis_equals_the_separate_computation(p):
    rng = np.random.default_rng(p)
    n = 4
    model = LinearGaussianModel(np.eye(n), np.ones((n, 1)), rng.normal(size=(p, n)), np.eye(n),
                                np.eye(n), np.diag(rng.uniform(0.5, 2.0, p)))
    x, P, z = rng.normal(size=n), np.eye(n) * 3.0, rng.normal(size=p)
    x_new, P_new, K, nis = kalman.correct_with_nis(x, P, z, model)
    np.testing.assert_allclose(nis, kalman.normalized_innovation_squared(x, P, z, model),
                               rtol=1e-12)
    for ours, plain in zip((x_new, P_new, K), kalman.correct(x, P, z, model)):
        np.testing.assert_array_equal(ours, plain)
