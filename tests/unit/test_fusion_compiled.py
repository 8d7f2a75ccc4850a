"""The fusion filter's compiled kernels (core/fusion/compiled.py) against the numpy code they
replace (steps.*_numpy, the inputs with compiled=False): the same estimates to 1e-9 and
measurements to 1e-12, the same rejections and verdicts on covariances, and numpy's
fallback where a covariance has no Cholesky factor."""

from __future__ import annotations

import math

import numpy as np
import pytest

from estimation_nodes.core.fusion import inputs, state, steps
from estimation_nodes.core.fusion.steps import Measurement, Rejected, UnscentedWeights

WEIGHTS = UnscentedWeights()
SEEDS = range(12)


# The module's fixture compiles every fusion kernel where numba's cache lacks them (an
# install the Makefile did not warm): minutes with both cores busy.
pytestmark = pytest.mark.timeout(600)


@pytest.fixture(scope="module", autouse=True)
def kernels_compiled():
    assert steps.prepare_compiled(), "numba is a dependency; it must import"


def random_case(seed: int, spread: float = 0.05):
    """A state (angles anywhere, pitch off the poles), its covariance, a process noise, a
    time step and a measurement of a random subset of the entries, angles included."""
    rng = np.random.default_rng(seed)
    x = rng.normal(size=15)
    x[state.ROLL:state.YAW + 1] = rng.uniform(-math.pi, math.pi, 3)
    x[state.PITCH] = rng.uniform(-1.2, 1.2)
    root = rng.normal(size=(15, 15))
    p = spread * (root @ root.T / 15 + 0.1 * np.eye(15))
    q = np.diag(rng.uniform(0.0, 0.05, 15))
    dt = float(rng.uniform(0.001, 0.1))
    indices = tuple(sorted(rng.choice(15, size=int(rng.integers(1, 10)), replace=False)))
    noise = rng.normal(size=(15, 15))
    z = x + rng.normal(scale=0.2, size=15)
    z[list(state.ANGLES)] = rng.uniform(-math.pi, math.pi, 3)
    measurement = Measurement(0, z, 0.01 * noise @ noise.T + 1e-4 * np.eye(15), indices)
    return x, p, q, dt, measurement


def assert_same(compiled, reference):
    for got, expected in zip(compiled, reference, strict=True):
        np.testing.assert_allclose(got, expected, rtol=0.0, atol=1e-9)


@pytest.mark.parametrize("seed", SEEDS)
def test_the_ekf_steps_equal_numpys(seed):
    x, p, q, dt, measurement = random_case(seed)
    assert_same(steps.ekf_predict(x, p, q, dt), steps.ekf_predict(x, p, q, dt, compiled=False))
    assert_same(steps.ekf_correct(x, p, measurement),
                steps.ekf_correct(x, p, measurement, compiled=False))


@pytest.mark.parametrize("seed", SEEDS)
def test_the_ukf_steps_equal_numpys(seed):
    x, p, q, dt, measurement = random_case(seed)
    predicted = steps.ukf_predict(x, p, q, dt, WEIGHTS)
    assert_same(predicted, steps.ukf_predict(x, p, q, dt, WEIGHTS, compiled=False))
    x_predicted, p_predicted, points = predicted
    for given in (points, None):   # the propagated points, then new ones from (x, P)
        assert_same(steps.ukf_correct(x_predicted, p_predicted, measurement, WEIGHTS, given),
                    steps.ukf_correct(x_predicted, p_predicted, measurement, WEIGHTS, given,
                                      compiled=False))


@pytest.mark.parametrize("kind", ["ekf", "ukf"])
def test_a_measurement_beyond_its_threshold_is_rejected_by_both_paths_alike(kind):
    x, p, _, _, measurement = random_case(3)
    far = Measurement(0, measurement.z + 50.0, measurement.covariance, (state.VX, state.VY),
                      threshold=2.0)
    distances = []
    for compiled in (True, False):
        with pytest.raises(Rejected) as rejected:
            if kind == "ekf":
                steps.ekf_correct(x, p, far, compiled=compiled)
            else:
                steps.ukf_correct(x, p, far, WEIGHTS, None, compiled=compiled)
        distances.append(rejected.value.squared_distance)
    assert distances[0] == pytest.approx(distances[1], rel=1e-9)
    assert distances[0] > 4.0


