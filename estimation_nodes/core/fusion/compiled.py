"""Compiled kernels of the fusion filter (numba): steps.py's EKF and UKF steps over floats.

A robot_localization filter takes an IMU at 30 to 100 Hz and wheel odometry besides, each
reading a correction and most a prediction; numpy's steps spend their time in the calls
on 15 x 15 and 31 x 15 arrays, not in the arithmetic (a UKF prediction builds the
transition matrix 31 times). Here each step is one call. The motion model is motion.py's
own functions, compiled; the rest are the steps of steps.py written as loops, with H a
selection of the identity's rows (``idx``) so that products with it are index look-ups.
Results equal numpy's to rounding (tests/unit/test_fusion_core.py).

Importing this module imports numba; ``warm_up`` compiles the kernels or loads them from
numba's cache (``cache=True``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from estimation_nodes.core.fusion import motion, state
from estimation_nodes.core.validation import FloatArray

_jit = njit(nogil=True, cache=True)
N = state.STATE_SIZE
TWO_PI = 2.0 * math.pi
_write_transfer = _jit(motion.write_transfer)
_write_angle_derivatives = _jit(motion.write_angle_derivatives)
_rpy_from_rotation = _jit(state.rpy_from_rotation)
_rotation_from_quaternion = _jit(state.rotation_from_quaternion)
_rotation_from_rpy = _jit(state.rotation_from_rpy)


@_jit
def _is_angle(index: int) -> bool:
    return index == state.ROLL or index == state.PITCH or index == state.YAW


@_jit
def _wrap(angle: float) -> float:
    """state.wrap with numpy's fmod (numba has no math.fmod; both are C's, exact)."""
    positive = np.fmod(np.fmod(angle, TWO_PI) + TWO_PI, TWO_PI)
    return positive - TWO_PI if positive > math.pi else positive


@_jit
def _wrap_angles(x: FloatArray) -> None:
    """state.wrap_state_angles, in place."""
    for index in range(state.ROLL, state.YAW + 1):
        x[index] = _wrap(x[index])


@_jit
def _wrapped_difference(value: float, index: int) -> float:
    """A difference of entry ``index``, wrapped into [-pi, pi) where it is an angle
    (steps._wrap_angle_entries)."""
    if _is_angle(index):
        return (value + math.pi) % TWO_PI - math.pi
    return value


@_jit
def _measured(z_full: FloatArray, covariance: FloatArray, idx: np.ndarray,
              min_variance: float) -> tuple[FloatArray, FloatArray]:
    """steps.subset: (z, R) on the entries ``idx``, R's variances floored."""
    m = idx.shape[0]
    z = np.empty(m)
    r = np.empty((m, m))
    for a in range(m):
        z[a] = z_full[idx[a]]
        for b in range(m):
            r[a, b] = covariance[idx[a], idx[b]]
        r[a, a] = max(abs(r[a, a]), min_variance)
    return z, r


@_jit
def covariance_verdict(covariance: FloatArray, idx: np.ndarray, min_variance: float,
                       tolerance: float) -> int:
    """What steps.covariance_problem would say of R on ``idx`` (variances floored): 0 a
    covariance, 1 not finite, 2 undecided here (numpy's check decides).

    0 is proven: R is symmetric to ``tolerance`` times its scale and, by Gershgorin's
    theorem over its lower triangle (what eigvalsh reads), has no eigenvalue below
    -``tolerance`` times its scale, numpy's test."""
    _, r = _measured(np.zeros(covariance.shape[0]), covariance, idx, min_variance)
    m = idx.shape[0]
    scale = 1.0
    for a in range(m):
        for b in range(m):
            if not math.isfinite(r[a, b]):
                return 1
            scale = max(scale, abs(r[a, b]))
    bound = tolerance * scale
    for a in range(m):
        radius = 0.0
        for b in range(m):
            if abs(r[a, b] - r[b, a]) > bound:
                return 2
            if b != a:
                radius += abs(r[max(a, b), min(a, b)])
        if r[a, a] - radius < -bound:
            return 2
    return 0


@_jit
def _move(x: FloatArray, dt: float, f: FloatArray, moved: FloatArray) -> None:
    """moved = F(x) x, the state after dt, angles not wrapped; ``f`` is the transfer
    matrix's storage (an identity, or an ``f`` written before)."""
    _write_transfer(x, dt, f)
    for i in range(N):
        total = 0.0
        for k in range(N):
            if f[i, k] != 0.0:
                total += f[i, k] * x[k]
        moved[i] = total


