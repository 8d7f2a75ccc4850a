"""Compiled kernel of the landmark UKF (numba): its prediction over 2n + 1 sigma points
(n = 3, the pose, or 4 with the range's scale).

A robot's odometry comes at 100 Hz; numpy's prediction (ukf.predict_numpy) spends
its time in the calls on 7 x 3 arrays, not in the arithmetic. Here the same steps
run over floats in one call: the Cholesky factor of scale P, the sigma points
moved by the unicycle, their mean (the heading as an angle) and weighted spread,
and the step's noise G diag(var d, var phi) G' at the mean before the step.
Results equal numpy's to rounding (tests/unit/test_landmark_models.py).

Importing this module imports numba; ``warm_up`` compiles the kernel or loads it
from numba's cache (``cache=True``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from estimation_nodes.core.validation import FloatArray

_jit = njit(nogil=True, cache=True)
TWO_PI = 2.0 * math.pi


@_jit
def unscented_predict(x: FloatArray, P: FloatArray, d: float, phi: float, scale: float,
                      Wm: FloatArray, Wc: FloatArray, var_d: float, var_phi: float,
                      x_out: FloatArray, P_out: FloatArray) -> bool:
    """x_out, P_out: the state and covariance after a step of distance d and turn phi
    (the pose, and a range scale if the state has a fourth entry, which the step leaves).
    False, with the outputs unset, where scale P has no Cholesky factor."""
    n = x.shape[0]
    # L L' = scale P, L lower triangular; its columns are the sigma points' offsets
    L = np.zeros((n, n))
    for j in range(n):
        pivot = scale * P[j, j]
        for k in range(j):
            pivot -= L[j, k] * L[j, k]
        if not pivot > 0.0:
            return False
        L[j, j] = math.sqrt(pivot)
        for i in range(j + 1, n):
            value = scale * P[i, j]
            for k in range(j):
                value -= L[i, k] * L[j, k]
            L[i, j] = value / L[j, j]
    points = 2 * n + 1
    moved = np.empty((points, n))
    for point in range(points):
        for i in range(n):
            moved[point, i] = x[i]
        if point > 0:
            column, sign = (point - 1) % n, 1.0 if point <= n else -1.0
            for i in range(n):
                moved[point, i] += sign * L[i, column]
        heading = moved[point, 2]
        along = heading + 0.5 * phi
        moved[point, 0] += d * math.cos(along)
        moved[point, 1] += d * math.sin(along)
        moved[point, 2] = (heading + phi + math.pi) % TWO_PI - math.pi
    sines = cosines = 0.0
    for i in range(n):
        x_out[i] = 0.0
    for point in range(points):
        for i in range(n):
            if i != 2:
                x_out[i] += Wm[point] * moved[point, i]
        sines += Wm[point] * math.sin(moved[point, 2])
        cosines += Wm[point] * math.cos(moved[point, 2])
    x_out[2] = math.atan2(sines, cosines)
    # the step's noise, G M G' with G at the heading before the step (unicycle.jacobians);
    # G's rows beyond the pose are nil
    along = x[2] + 0.5 * phi
    c, s = math.cos(along), math.sin(along)
    G = np.zeros((n, 2))
    G[0, 0], G[0, 1], G[1, 0], G[1, 1], G[2, 1] = c, -0.5 * d * s, s, 0.5 * d * c, 1.0
    for i in range(n):
        for j in range(n):
            P_out[i, j] = G[i, 0] * var_d * G[j, 0] + G[i, 1] * var_phi * G[j, 1]
    delta = np.empty(n)
    for point in range(points):
        for i in range(n):
            delta[i] = moved[point, i] - x_out[i]
        delta[2] = (delta[2] + math.pi) % TWO_PI - math.pi
        for i in range(n):
            for j in range(n):
                P_out[i, j] += Wc[point] * delta[i] * delta[j]
    return True


def warm_up() -> None:
    """Compile (or load from numba's cache) the kernel on a tiny input."""
    weights = np.full(7, 1.0 / 7)
    unscented_predict(np.zeros(3), np.eye(3), 0.1, 0.1, 3.0, weights, weights, 0.0, 0.0,
                      np.empty(3), np.empty((3, 3)))
