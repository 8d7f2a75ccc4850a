"""The EKF and UKF steps over robot_localization's state (the book's symbols: x, P, Q, R, K).

A measurement gives values for a subset of the state (``Measurement.indices``), so its
H is a selection of rows of the identity; a gyro whose bias is estimated adds the bias's
state entry to the rate it measures (``Measurement.biased``: H's row has a second 1).
The state is robot_localization's 15 entries, then 3 per IMU whose gyro bias it holds
(their motion: constant, a random walk by their process noise). Both filters:
- predict with the motion model and P' = ... + dt Q (the process noise is a rate);
- correct with the innovation's angles wrapped, and skip a measurement whose squared
  Mahalanobis distance reaches its threshold squared (``Rejected``);
- raise variances below 1e-9 to 1e-9 and take negative ones as positive, as the peer;
  ``covariance_problem`` says when what is left still cannot be a covariance (not
  finite, not symmetric positive semi-definite), for the caller to drop it.
The EKF's covariance update is the Joseph form. The UKF is the scaled unscented
transform with the peer's weights (lambda = alpha^2 (n + kappa) - n); its first
correction after a prediction uses the propagated sigma points, later ones draw new
ones from the corrected covariance. Functions return new values; inputs are left alone.

Each step runs as compiled.py's kernel where numba imports (``compiled=True``, the
default), else as its ``*_numpy`` twin here, the reference the kernels are tested equal
to: numpy's calls on 15 x 15 arrays cost more than their arithmetic. The kernels are
the 15-entry filter's; a state with gyro biases, or a biased measurement, takes the
numpy steps.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from estimation_nodes.core.compiled_loader import load_kernels
from estimation_nodes.core.fusion import motion
from estimation_nodes.core.fusion.state import ANGLES, STATE_SIZE, wrap, wrap_state_angles
from estimation_nodes.core.errors import InvalidInputError
from estimation_nodes.core.validation import MATRIX_TOLERANCE, FloatArray, check_covariance

#: The smallest variance a measurement may claim (the peer's floor).
MIN_VARIANCE = 1e-9
COMPILED = "estimation_nodes.core.fusion.compiled"


def prepare_compiled() -> bool:
    """Compile (or load from numba's cache) the steps' kernels now, not at the first
    message a node answers; False where numba does not import."""
    return load_kernels(COMPILED) is not None


def kernels(compiled: bool = True):
    """compiled.py's module (compiled once), None where numba does not import or
    ``compiled`` is False."""
    return load_kernels(COMPILED) if compiled else None


def c_doubles(array: FloatArray) -> FloatArray:
    """The array as the kernels were compiled for (C-ordered doubles): no copy when it is
    (another layout would compile them anew)."""
    return np.ascontiguousarray(array, dtype=np.float64)


@dataclass(frozen=True)
class Measurement:
    """Values for some of the state's entries, at one time, with their covariance."""

    #: When it was taken (ns).
    stamp_ns: int
    #: The 15-entry vector; only ``indices`` are read.
    z: FloatArray
    #: The 15 x 15 covariance; only the rows and columns of ``indices`` are read.
    covariance: FloatArray
    #: The state entries it measures, finite values only.
    indices: tuple[int, ...]
    #: Mahalanobis rejection threshold (in standard deviations; inf: never).
    threshold: float = math.inf
    #: Where it came from ("odom0_twist", ...), for diagnostics.
    source: str = ""
    #: (measured entry, bias entry) pairs: the value read is the entry plus the bias (a
    #: gyro's rate and its bias's state entry).
    biased: tuple[tuple[int, int], ...] = ()

    #: ``indices`` as the kernels take them (one array per set of indices, shared by the
    #: measurements that have it: never changed in place).
    index_array: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "index_array", _index_array(self.indices))


@functools.cache
def _index_array(indices: tuple[int, ...]) -> np.ndarray:
    return np.array(indices, dtype=np.int64)


class Rejected(Exception):
    """A measurement beyond its Mahalanobis threshold: the state is left as it was."""

    def __init__(self, squared_distance: float, threshold: float) -> None:
        super().__init__(f"squared Mahalanobis distance {squared_distance:.3g} "
                         f">= {threshold:.3g}^2")
        self.squared_distance = squared_distance