@_jit
def _gain(x: FloatArray, cross: FloatArray, s: FloatArray, z: FloatArray,
          predicted: FloatArray, idx: np.ndarray) -> tuple[FloatArray, float, FloatArray]:
    """K = C S^-1 (C the state's covariance with the measured entries, S the innovation's),
    the squared Mahalanobis distance of the innovation y = z - predicted (angles wrapped)
    and x + K y (angles wrapped)."""
    m = idx.shape[0]
    s_inverse = np.linalg.inv(s)
    k = np.zeros((N, m))
    for i in range(N):
        for b in range(m):
            for a in range(m):
                k[i, a] += cross[i, b] * s_inverse[b, a]
    innovation = np.empty(m)
    for a in range(m):
        innovation[a] = _wrapped_difference(z[a] - predicted[a], idx[a])
    squared = 0.0
    for a in range(m):
        for b in range(m):
            squared += innovation[a] * s_inverse[a, b] * innovation[b]
    x_new = x.copy()
    for i in range(N):
        for a in range(m):
            x_new[i] += k[i, a] * innovation[a]
    _wrap_angles(x_new)
    return k, squared, x_new


@_jit
def ekf_predict(x: FloatArray, p: FloatArray, q: FloatArray, dt: float
                ) -> tuple[FloatArray, FloatArray]:
    """steps.ekf_predict: x' = F(x) x, P' = J P J' + dt Q."""
    j = np.eye(N)
    _write_transfer(x, dt, j)
    _write_angle_derivatives(x, dt, j)
    x_new = np.empty(N)
    _move(x, dt, np.eye(N), x_new)
    _wrap_angles(x_new)
    jp = np.zeros((N, N))
    for i in range(N):
        for k in range(N):
            if j[i, k] != 0.0:
                for c in range(N):
                    jp[i, c] += j[i, k] * p[k, c]
    p_new = dt * q
    for i in range(N):
        for c in range(N):
            total = 0.0
            for k in range(N):
                total += jp[i, k] * j[c, k]
            p_new[i, c] += total
    return x_new, p_new


@_jit
def ekf_correct(x: FloatArray, p: FloatArray, z_full: FloatArray, covariance: FloatArray,
                idx: np.ndarray, min_variance: float
                ) -> tuple[float, FloatArray, FloatArray]:
    """steps.ekf_correct (the Joseph form); the squared Mahalanobis distance first, for
    the caller to reject on."""
    z, r = _measured(z_full, covariance, idx, min_variance)
    m = idx.shape[0]
    pht = np.empty((N, m))
    for i in range(N):
        for a in range(m):
            pht[i, a] = p[i, idx[a]]
    s = r.copy()
    for a in range(m):
        for b in range(m):
            s[a, b] += pht[idx[a], b]
    k, squared, x_new = _gain(x, pht, s, z, x[idx], idx)
    # (I - K H) P (I - K H)' + K R K', I - K H being the identity less K in the columns idx
    kept = p.copy()
    for i in range(N):
        for a in range(m):
            for c in range(N):
                kept[i, c] -= k[i, a] * p[idx[a], c]
    p_new = kept.copy()
    for i in range(N):
        for a in range(m):
            for c in range(N):
                p_new[i, c] -= kept[i, idx[a]] * k[c, a]
    kr = np.zeros((N, m))
    for i in range(N):
        for a in range(m):
            for b in range(m):
                kr[i, b] += k[i, a] * r[a, b]
    for i in range(N):
        for c in range(N):
            for b in range(m):
                p_new[i, c] += kr[i, b] * k[c, b]
    return squared, x_new, p_new


@_jit
def sigma_points(x: FloatArray, p: FloatArray, scale: float) -> tuple[bool, FloatArray]:
    """steps.sigma_points by Cholesky's factor of scale P; False where it has none (numpy's
    path then takes the symmetric square root)."""
    root = np.zeros((N, N))
    points = np.empty((2 * N + 1, N))
    for j in range(N):
        pivot = scale * p[j, j]
        for c in range(j):
            pivot -= root[j, c] * root[j, c]
        if not pivot > 0.0:
            return False, points
        root[j, j] = math.sqrt(pivot)
        for i in range(j + 1, N):
            value = scale * p[i, j]
            for c in range(j):
                value -= root[i, c] * root[j, c]
            root[i, j] = value / root[j, j]
    for i in range(N):
        points[0, i] = x[i]
        for column in range(N):
            points[1 + column, i] = x[i] + root[i, column]
            points[1 + N + column, i] = x[i] - root[i, column]
    return True, points


