"""The EKF and UKF steps over robot_localization's state (the book's symbols: x, P, Q, R, K).

A measurement gives values for a subset of the state (``Measurement.indices``), so its
H is a selection of rows of the identity. Both filters:
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
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimation_nodes.core.fusion import motion
from estimation_nodes.core.fusion.state import ANGLES, PITCH, ROLL, STATE_SIZE, YAW, \
    wrap_state_angles
from estimation_nodes.core.errors import InvalidInputError
from estimation_nodes.core.validation import FloatArray, check_covariance

#: The smallest variance a measurement may claim (the peer's floor).
MIN_VARIANCE = 1e-9


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


def covariance_problem(measurement: Measurement) -> str | None:
    """Why the measurement's R (on its entries, its variances as ``subset`` floors them)
    cannot be used, None when it can: a non-finite entry, or a matrix that is not symmetric
    positive semi-definite (the peer takes it as it is: an indefinite R can turn the
    innovation's covariance indefinite and the state's with it)."""
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


def _check(innovation: np.ndarray, s_inverse: np.ndarray, threshold: float) -> None:
    squared = float(innovation @ s_inverse @ innovation)
    if squared >= threshold * threshold:
        raise Rejected(squared, threshold)


def ekf_predict(x: FloatArray, p: FloatArray, q: FloatArray, dt: float
                ) -> tuple[FloatArray, FloatArray]:
    """x' = F(x) x, P' = J P J' + dt Q."""
    f = motion.transfer(x, dt)
    j = motion.jacobian(x, dt)
    return wrap_state_angles(f @ x), j @ p @ j.T + dt * q


def ekf_correct(x: FloatArray, p: FloatArray, measurement: Measurement
                ) -> tuple[FloatArray, FloatArray]:
    """K = P H' (H P H' + R)^-1, x' = x + K y, P' = (I - K H) P (I - K H)' + K R K'."""
    idx = list(measurement.indices)
    z, r = subset(measurement)
    pht = p[:, idx]                       # P H' with H the rows idx of the identity
    s_inverse = np.linalg.inv(pht[idx] + r)
    k = pht @ s_inverse
    innovation = _wrap_angle_entries(z - x[idx], measurement.indices)
    _check(innovation, s_inverse, measurement.threshold)
    gain_residual = np.eye(STATE_SIZE)
    gain_residual[:, idx] -= k
    p_new = gain_residual @ p @ gain_residual.T + k @ r @ k.T
    return wrap_state_angles(x + k @ innovation), p_new


@dataclass(frozen=True)
class UnscentedWeights:
    """The scaled unscented transform's parameters and weights for n = 15."""

    alpha: float = 0.001
    kappa: float = 0.0
    beta: float = 2.0

    @property
    def lam(self) -> float:
        return self.alpha * self.alpha * (STATE_SIZE + self.kappa) - STATE_SIZE

    @property
    def mean(self) -> FloatArray:
        w = np.full(2 * STATE_SIZE + 1, 1.0 / (2.0 * (STATE_SIZE + self.lam)))
        w[0] = self.lam / (STATE_SIZE + self.lam)
        return w

    @property
    def covariance(self) -> FloatArray:
        w = self.mean.copy()
        w[0] += 1.0 - self.alpha * self.alpha + self.beta
        return w


def sigma_points(x: FloatArray, p: FloatArray, weights: UnscentedWeights) -> FloatArray:
    """2n + 1 points (rows): x, x + the columns of chol((n + lambda) P), x - them."""
    scaled = (STATE_SIZE + weights.lam) * p
    try:
        root = np.linalg.cholesky(scaled)
    except np.linalg.LinAlgError:
        # Rounding can leave P a hair indefinite: take its symmetric square root, with
        # negative eigenvalues as zero, rather than stop the filter.
        values, vectors = np.linalg.eigh(0.5 * (scaled + scaled.T))
        root = vectors * np.sqrt(np.clip(values, 0.0, None))
    return np.vstack([x, x + root.T, x - root.T])


def _circular_mean(values: FloatArray, weights: FloatArray) -> float:
    return math.atan2(float(weights @ np.sin(values)), float(weights @ np.cos(values)))


def ukf_predict(x: FloatArray, p: FloatArray, q: FloatArray, dt: float,
                weights: UnscentedWeights) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Propagate the sigma points; (x', P', the propagated points)."""
    points = np.array([motion.transfer(point, dt) @ point
                       for point in sigma_points(x, p, weights)])
    w_mean, w_cov = weights.mean, weights.covariance
    mean = w_mean @ points
    for index in (ROLL, PITCH, YAW):
        mean[index] = _circular_mean(points[:, index], w_mean)
    diff = _wrap_angle_entries(points - mean, tuple(range(STATE_SIZE)))
    p_new = (diff * w_cov[:, None]).T @ diff + dt * q
    return wrap_state_angles(mean), p_new, points


def ukf_correct(x: FloatArray, p: FloatArray, measurement: Measurement,
                weights: UnscentedWeights, points: FloatArray | None
                ) -> tuple[FloatArray, FloatArray]:
    """Correct with ``points`` (the propagated ones), or new ones from (x, P) when None."""
    if points is None:
        points = sigma_points(x, p, weights)
    idx = list(measurement.indices)
    z, r = subset(measurement)
    w_mean, w_cov = weights.mean, weights.covariance
    predicted_points = points[:, idx]
    predicted = w_mean @ predicted_points
    for row, index in enumerate(measurement.indices):
        if index in ANGLES:
            predicted[row] = _circular_mean(predicted_points[:, row], w_mean)
    z_diff = _wrap_angle_entries(predicted_points - predicted, measurement.indices)
    x_diff = _wrap_angle_entries(points - x, tuple(range(STATE_SIZE)))
    s = (z_diff * w_cov[:, None]).T @ z_diff
    cross = (x_diff * w_cov[:, None]).T @ z_diff
    s_inverse = np.linalg.inv(s + r)
    k = cross @ s_inverse
    innovation = _wrap_angle_entries(z - predicted, measurement.indices)
    _check(innovation, s_inverse, measurement.threshold)
    return wrap_state_angles(x + k @ innovation), p - k @ s @ k.T