def subset(measurement: Measurement) -> tuple[FloatArray, FloatArray]:
    """(z, R) on the measured entries, R's variances floored as the peer does."""
    idx = list(measurement.indices)
    z = measurement.z[idx]
    r = measurement.covariance[np.ix_(idx, idx)].copy()
    diagonal = np.abs(np.diag(r))
    np.fill_diagonal(r, np.maximum(diagonal, MIN_VARIANCE))
    return z, r


def covariance_problem(measurement: Measurement, compiled: bool = True) -> str | None:
    """Why the measurement's R (on its entries, its variances as ``subset`` floors them)
    cannot be used, None when it can: a non-finite entry, or a matrix that is not symmetric
    positive semi-definite (the peer takes it as it is: an indefinite R can turn the
    innovation's covariance indefinite and the state's with it). The kernel proves the
    common case usable; what it cannot prove, numpy's eigenvalues decide."""
    compiled_steps = kernels(compiled)
    if compiled_steps is not None:
        verdict = compiled_steps.covariance_verdict(c_doubles(measurement.covariance),
                                             measurement.index_array, MIN_VARIANCE,
                                             MATRIX_TOLERANCE)
        if verdict == 0:
            return None
        if verdict == 1:
            return "a non-finite covariance"
    _, r = subset(measurement)
    if not np.all(np.isfinite(r)):
        return "a non-finite covariance"
    try:
        check_covariance("R", r, len(measurement.indices))
    except InvalidInputError:
        return "a covariance that is not symmetric positive semi-definite"
    return None


def _wrap_angle_entries(vector: FloatArray, indices: tuple[int, ...]) -> FloatArray:
    """The entries (last axis) that are angles wrapped into [-pi, pi)."""
    rows = [row for row, index in enumerate(indices) if index in ANGLES]
    wrapped = vector.copy()
    wrapped[..., rows] = np.mod(vector[..., rows] + math.pi, 2.0 * math.pi) - math.pi
    return wrapped


def _uses_kernels(x: FloatArray, measurement: Measurement | None = None) -> bool:
    """Whether the compiled kernels fit: the 15-entry state, a plain selection H."""
    return x.shape[0] == STATE_SIZE and (measurement is None or not measurement.biased)


def observation_matrix(measurement: Measurement, size: int) -> FloatArray:
    """H: the rows of the identity at the measured entries, each biased one with a 1 at its
    bias's entry too."""
    h = np.eye(size)[list(measurement.indices)]
    rows = {index: row for row, index in enumerate(measurement.indices)}
    for measured, bias in measurement.biased:
        h[rows[measured], bias] += 1.0
    return h


def _check(innovation: np.ndarray, s_inverse: np.ndarray, threshold: float) -> None:
    _reject_beyond(float(innovation @ s_inverse @ innovation), threshold)


def _reject_beyond(squared: float, threshold: float) -> None:
    if squared >= threshold * threshold:
        raise Rejected(squared, threshold)


def ekf_predict(x: FloatArray, p: FloatArray, q: FloatArray, dt: float,
                compiled: bool = True) -> tuple[FloatArray, FloatArray]:
    """x' = F(x) x, P' = J P J' + dt Q."""
    compiled_steps = kernels(compiled and _uses_kernels(x))
    if compiled_steps is not None:
        return compiled_steps.ekf_predict(c_doubles(x), c_doubles(p), c_doubles(q), float(dt))
    return ekf_predict_numpy(x, p, q, dt)


def ekf_predict_numpy(x: FloatArray, p: FloatArray, q: FloatArray, dt: float
                      ) -> tuple[FloatArray, FloatArray]:
    """``ekf_predict`` over numpy arrays."""
    f = motion.transfer(x, dt)
    j = motion.jacobian(x, dt)
    return wrap_state_angles(f @ x), j @ p @ j.T + dt * q


def ekf_correct(x: FloatArray, p: FloatArray, measurement: Measurement,
                compiled: bool = True) -> tuple[FloatArray, FloatArray]:
    """K = P H' (H P H' + R)^-1, x' = x + K y, P' = (I - K H) P (I - K H)' + K R K'."""
    compiled_steps = kernels(compiled and _uses_kernels(x, measurement))
    if compiled_steps is not None:
        squared, x_new, p_new = compiled_steps.ekf_correct(
            c_doubles(x), c_doubles(p), c_doubles(measurement.z),
            c_doubles(measurement.covariance), measurement.index_array, MIN_VARIANCE)
        _reject_beyond(squared, measurement.threshold)
        return x_new, p_new
    return ekf_correct_numpy(x, p, measurement)