@_jit
def _weighted_mean(points: FloatArray, w_mean: FloatArray, column: int,
                   angle: bool) -> float:
    """The points' weighted mean of one column, an angle's circular, over the differences
    to the first point (steps.unscented_mean says why)."""
    first = points[0, column]
    if angle:
        sines = versines = 0.0
        for point in range(1, points.shape[0]):
            d = points[point, column] - first
            half = math.sin(0.5 * d)
            sines += w_mean[point] * math.sin(d)
            versines += w_mean[point] * half * half
        return _wrap(first + math.atan2(sines, 1.0 - 2.0 * versines))
    total = 0.0
    for point in range(1, points.shape[0]):
        total += w_mean[point] * (points[point, column] - first)
    return first + total


@_jit
def ukf_predict(x: FloatArray, p: FloatArray, q: FloatArray, dt: float, scale: float,
                w_mean: FloatArray, w_cov: FloatArray
                ) -> tuple[bool, FloatArray, FloatArray, FloatArray]:
    """steps.ukf_predict: (drawn, x', P', the propagated points); drawn False where
    scale P has no Cholesky factor (nothing else is then set)."""
    drawn, points = sigma_points(x, p, scale)
    mean = np.empty(N)
    p_new = dt * q
    if not drawn:
        return False, mean, p_new, points
    f = np.eye(N)
    moved = np.empty(N)
    for point in range(points.shape[0]):
        _move(points[point], dt, f, moved)
        points[point] = moved
    for i in range(N):
        mean[i] = _weighted_mean(points, w_mean, i, _is_angle(i))
    diff = np.empty(N)
    spread = np.zeros((N, N))
    for point in range(points.shape[0]):
        for i in range(N):
            diff[i] = _wrapped_difference(points[point, i] - mean[i], i)
        for i in range(N):
            weighted = w_cov[point] * diff[i]
            for c in range(i, N):
                spread[i, c] += weighted * diff[c]
    for i in range(N):
        for c in range(i, N):
            p_new[i, c] += spread[i, c]
            if c != i:
                p_new[c, i] += spread[i, c]
    _wrap_angles(mean)
    return True, mean, p_new, points


@_jit
def ukf_correct(x: FloatArray, p: FloatArray, points: FloatArray, z_full: FloatArray,
                covariance: FloatArray, idx: np.ndarray, min_variance: float,
                w_mean: FloatArray, w_cov: FloatArray) -> tuple[float, FloatArray, FloatArray]:
    """steps.ukf_correct with the sigma points given; the squared Mahalanobis distance
    first, for the caller to reject on."""
    z, r = _measured(z_full, covariance, idx, min_variance)
    m = idx.shape[0]
    count = points.shape[0]
    predicted = np.empty(m)
    for a in range(m):
        predicted[a] = _weighted_mean(points, w_mean, idx[a], _is_angle(idx[a]))
    s = np.zeros((m, m))
    cross = np.zeros((N, m))
    z_diff = np.empty(m)
    x_diff = np.empty(N)
    for point in range(count):
        for a in range(m):
            z_diff[a] = _wrapped_difference(points[point, idx[a]] - predicted[a], idx[a])
        for i in range(N):
            x_diff[i] = _wrapped_difference(points[point, i] - x[i], i)
        for a in range(m):
            weighted = w_cov[point] * z_diff[a]
            for b in range(m):
                s[a, b] += weighted * z_diff[b]
            for i in range(N):
                cross[i, a] += w_cov[point] * x_diff[i] * z_diff[a]
    k, squared, x_new = _gain(x, cross, s + r, z, predicted, idx)
    ks = np.zeros((N, m))
    for i in range(N):
        for a in range(m):
            for b in range(m):
                ks[i, b] += k[i, a] * s[a, b]
    p_new = p.copy()
    for i in range(N):
        for c in range(N):
            for b in range(m):
                p_new[i, c] -= ks[i, b] * k[c, b]
    return squared, x_new, p_new


@_jit
def ukf_correct_drawn(x: FloatArray, p: FloatArray, z_full: FloatArray,
                      covariance: FloatArray, idx: np.ndarray, min_variance: float,
                      scale: float, w_mean: FloatArray, w_cov: FloatArray
                      ) -> tuple[bool, float, FloatArray, FloatArray]:
    """ukf_correct with sigma points drawn anew from (x, P) (``sigma_points``), in one call;
    False where scale P has no Cholesky factor (x and P returned as they were)."""
    drawn, points = sigma_points(x, p, scale)
    if not drawn:
        return False, 0.0, x, p
    squared, x_new, p_new = ukf_correct(x, p, points, z_full, covariance, idx, min_variance,
                                        w_mean, w_cov)
    return True, squared, x_new, p_new


