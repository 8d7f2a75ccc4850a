"""The unscented Kalman filter for a unicycle among landmarks: the models are not
linearized but propagated through Van der Merwe's scaled sigma points (Wan and van der
Merwe 2000; filterpy's MerweScaledSigmaPoints).

Headings are averaged as angles (the mean of the sigma points' unit vectors) and every
difference of headings or bearings is wrapped to [-pi, pi). The process noise is
additive, P' = sum Wc (X - x')(X - x')' + G M G', and a correction is the standard
x' = x + K y, P' = P - K S K' with K = Pxz S^-1 (the Joseph form has no UKF
counterpart). Sigma points are drawn anew from (x, P) before every step, so several
observations of one camera frame are applied one after the other, each from the
estimate the last one left. A state of four carries the range's scale too
(range_bearing.py): its sigma points are drawn in four dimensions, and the motion
leaves the scale as it is.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from estimation_nodes.core.compiled_loader import load_kernels
from estimation_nodes.core.kalman import range_bearing, unicycle
from estimation_nodes.core.kalman.ekf import Innovation, _symmetric, gain, shifted
from estimation_nodes.core.kalman.range_bearing import EUCLIDEAN, Ranging, SensorPose
from estimation_nodes.core.kalman.unicycle import TWO_PI, UnicycleNoise
from estimation_nodes.core.validation import FloatArray

#: The states the sigma points may span: the pose, or the pose and the range's scale.
STATE_SIZES = (3, 4)


@dataclass(frozen=True)
class SigmaPoints:
    """Van der Merwe's scaled sigma points for a state of ``n`` (3 or 4): spread ``alpha``
    (0 < alpha <= 1), ``beta`` (2 is optimal for a Gaussian), ``kappa`` (usually 0, or
    3 - n)."""

    alpha: float
    beta: float
    kappa: float
    n: int = 3
    Wm: FloatArray = field(init=False, repr=False, compare=False)
    Wc: FloatArray = field(init=False, repr=False, compare=False)
    scale: float = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        n = self.n
        if n not in STATE_SIZES:
            raise ValueError(f"n: expected a state size in {STATE_SIZES}, got {n!r}")
        if not (math.isfinite(self.alpha) and 0 < self.alpha <= 1):
            raise ValueError(f"alpha: expected 0 < alpha <= 1, got {self.alpha!r}")
        if not math.isfinite(self.beta):
            raise ValueError(f"beta: expected a finite number, got {self.beta!r}")
        if not (math.isfinite(self.kappa) and n + self.kappa > 0):
            raise ValueError(f"kappa: expected n + kappa > 0 (n = {n}), got {self.kappa!r}")
        lambda_ = self.alpha ** 2 * (n + self.kappa) - n
        Wm = np.full(2 * n + 1, 0.5 / (n + lambda_))
        Wc = Wm.copy()
        Wm[0] = lambda_ / (n + lambda_)
        Wc[0] = lambda_ / (n + lambda_) + (1 - self.alpha ** 2 + self.beta)
        object.__setattr__(self, "Wm", Wm)
        object.__setattr__(self, "Wc", Wc)
        object.__setattr__(self, "scale", n + lambda_)

    def draw(self, x: FloatArray, P: FloatArray) -> FloatArray:
        """The 2n + 1 sigma points of N(x, P), one a row: x, then x + and x - each column
        of the Cholesky factor of (n + lambda) P."""
        L = np.linalg.cholesky(self.scale * P)
        return np.vstack([x, x + L.T, x - L.T])

    def mean(self, points: FloatArray, angle: int) -> FloatArray:
        """The weighted mean, column ``angle`` averaged as an angle."""
        mean = self.Wm @ points
        mean[angle] = math.atan2(float(self.Wm @ np.sin(points[:, angle])),
                                 float(self.Wm @ np.cos(points[:, angle])))
        return mean


def _differences(points: FloatArray, mean: FloatArray, angle: int) -> FloatArray:
    deltas = points - mean
    deltas[:, angle] = (deltas[:, angle] + math.pi) % TWO_PI - math.pi
    return deltas


def _moved(points: FloatArray, v: float, w: float, dt: float) -> FloatArray:
    """unicycle.move for every sigma point at once (a scale, if any, left as it is)."""
    d, phi = v * dt, w * dt
    heading = points[:, 2] + 0.5 * phi
    return np.column_stack([points[:, 0] + d * np.cos(heading),
                            points[:, 1] + d * np.sin(heading),
                            (points[:, 2] + phi + math.pi) % TWO_PI - math.pi,
                            points[:, 3:]])


COMPILED = "estimation_nodes.core.kalman.compiled"


def prepare_compiled() -> bool:
    """Compile (or load from numba's cache) the prediction's kernel now, not at the first
    odometry message a node answers; False where numba does not import."""
    return load_kernels(COMPILED) is not None


def predict(x: FloatArray, P: FloatArray, v: float, w: float, dt: float,
            noise: UnicycleNoise, points: SigmaPoints,
            compiled: bool = True) -> tuple[FloatArray, FloatArray]:
    """The pose and covariance after driving at (v, w) for dt seconds: the sigma points
    of (x, P) moved, their mean and spread, plus the step's noise. With ``compiled`` and
    numba at hand, kalman/compiled.py does it (odometry comes at 100 Hz, and numpy's
    calls on 7 x 3 arrays cost more than their arithmetic); else ``predict_numpy``."""
    v, w, dt = unicycle.check_motion(v, w, dt)
    kernels = load_kernels(COMPILED) if compiled else None
    if kernels is not None:
        var_d, var_phi = noise.variances(v * dt, w * dt, dt)
        x_next, P_next = np.empty(len(x)), np.empty((len(x), len(x)))
        if kernels.unscented_predict(x, P, v * dt, w * dt, points.scale, points.Wm,
                                     points.Wc, var_d, var_phi, x_next, P_next):
            return x_next, P_next
    # numpy's path: the same steps, and LinAlgError for a P with no Cholesky factor
    return predict_numpy(x, P, v, w, dt, noise, points)


def predict_numpy(x: FloatArray, P: FloatArray, v: float, w: float, dt: float,
                  noise: UnicycleNoise, points: SigmaPoints) -> tuple[FloatArray, FloatArray]:
    """``predict`` over numpy arrays, as the filter reads in the books (the reference the
    compiled kernel is tested equal to)."""
    v, w, dt = unicycle.check_motion(v, w, dt)
    moved = _moved(points.draw(x, P), v, w, dt)
    x_next = points.mean(moved, angle=2)
    deltas = _differences(moved, x_next, angle=2)
    P_next = (deltas.T * points.Wc) @ deltas
    P_next[:3, :3] += unicycle.process_noise(x, v, w, dt, noise)
    return x_next, _symmetric(P_next)


def innovation(x: FloatArray, P: FloatArray, z: FloatArray, landmark: tuple[float, float],
               sensor: SensorPose, R: FloatArray, points: SigmaPoints,
               ranging: Ranging = EUCLIDEAN) -> Innovation:
    """A range-bearing observation ``z`` of ``landmark``, through the sigma points of (x, P)."""
    sigmas = points.draw(x, P)
    seen = np.array([range_bearing.expected(s, landmark, sensor, ranging) for s in sigmas])
    predicted = points.mean(seen, angle=1)
    dz = _differences(seen, predicted, angle=1)
    dx = _differences(sigmas, x, angle=2)
    S = _symmetric((dz.T * points.Wc) @ dz + R)
    return Innovation(range_bearing.residual(z, predicted), S, (dx.T * points.Wc) @ dz, None)


def correct(x: FloatArray, P: FloatArray, observed: Innovation) -> tuple[FloatArray, FloatArray]:
    """The observation applied: x + K y and P - K S K'."""
    K = gain(observed)
    return shifted(x, K, observed.y), _symmetric(P - K @ observed.S @ K.T)