def test_a_covariance_without_a_cholesky_factor_takes_numpys_symmetric_root():
    x, p, q, dt, _ = random_case(5)
    values, vectors = np.linalg.eigh(p)
    values[:3] = [0.0, -1e-12, 0.0]     # singular and a hair indefinite, as rounding leaves P
    p = vectors @ np.diag(values) @ vectors.T
    with pytest.raises(np.linalg.LinAlgError):
        np.linalg.cholesky((15 + WEIGHTS.lam) * p)
    assert_same(steps.ukf_predict(x, p, q, dt, WEIGHTS),
                steps.ukf_predict(x, p, q, dt, WEIGHTS, compiled=False))


def covariance_cases():
    rng = np.random.default_rng(11)
    root = rng.normal(size=(15, 15))
    correlated = root @ root.T
    indefinite = np.eye(15)
    indefinite[6, 7] = indefinite[7, 6] = 2.0
    asymmetric = np.eye(15)
    asymmetric[6, 7] = 0.5
    negative = np.eye(15)
    negative[7, 7] = -0.04        # taken as 0.04, as the peer takes it
    nan = np.eye(15)
    nan[8, 6] = math.nan
    singular = np.zeros((15, 15))  # floored to 1e-9 on the diagonal: usable
    # an eigenvalue of -1e-12, within the tolerance: Gershgorin cannot tell, numpy decides
    within_tolerance = np.eye(15)
    within_tolerance[6, 7] = within_tolerance[7, 6] = 1.0 + 1e-12
    return {"diagonal": np.eye(15) * 0.01, "correlated": correlated,
            "indefinite": indefinite, "asymmetric": asymmetric, "negative": negative,
            "nan": nan, "singular": singular, "within_tolerance": within_tolerance}


@pytest.mark.parametrize(("name", "covariance"), list(covariance_cases().items()))
def test_the_covariance_check_says_what_numpys_says(name, covariance):
    measurement = Measurement(0, np.zeros(15), covariance, (6, 7, 8))
    verdict = steps.covariance_problem(measurement)
    assert verdict == steps.covariance_problem(measurement, compiled=False)
    usable = name in ("diagonal", "correlated", "negative", "singular", "within_tolerance")
    assert (verdict is None) == usable, verdict


def test_the_unscented_mean_is_exact_far_from_the_origin():
    """With the peer's alpha of 0.001 the first weight is about -1e6: sum_i w_i X_i cancels
    terms of 1e8 at 80 m from the origin. Over the differences to the first point, both
    paths' means agree with the exact rational sum of the same points to 1e-12 (the direct
    sum is off by about 1e-8 here)."""
    from fractions import Fraction

    rng = np.random.default_rng(2)
    x = rng.normal(size=15)
    x[:3] += [-40.0, -77.0, -2.5]
    root = rng.normal(size=(15, 15))
    points = steps.sigma_points(x, 0.01 * root @ root.T, WEIGHTS)
    lam = Fraction(WEIGHTS.alpha) ** 2 * (15 + Fraction(WEIGHTS.kappa)) - 15
    exact_weights = [lam / (15 + lam)] + [1 / (2 * (15 + lam))] * 30
    exact = [float(sum(Fraction(float(v)) * w for v, w in zip(points[:, column],
                                                              exact_weights)))
             for column in range(3)]
    np.testing.assert_allclose(steps.unscented_mean(points, WEIGHTS.mean, [])[:3], exact,
                               rtol=0.0, atol=1e-12)
    predicted, _, _ = steps.ukf_predict(x, 0.01 * root @ root.T, np.zeros((15, 15)), 0.0,
                                        WEIGHTS)
    np.testing.assert_allclose(predicted[:3], exact, rtol=0.0, atol=1e-12)


def random_mount(rng) -> inputs.Mount:
    return inputs.Mount.from_rpy(tuple(rng.normal(size=3)), tuple(rng.uniform(-3, 3, 3)))