@_jit
def _cross(a: FloatArray, b: FloatArray) -> tuple[float, float, float]:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@_jit
def _turned(rotation: FloatArray, vector: FloatArray, row: int) -> float:
    """Row ``row`` of R v."""
    return rotation[row, 0] * vector[0] + rotation[row, 1] * vector[1] + \
        rotation[row, 2] * vector[2]


@_jit
def _write_turned_covariance(rotation: FloatArray, covariance: FloatArray, out: FloatArray,
                             start: int) -> None:
    """out's block at (start, start) = B C B', B the rotation on each 3-block of C's
    (C 3 x 3, or 6 x 6 for a pose or a twist)."""
    n = covariance.shape[0]
    turned = np.empty((n, n))
    for a in range(n):
        base = (a // 3) * 3
        for d in range(n):
            turned[a, d] = rotation[a % 3, 0] * covariance[base, d] + \
                rotation[a % 3, 1] * covariance[base + 1, d] + \
                rotation[a % 3, 2] * covariance[base + 2, d]
    for a in range(n):
        for b in range(n):
            base = (b // 3) * 3
            out[start + a, start + b] = turned[a, base] * rotation[b % 3, 0] + \
                turned[a, base + 1] * rotation[b % 3, 1] + \
                turned[a, base + 2] * rotation[b % 3, 2]


@_jit
def _write_twist(rotation: FloatArray, origin: FloatArray, linear: FloatArray,
                 angular: FloatArray, covariance6: FloatArray, rates: FloatArray,
                 z: FloatArray, covariance: FloatArray) -> None:
    """inputs.twist's values into the twist's entries of z and covariance: v = R linear + o
    x omega, omega' = R angular, and R C R' (R on both halves)."""
    lever = _cross(origin, rates)
    for i in range(3):
        z[state.VX + i] = _turned(rotation, linear, i) + lever[i]
        z[state.VROLL + i] = _turned(rotation, angular, i)
    _write_turned_covariance(rotation, covariance6, covariance, state.VX)


@_jit
def twist_values(rotation: FloatArray, origin: FloatArray, linear: FloatArray,
                 angular: FloatArray, covariance6: FloatArray, rates: FloatArray
                 ) -> tuple[FloatArray, FloatArray]:
    """inputs.twist's z and covariance (``_write_twist``)."""
    z = np.zeros(N)
    covariance = np.zeros((N, N))
    _write_twist(rotation, origin, linear, angular, covariance6, rates, z, covariance)
    return z, covariance


@_jit
def _write_acceleration(rotation: FloatArray, origin: FloatArray, linear: FloatArray,
                        covariance3: FloatArray, rates: FloatArray,
                        angular_acceleration: FloatArray, attitude: FloatArray,
                        gravity: float, z: FloatArray, covariance: FloatArray) -> None:
    """inputs.acceleration's values into the acceleration's entries of z and covariance: a
    = R (linear - attitude' (0, 0, g)) + o x alpha - (o x omega) x omega (g 0 to keep
    gravity), and R C R'."""
    felt = np.empty(3)
    for i in range(3):
        felt[i] = linear[i] - attitude[2, i] * gravity
    tangential = _cross(origin, angular_acceleration)
    centripetal = _cross(np.array(_cross(origin, rates)), rates)
    for i in range(3):
        z[state.AX + i] = _turned(rotation, felt, i) + tangential[i] - centripetal[i]
    _write_turned_covariance(rotation, covariance3, covariance, state.AX)


@_jit
def acceleration_values(rotation: FloatArray, origin: FloatArray, linear: FloatArray,
                        covariance3: FloatArray, rates: FloatArray,
                        angular_acceleration: FloatArray, attitude: FloatArray,
                        gravity: float) -> tuple[FloatArray, FloatArray]:
    """inputs.acceleration's z and covariance (``_write_acceleration``)."""
    z = np.zeros(N)
    covariance = np.zeros((N, N))
    _write_acceleration(rotation, origin, linear, covariance3, rates, angular_acceleration,
                        attitude, gravity, z, covariance)
    return z, covariance


@_jit
def _write_orientation(attitude: FloatArray, turn: FloatArray, covariance3: FloatArray,
                       z: FloatArray, covariance: FloatArray) -> None:
    """inputs.imu_orientation's values into the orientation's entries of z and covariance:
    the attitude's roll, pitch and yaw, and T C T' (T the mount's yaw)."""
    z[state.ROLL], z[state.PITCH], z[state.YAW] = _rpy_from_rotation(attitude)
    _write_turned_covariance(turn, covariance3, covariance, state.ROLL)


@_jit
def orientation_values(attitude: FloatArray, turn: FloatArray, covariance3: FloatArray
                       ) -> tuple[FloatArray, FloatArray]:
    """inputs.imu_orientation's z and covariance (``_write_orientation``)."""
    z = np.zeros(N)
    covariance = np.zeros((N, N))
    _write_orientation(attitude, turn, covariance3, z, covariance)
    return z, covariance


@_jit
def _imu_attitude(quaternion: FloatArray, mount_rpy: FloatArray, turn: FloatArray
                  ) -> FloatArray:
    """inputs.imu_attitude: the reported attitude's angles less the mount's, the roll /
    pitch pair turned by the mount's yaw ``turn``."""
    angles = _rpy_from_rotation(_rotation_from_quaternion(
        quaternion[0], quaternion[1], quaternion[2], quaternion[3]))
    offsets = np.empty(3)
    for i in range(3):
        offsets[i] = _wrap(angles[i] - mount_rpy[i])
    turned = np.empty(3)
    for i in range(3):
        turned[i] = turn[i, 0] * offsets[0] + turn[i, 1] * offsets[1] + \
            turn[i, 2] * offsets[2]
    return _rotation_from_rpy(turned[0], turned[1], turned[2])


@_jit
def imu_values(quaternion: FloatArray, mount_rpy: FloatArray, turn: FloatArray,
               orientation_covariance: FloatArray, with_orientation: bool,
               rotation: FloatArray, origin: FloatArray, angular: FloatArray,
               angular_covariance: FloatArray, linear: FloatArray,
               linear_covariance: FloatArray, rates: FloatArray,
               angular_acceleration: FloatArray, gravity_attitude: FloatArray,
               gravity: float) -> tuple[FloatArray, FloatArray]:
    """An IMU reading's three parts at once, each in its own entries of one z and one
    covariance (their blocks do not overlap): the attitude as inputs.imu_orientation
    takes ``imu_attitude`` (skipped when ``with_orientation`` is False: the reading has
    none), the angular velocity as inputs.twist (no linear part), the linear
    acceleration as inputs.acceleration."""
    z = np.zeros(N)
    covariance = np.zeros((N, N))
    if with_orientation:
        _write_orientation(_imu_attitude(quaternion, mount_rpy, turn), turn,
                           orientation_covariance, z, covariance)
    twist6 = np.zeros((6, 6))
    twist6[3:, 3:] = angular_covariance
    _write_twist(rotation, origin, np.zeros(3), angular, twist6, rates, z, covariance)
    _write_acceleration(rotation, origin, linear, linear_covariance, rates,
                        angular_acceleration, gravity_attitude, gravity, z, covariance)
    return z, covariance


def warm_up() -> None:
    """Compile (or load from numba's cache) the kernels, with the argument types of the
    filter's calls."""
    x, p = np.zeros(N), np.eye(N)
    idx = np.arange(3, dtype=np.int64)
    weights = np.full(2 * N + 1, 1.0 / (2 * N + 1))
    weights.flags.writeable = False  # as UnscentedWeights hands them
    covariance_verdict(p, idx, 1e-9, 1e-9)
    ekf_predict(x, p, p, 0.01)
    ekf_correct(x, p, x, p, idx, 1e-9)
    _, _, _, points = ukf_predict(x, p, p, 0.01, 1.0, weights, weights)
    ukf_correct(x, p, points, x, p, idx, 1e-9, weights, weights)
    ukf_correct_drawn(x, p, x, p, idx, 1e-9, 1.0, weights, weights)
    three, rotation = np.zeros(3), np.eye(3)
    twist_values(rotation, three, three, three, np.eye(6), three)
    acceleration_values(rotation, three, three, rotation, three, three, rotation, 9.8)
    orientation_values(rotation, rotation, rotation)
    imu_values(np.array([0.0, 0.0, 0.0, 1.0]), three, rotation, rotation, True, rotation,
               three, three, rotation, three, rotation, three, three, rotation, 9.8)
