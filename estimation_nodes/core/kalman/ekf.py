"""The extended Kalman filter for a unicycle among landmarks (Eqs. 6.35 and 6.36 with the
models linearized at the estimate).

Prediction: x' = move(x, u), P' = F P F' + G M G' (F, G the motion's Jacobians in the
state and in the step's distance and turn, M their variances). Correction with one
landmark's range and bearing z: y = z - h(x) (the bearing wrapped), S = H P H' + R,
K = P H' S^-1, x' = x + K y, and the Joseph form P' = (I - K H) P (I - K H)' + K R K',
which stays symmetric and positive semi-definite whatever the rounding.

The iterated EKF (Bell and Cathey 1993) linearizes the measurement again at the
estimate the last pass gave, x_i+1 = x + K_i (z - h(x_i) - H_i (x - x_i)), until the
step is below ``ITERATION_STEP``: a Gauss-Newton search of the posterior's mode, kept
where it converged to a lower posterior cost than the first pass's (else the first
pass is the answer: from a very wide prior the search can leap metres). One pass is
the plain EKF. It matters after a long time unobserved, when the heading is
tens of degrees uncertain and a landmark's bearing, linearized there, would move the
estimate along a tangent far from the arc the measurement allows.
A state of four entries carries the range's scale as well (range_bearing.py): the
motion leaves it as it is, and the observations' Jacobians have a column for it.
Every function returns new values and leaves its inputs alone.
"""

from __future__ import annotations

import math
from typing import NamedTuple, cast

import numpy as np

from estimation_nodes.core.kalman import range_bearing, unicycle
from estimation_nodes.core.kalman.range_bearing import EUCLIDEAN, Ranging, SensorPose
from estimation_nodes.core.kalman.unicycle import UnicycleNoise, wrap
from estimation_nodes.core.validation import FloatArray

#: The iterated EKF stops when no state component moves more than this (m or rad): a
#: micrometre, a microradian, far below what a sensor resolves.
ITERATION_STEP = 1e-6


class Innovation(NamedTuple):
    """What a landmark observation says before it is applied: the residual ``y``, its
    covariance ``S``, the cross covariance ``Pxz`` of state and measurement (P H' for the
    EKF), and the Jacobian ``H`` where the filter linearizes (None for the UKF)."""

    y: FloatArray
    S: FloatArray
    Pxz: FloatArray
    H: FloatArray | None

    @property
    def nis(self) -> float:
        """The normalized innovation squared y' S^-1 y (chi-square with 2 degrees of
        freedom when the filter is consistent)."""
        return float(self.y @ np.linalg.solve(self.S, self.y))


def _symmetric(P: FloatArray) -> FloatArray:
    return 0.5 * (P + P.T)


def predict(x: FloatArray, P: FloatArray, v: float, w: float, dt: float,
            noise: UnicycleNoise) -> tuple[FloatArray, FloatArray]:
    """The pose and covariance after driving at (v, w) for dt seconds:
    P' = F P F' + G diag(var d, var phi) G' (``predict_by_matrices``), written out.

    A robot's odometry comes at 50 to 100 Hz, and numpy's 3 x 3 products cost more
    in their calls than in their arithmetic: F is the identity but for its last
    column (a, b, 1), so each entry of P' is a few products of floats."""
    if len(x) > 3:
        return _predict_with_scale(x, P, v, w, dt, noise)
    v, w, dt = unicycle.check_motion(v, w, dt)
    d, phi = v * dt, w * dt
    heading = x[2] + 0.5 * phi
    c, s = math.cos(heading), math.sin(heading)
    a, b = -d * s, d * c                     # d x' / d theta, d y' / d theta
    var_d, var_phi = noise.variances(d, phi, dt)
    (p00, p01, p02), (_, p11, p12), (_, _, p22) = P.tolist()
    # F P F'
    q00 = p00 + 2.0 * a * p02 + a * a * p22
    q01 = p01 + a * p12 + b * p02 + a * b * p22
    q02 = p02 + a * p22
    q11 = p11 + 2.0 * b * p12 + b * b * p22
    q12 = p12 + b * p22
    # + G M G', G = [[c, a / 2], [s, b / 2], [0, 1]]
    ha, hb = 0.5 * a, 0.5 * b
    q00 += c * c * var_d + ha * ha * var_phi
    q01 += c * s * var_d + ha * hb * var_phi
    q02 += ha * var_phi
    q11 += s * s * var_d + hb * hb * var_phi
    q12 += hb * var_phi
    q22 = p22 + var_phi
    moved = np.array([x[0] + d * c, x[1] + d * s, wrap(x[2] + phi)])
    return moved, np.array([[q00, q01, q02], [q01, q11, q12], [q02, q12, q22]])


def _predict_with_scale(x: FloatArray, P: FloatArray, v: float, w: float, dt: float,
                        noise: UnicycleNoise) -> tuple[FloatArray, FloatArray]:
    """``predict`` of a state with the range's scale: the pose block as above, the scale
    unchanged, and its covariance with the pose carried by F (its last column)."""
    pose, pose_P = predict(x[:3], P[:3, :3], v, w, dt, noise)
    d, phi = v * dt, w * dt
    heading = x[2] + 0.5 * phi
    a, b = -d * math.sin(heading), d * math.cos(heading)
    c0, c1, c2, scale_var = P[:, 3].tolist()
    c0, c1 = c0 + a * c2, c1 + b * c2
    (q00, q01, q02), (_, q11, q12), (_, _, q22) = pose_P.tolist()
    return (np.array([*pose.tolist(), x[3]]),
            np.array([[q00, q01, q02, c0], [q01, q11, q12, c1], [q02, q12, q22, c2],
                      [c0, c1, c2, scale_var]]))


