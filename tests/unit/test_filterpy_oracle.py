"""filterpy 2.0 as an independent oracle on random inputs."""

import numpy as np
import pytest
from filterpy import discrete_bayes
from filterpy.kalman import KalmanFilter

from estimation_nodes.core.kalman import linear as kalman
from estimation_nodes.core.kalman.models import LinearGaussianModel
from estimation_nodes.core.tiles import histogram
from estimation_nodes.core.tiles.models import MotionKernel


@pytest.mark.parametrize("seed", range(20))
def test_histogram_agrees_with_filterpy(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 300))
    belief = rng.random(n)
    belief /= belief.sum()
    weights = rng.random(2 * int(rng.integers(0, min(5, (n - 1) // 2) + 1)) + 1)
    kernel = MotionKernel(weights / weights.sum())
    ours, theirs = belief, belief.copy()
    for _ in range(10):
        u = int(rng.integers(-3 * n, 3 * n))
        likelihood = rng.uniform(0.05, 1.0, n)
        ours, _ = histogram.correct(histogram.predict(ours, u, kernel), likelihood)
        theirs = discrete_bayes.update(likelihood,
                                       discrete_bayes.predict(theirs, u, kernel.weights))
        np.testing.assert_allclose(ours, theirs, atol=1e-12)


@pytest.mark.parametrize("seed", range(10))
def test_matrix_kalman_agrees_with_filterpy(seed):
    rng = np.random.default_rng(seed)
    n, m, p = 4, 2, 2
    A = np.eye(n) + rng.normal(scale=0.1, size=(n, n))
    B = rng.normal(size=(n, m))
    C = rng.normal(size=(p, n))
    F = rng.normal(size=(n, n))
    Qw = np.diag(rng.uniform(0.1, 1.0, n))
    R = np.diag(rng.uniform(0.5, 2.0, p))
    model = LinearGaussianModel(A, B, C, F, Qw, R)

    # filterpy names the transition F, the input B, the measurement H and takes
    # the process noise already mapped into the state: Q = F_book Qw F_book'.
    kf = KalmanFilter(dim_x=n, dim_z=p, dim_u=m)
    kf.F, kf.B, kf.H, kf.Q, kf.R = A, B, C, F @ Qw @ F.T, R
    x, P = rng.normal(size=n), np.eye(n) * 10.0
    kf.x, kf.P = x.copy(), P.copy()
    for _ in range(30):
        u, z = rng.normal(size=m), rng.normal(size=p)
        x, P = kalman.predict(x, P, u, model)
        x, P, K = kalman.correct(x, P, z, model)
        kf.predict(u=u)
        kf.update(z)
        np.testing.assert_allclose(x, kf.x, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(P, kf.P, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(K, kf.K, rtol=1e-9, atol=1e-9)