def ekf_correct_numpy(x: FloatArray, p: FloatArray, measurement: Measurement
                      ) -> tuple[FloatArray, FloatArray]:
    """``ekf_correct`` over numpy arrays."""
    if measurement.biased:
        return _ekf_correct_biased(x, p, measurement)
    idx = list(measurement.indices)
    z, r = subset(measurement)
    pht = p[:, idx]                       # P H' with H the rows idx of the identity
    s_inverse = np.linalg.inv(pht[idx] + r)
    k = pht @ s_inverse
    innovation = _wrap_angle_entries(z - x[idx], measurement.indices)
    _check(innovation, s_inverse, measurement.threshold)
    gain_residual = np.eye(x.shape[0])
    gain_residual[:, idx] -= k
    p_new = gain_residual @ p @ gain_residual.T + k @ r @ k.T
    return wrap_state_angles(x + k @ innovation), p_new


def _ekf_correct_biased(x: FloatArray, p: FloatArray, measurement: Measurement
                        ) -> tuple[FloatArray, FloatArray]:
    """``ekf_correct_numpy`` with H written out (``observation_matrix``)."""
    z, r = subset(measurement)
    h = observation_matrix(measurement, x.shape[0])
    pht = p @ h.T
    s_inverse = np.linalg.inv(h @ pht + r)
    k = pht @ s_inverse
    innovation = _wrap_angle_entries(z - h @ x, measurement.indices)
    _check(innovation, s_inverse, measurement.threshold)
    gain_residual = np.eye(x.shape[0]) - k @ h
    p_new = gain_residual @ p @ gain_residual.T + k @ r @ k.T
    return wrap_state_angles(x + k @ innovation), p_new


@dataclass(frozen=True)
class UnscentedWeights:
    """The scaled unscented transform's parameters and weights for n = ``size`` (15, or
    more with gyro biases)."""

    alpha: float = 0.001
    kappa: float = 0.0
    beta: float = 2.0
    size: int = STATE_SIZE

    @functools.cached_property
    def lam(self) -> float:
        return self.alpha * self.alpha * (self.size + self.kappa) - self.size

    @functools.cached_property
    def mean(self) -> FloatArray:
        """The mean's weights (read-only: computed once, shared by every step)."""
        w = np.full(2 * self.size + 1, 1.0 / (2.0 * (self.size + self.lam)))
        w[0] = self.lam / (self.size + self.lam)
        w.flags.writeable = False
        return w

    @functools.cached_property
    def covariance(self) -> FloatArray:
        """The covariance's weights (read-only, as ``mean``)."""
        w = self.mean.copy()
        w[0] += 1.0 - self.alpha * self.alpha + self.beta
        w.flags.writeable = False
        return w


def sigma_points(x: FloatArray, p: FloatArray, weights: UnscentedWeights) -> FloatArray:
    """2n + 1 points (rows): x, x + the columns of chol((n + lambda) P), x - them."""
    scaled = (weights.size + weights.lam) * p
    try:
        root = np.linalg.cholesky(scaled)
    except np.linalg.LinAlgError:
        # Rounding can leave P a hair indefinite: take its symmetric square root, with
        # negative eigenvalues as zero, rather than stop the filter.
        values, vectors = np.linalg.eigh(0.5 * (scaled + scaled.T))
        root = vectors * np.sqrt(np.clip(values, 0.0, None))
    return np.vstack([x, x + root.T, x - root.T])


def unscented_mean(points: FloatArray, w_mean: FloatArray, angle_columns: list[int]
                   ) -> FloatArray:
    """sum_i w_i X_i over the points' rows, the columns ``angle_columns`` as circular means.

    Computed as X_0 + sum_{i>0} w_i (X_i - X_0), and an angle as X_0 + atan2(sum_{i>0} w_i
    sin d_i, 1 - 2 sum_{i>0} w_i sin^2(d_i / 2)) with d_i = X_i - X_0: the same in exact
    arithmetic, the weights summing to 1. With the peer's alpha of 0.001, w_0 = lambda /
    (n + lambda) is about -1e6, and the direct sum keeps the rounding of terms a million
    times the state's size; the differences here are small and keep none of it.
    """
    first = points[0]
    offsets = points[1:] - first
    w = w_mean[1:]
    mean = first + w @ offsets
    for column in angle_columns:
        d = offsets[:, column]
        mean[column] = wrap(float(first[column]) + math.atan2(
            float(w @ np.sin(d)), 1.0 - 2.0 * float(w @ np.sin(0.5 * d) ** 2)))
    return mean


