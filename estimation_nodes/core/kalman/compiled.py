"""Compiled kernel of the landmark UKF (numba): its prediction over seven sigma points.

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
    """x_out, P_out: the pose and covariance after a step of distance d and turn phi.
    False, with the outputs unset, where scale P has no Cholesky factor."""
    # L L' = scale P, L lower triangular; its columns are the sigma points' offsets
    L = np.zeros((3, 3))
    for j in range(3):
        pivot = scale * P[j, j]
        for k in range(j):
            pivot -= L[j, k] * L[j, k]
        if not pivot > 0.0:
            return False
        L[j, j] = math.sqrt(pivot)
        for i in range(j + 1, 3):
            value = scale * P[i, j]
            for k in range(j):
                value -= L[i, k] * L[j, k]
            L[i, j] = value / L[j, j]
    moved = np.empty((7, 3))
    for point in range(7):
        px, py, heading = x[0], x[1], x[2]
        if point > 0:
            column, sign = (point - 1) % 3, 1.0 if point <= 3 else -1.0
            px += sign * L[0, column]
            py += sign * L[1, column]
            heading += sign * L[2, column]
        along = heading + 0.5 * phi
        moved[point, 0] = px + d * math.cos(along)
        moved[point, 1] = py + d * math.sin(along)
        moved[point, 2] = (heading + phi + math.pi) % TWO_PI - math.pi
    sines = cosines = 0.0
    x_out[0] = x_out[1] = 0.0
    for point in range(7):
        x_out[0] += Wm[point] * moved[point, 0]
        x_out[1] += Wm[point] * moved[point, 1]
        sines += Wm[point] * math.sin(moved[point, 2])
        cosines += Wm[point] * math.cos(moved[point, 2])
    x_out[2] = math.atan2(sines, cosines)
    # the step's noise, G M G' with G at the heading before the step (unicycle.jacobians)
    along = x[2] + 0.5 * phi
    c, s = math.cos(along), math.sin(along)
    G = np.array([[c, -0.5 * d * s], [s, 0.5 * d * c], [0.0, 1.0]])
    for i in range(3):
        for j in range(3):
            P_out[i, j] = G[i, 0] * var_d * G[j, 0] + G[i, 1] * var_phi * G[j, 1]
    delta = np.empty(3)
    for point in range(7):
        delta[0] = moved[point, 0] - x_out[0]
        delta[1] = moved[point, 1] - x_out[1]
        delta[2] = (moved[point, 2] - x_out[2] + math.pi) % TWO_PI - math.pi
        for i in range(3):
            for j in range(3):
                P_out[i, j] += Wc[point] * delta[i] * delta[j]
    return True


def warm_up() -> None:
    """Compile (or load from numba's cache) the kernel on a tiny input."""
    weights = np.full(7, 1.0 / 7)
    unscented_predict(np.zeros(3), np.eye(3), 0.1, 0.1, 3.0, weights, weights, 0.0, 0.0,
                      np.empty(3), np.empty((3, 3)))