def random_covariance(rng, size: int) -> np.ndarray:
    root = rng.normal(size=(size, size))
    return root @ root.T


def assert_same_measurement(compiled, reference):
    assert compiled.indices == reference.indices
    np.testing.assert_allclose(compiled.z, reference.z, rtol=0.0, atol=1e-12)
    np.testing.assert_allclose(compiled.covariance, reference.covariance, rtol=0.0,
                               atol=1e-12)


@pytest.mark.parametrize("seed", SEEDS)
def test_the_inputs_kernels_equal_numpys(seed):
    rng = np.random.default_rng(seed)
    mount = random_mount(rng)
    every = (True,) * 15
    linear, angular, rates, alpha = (rng.normal(size=3) for _ in range(4))
    twist6 = random_covariance(rng, 6)
    assert_same_measurement(
        inputs.twist(0, linear, angular, twist6, every, rates, mount),
        inputs.twist(0, linear, angular, twist6, every, rates, mount, compiled=False))
    attitude = state.rotation_from_rpy(*rng.uniform(-3, 3, 3))
    covariance3 = random_covariance(rng, 3)
    assert_same_measurement(
        inputs.imu_orientation(0, attitude, covariance3, every, mount),
        inputs.imu_orientation(0, attitude, covariance3, every, mount, compiled=False))
    for seen_from, remove_gravity in ((attitude, True), (attitude, False), (None, True)):
        assert_same_measurement(
            inputs.acceleration(0, linear, covariance3, every, rates, alpha, seen_from,
                                remove_gravity, inputs.GRAVITY, mount),
            inputs.acceleration(0, linear, covariance3, every, rates, alpha, seen_from,
                                remove_gravity, inputs.GRAVITY, mount, compiled=False))


@pytest.mark.parametrize("seed", SEEDS)
def test_an_imu_readings_kernel_equals_numpys(seed):
    """inputs.imu_values in one kernel: each part's entries as numpy's, with and without an
    attitude and gravity, and NaNs where the reading has them (its entries then left
    unmeasured, as by the part's own function)."""
    rng = np.random.default_rng(seed)
    mount = random_mount(rng)
    quaternion = tuple(rng.normal(size=4))
    covariances = [random_covariance(rng, 3) for _ in range(3)]
    angular, linear, rates, alpha = (rng.normal(size=3) for _ in range(4))
    if seed % 3 == 0:
        angular[1] = math.nan
    gravity_attitude = state.rotation_from_quaternion(*quaternion)
    for attitude_of, seen_from in ((quaternion, gravity_attitude), (None, gravity_attitude),
                                   (quaternion, None)):
        arguments = (attitude_of, covariances[0], angular, covariances[1], linear,
                     covariances[2], rates, alpha, seen_from, inputs.GRAVITY, mount)
        compiled = inputs.imu_values(*arguments)
        reference = inputs.imu_values(*arguments, compiled=False)
        np.testing.assert_allclose(compiled[0], reference[0], rtol=0.0, atol=1e-12)
        np.testing.assert_allclose(compiled[1], reference[1], rtol=0.0, atol=1e-12)
        if attitude_of is not None:
            alone = inputs.imu_orientation(0, inputs.imu_attitude(quaternion, mount),
                                           covariances[0], (True,) * 15, mount,
                                           compiled=False)
            np.testing.assert_allclose(compiled[0][state.ORIENTATION],
                                       alone.z[state.ORIENTATION], rtol=0.0, atol=1e-12)
        rates_only = inputs.imu_measurement(0, *compiled, (True,) * 15, state.TWIST, mount)
        nan_entries = {i for i in range(15) if not math.isfinite(compiled[0][i])}
        assert set(rates_only.indices) == set(range(state.VX, state.VYAW + 1)) - nan_entries
        assert bool(nan_entries) == (seed % 3 == 0)


@pytest.mark.parametrize("seed", SEEDS)
def test_a_ukf_correction_drawing_its_points_equals_numpys(seed):
    x, p, q, dt, measurement = random_case(seed)
    assert_same(steps.ukf_correct(x, p, measurement, WEIGHTS, None),
                steps.ukf_correct(x, p, measurement, WEIGHTS, None, compiled=False))