def predict_by_matrices(x: FloatArray, P: FloatArray, v: float, w: float, dt: float,
                        noise: UnicycleNoise) -> tuple[FloatArray, FloatArray]:
    """``predict`` as the matrix products it writes out (the tests hold them equal)."""
    v, w, dt = unicycle.check_motion(v, w, dt)
    F3, G3 = unicycle.jacobians(x, v, w, dt)
    n = len(x)
    F, G = np.eye(n), np.zeros((n, 2))          # the scale, if any, does not move
    F[:3, :3], G[:3] = F3, G3
    var_d, var_phi = noise.variances(v * dt, w * dt, dt)
    P_next = F @ P @ F.T + (G * np.array([var_d, var_phi])) @ G.T
    return np.append(unicycle.move(x, v, w, dt), x[3:]), _symmetric(P_next)


def innovation(x: FloatArray, P: FloatArray, z: FloatArray, landmark: tuple[float, float],
               sensor: SensorPose, R: FloatArray,
               ranging: Ranging = EUCLIDEAN) -> Innovation:
    """A range-bearing observation ``z`` of ``landmark``, linearized at x."""
    H = range_bearing.jacobian(x, landmark, sensor, ranging)
    PHt = P @ H.T
    S = _symmetric(H @ PHt + R)
    predicted = range_bearing.expected(x, landmark, sensor, ranging)
    return Innovation(range_bearing.residual(z, predicted), S, PHt, H)


def correct(x: FloatArray, P: FloatArray, observed: Innovation,
            R: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The observation applied, with the Joseph form of the covariance update."""
    assert observed.H is not None, "an EKF correction needs the EKF's innovation"
    K = gain(observed)
    I_KH = np.eye(len(x)) - K @ observed.H
    return shifted(x, K, observed.y), _symmetric(I_KH @ P @ I_KH.T + K @ R @ K.T)


def gain(observed: Innovation) -> FloatArray:
    """K = Pxz S^-1."""
    return cast(FloatArray, np.linalg.solve(observed.S, observed.Pxz.T).T)


def shifted(x: FloatArray, K: FloatArray, y: FloatArray) -> FloatArray:
    """x + K y, the heading wrapped (the EKF's and the UKF's corrections)."""
    x_next = x + K @ y
    x_next[2] = wrap(x_next[2])
    return x_next


def correct_iterated(x: FloatArray, P: FloatArray, observed: Innovation, z: FloatArray,
                     landmark: tuple[float, float], sensor: SensorPose, R: FloatArray,
                     ranging: Ranging, iterations: int) -> tuple[FloatArray, FloatArray, bool]:
    """The observation applied by the iterated EKF, at most ``iterations`` passes (the
    first is ``observed``, linearized at x); the Joseph form at the last linearization.
    The third value: whether the search was kept (always True for one pass, the EKF).
    Only the mean is updated between passes.

    Gauss-Newton may not converge, or converge far away: with the covariance wide (a
    recovery) it can leap metres from x to where the one landmark fits as well. The
    search is kept only where it converged to a lower posterior cost than the single
    pass reaches; elsewhere the single pass is the answer."""
    single = correct(x, P, observed, R)
    if iterations == 1:
        return (*single, True)
    x_next = single[0]
    last, converged = observed, False
    for _ in range(iterations - 1):
        at = x_next
        try:
            here = innovation(at, P, z, landmark, sensor, R, ranging)
        except ValueError:
            # an iterate on the landmark itself, where it has no bearing
            return (*single, False)
        assert here.H is not None
        # linearized at ``at``, applied from x: y = z - h(at) - H (x - at)
        offset = x - at
        offset[2] = wrap(offset[2])
        last = here._replace(y=here.y - here.H @ offset)
        x_next = shifted(x, gain(last), last.y)
        step = x_next - at
        step[2] = wrap(step[2])
        if np.abs(step).max() <= ITERATION_STEP:
            converged = True
            break
    cost = lambda at: posterior_cost(at, x, P, z, landmark, sensor, R, ranging)  # noqa: E731
    if not converged or cost(x_next) > cost(single[0]):
        return (*single, False)
    return (*correct(x, P, last, R), True)


def posterior_cost(at: FloatArray, x: FloatArray, P: FloatArray, z: FloatArray,
                   landmark: tuple[float, float], sensor: SensorPose, R: FloatArray,
                   ranging: Ranging) -> float:
    """(at - x)' P^-1 (at - x) + (z - h(at))' R^-1 (z - h(at)): what the iterated EKF's
    search lowers (its minimum is the posterior's mode)."""
    moved = at - x
    moved[2] = wrap(moved[2])
    y = range_bearing.residual(z, range_bearing.expected(at, landmark, sensor, ranging))
    return float(moved @ np.linalg.solve(P, moved) + y @ np.linalg.solve(R, y))