def ukf_predict(x: FloatArray, p: FloatArray, q: FloatArray, dt: float,
                weights: UnscentedWeights, compiled: bool = True
                ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Propagate the sigma points; (x', P', the propagated points)."""
    compiled_steps = kernels(compiled and _uses_kernels(x))
    if compiled_steps is not None:
        drawn, x_new, p_new, points = compiled_steps.ukf_predict(
            c_doubles(x), c_doubles(p), c_doubles(q), float(dt), STATE_SIZE + weights.lam,
            weights.mean, weights.covariance)
        if drawn:
            return x_new, p_new, points
    return ukf_predict_numpy(x, p, q, dt, weights)


def ukf_predict_numpy(x: FloatArray, p: FloatArray, q: FloatArray, dt: float,
                      weights: UnscentedWeights) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``ukf_predict`` over numpy arrays (and the symmetric root where P has no Cholesky
    factor)."""
    points = np.array([motion.transfer(point, dt) @ point
                       for point in sigma_points(x, p, weights)])
    w_cov = weights.covariance
    mean = unscented_mean(points, weights.mean, list(ANGLES))
    diff = _wrap_angle_entries(points - mean, tuple(range(x.shape[0])))
    p_new = (diff * w_cov[:, None]).T @ diff + dt * q
    return wrap_state_angles(mean), p_new, points


def ukf_correct(x: FloatArray, p: FloatArray, measurement: Measurement,
                weights: UnscentedWeights, points: FloatArray | None, compiled: bool = True
                ) -> tuple[FloatArray, FloatArray]:
    """Correct with ``points`` (the propagated ones), or new ones from (x, P) when None."""
    compiled_steps = kernels(compiled and _uses_kernels(x, measurement))
    if compiled_steps is None:
        return ukf_correct_numpy(x, p, measurement, weights, points)
    x, p = c_doubles(x), c_doubles(p)
    if points is None:
        drawn, squared, x_new, p_new = compiled_steps.ukf_correct_drawn(
            x, p, c_doubles(measurement.z), c_doubles(measurement.covariance),
            measurement.index_array, MIN_VARIANCE, STATE_SIZE + weights.lam, weights.mean,
            weights.covariance)
        if drawn:
            _reject_beyond(squared, measurement.threshold)
            return x_new, p_new
        points = sigma_points(x, p, weights)
    squared, x_new, p_new = compiled_steps.ukf_correct(
        x, p, c_doubles(points), c_doubles(measurement.z), c_doubles(measurement.covariance),
        measurement.index_array, MIN_VARIANCE, weights.mean, weights.covariance)
    _reject_beyond(squared, measurement.threshold)
    return x_new, p_new


def ukf_correct_numpy(x: FloatArray, p: FloatArray, measurement: Measurement,
                      weights: UnscentedWeights, points: FloatArray | None
                      ) -> tuple[FloatArray, FloatArray]:
    """``ukf_correct`` over numpy arrays."""
    if points is None:
        points = sigma_points(x, p, weights)
    idx = list(measurement.indices)
    z, r = subset(measurement)
    w_cov = weights.covariance
    predicted_points = points[:, idx] if not measurement.biased else \
        points @ observation_matrix(measurement, x.shape[0]).T
    predicted = unscented_mean(predicted_points, weights.mean, [
        row for row, index in enumerate(measurement.indices) if index in ANGLES])
    z_diff = _wrap_angle_entries(predicted_points - predicted, measurement.indices)
    x_diff = _wrap_angle_entries(points - x, tuple(range(x.shape[0])))
    s = (z_diff * w_cov[:, None]).T @ z_diff
    cross = (x_diff * w_cov[:, None]).T @ z_diff
    s_inverse = np.linalg.inv(s + r)
    k = cross @ s_inverse
    innovation = _wrap_angle_entries(z - predicted, measurement.indices)
    _check(innovation, s_inverse, measurement.threshold)
    return wrap_state_angles(x + k @ innovation), p - k @ s @ k.T

