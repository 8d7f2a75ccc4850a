"""Where one camera frame puts the robot: the pose from two landmarks or more seen at once.

A landmark filter that lost its robot (landmarks.py: every observation gated for
recovery_time) widens its covariance until the observations pass the gate again. From
metres of position and tens of degrees of heading, a range and bearing linearized at the
wrong pose can move the EKF far from the robot instead of towards it (robot 3 of UTIAS
dataset 7 stayed lost for 89 s that way). But a frame with two landmarks or more fixes the
pose by itself: the landmarks placed in the sensor's frame by their ranges and bearings,
and the same landmarks on the map, are one set of points seen from two frames; the rigid
motion between them (least squares, the 2-D Kabsch solution) is the sensor's pose on the
map, and the mount gives the robot's.

That fit weighs every point alike; a few Gauss-Newton steps then weigh each range
and bearing by its noise (R, with what the range's estimated scale still leaves
uncertain), and the frame's own information, (J' W J)^-1 at that pose, is the
covariance the filter restarts with: the frame is used once, for the placing. The pose
is taken only where every observation of the frame fits it: the sum of their squared
residuals, each over its own noise, within the gate's probability of chi-square with
2k - 3 degrees of freedom (2 per observation, less the pose's 3). A misidentified
landmark puts the frame's points at distances the map does not have, and seeds
nothing. The caller leaves out what cannot place (an unknown id, an id seen twice, a
range that is not a positive number, a depth too far off the axis: ``usable``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import cast
from statistics import NormalDist

import numpy as np

from estimation_nodes.core.kalman import range_bearing
from estimation_nodes.core.kalman.range_bearing import Ranging, SensorPose
from estimation_nodes.core.kalman.unicycle import wrap
from estimation_nodes.core.validation import FloatArray

#: A depth camera's landmark farther than this off its axis (rad) gives no place: the
#: distance depth / cos(bearing) grows without bound towards 90 degrees.
MAX_DEPTH_BEARING = math.radians(80)

#: Gauss-Newton steps from the unweighted fit to the weighted one (each a 3 x 3 solve;
#: from the fit's start they settle in two or three).
REFINE_STEPS = 5

#: A landmark seen in the frame: where it is on the map, and (range, bearing) measured.
Sighting = tuple[tuple[float, float], FloatArray]


def chi_square_quantile(dof: int, probability: float) -> float:
    """The chi-square quantile (Wilson and Hilferty's approximation, within a few percent
    for one degree of freedom and closer for more): a plausibility bound, not a test."""
    if probability >= 1.0:
        return math.inf
    z = NormalDist().inv_cdf(probability)
    spread = 2.0 / (9.0 * dof)
    return dof * (1.0 - spread + z * math.sqrt(spread)) ** 3


def sensor_point(z: FloatArray, ranging: Ranging, scale: float) -> tuple[float, float] | None:
    """The landmark's place in the sensor's frame from its (range, bearing) ``z``, the range
    taken as ``scale`` times the distance or the depth; None where it gives none."""
    measured, bearing = float(z[0]) / scale, float(z[1])
    if ranging.kind == "depth":
        if abs(bearing) > MAX_DEPTH_BEARING:
            return None
        return measured, measured * math.tan(bearing)
    return measured * math.cos(bearing), measured * math.sin(bearing)


def sensor_pose_on_map(seen: Sequence[tuple[tuple[float, float], tuple[float, float]]]
                       ) -> tuple[float, float, float]:
    """The rigid motion (x, y, rotation) taking the sensor-frame points onto the map's,
    least squares: the 2-D Kabsch solution over (map place, sensor place) pairs."""
    on_map = np.array([place for place, _ in seen], dtype=np.float64)
    in_sensor = np.array([point for _, point in seen], dtype=np.float64)
    map_mean, sensor_mean = on_map.mean(axis=0), in_sensor.mean(axis=0)
    a, b = in_sensor - sensor_mean, on_map - map_mean
    rotation = math.atan2(float(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])),
                          float(np.sum(a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1])))
    c, s = math.cos(rotation), math.sin(rotation)
    x = map_mean[0] - (c * sensor_mean[0] - s * sensor_mean[1])
    y = map_mean[1] - (s * sensor_mean[0] + c * sensor_mean[1])
    return x, y, rotation


def robot_pose(sensor_on_map: tuple[float, float, float], sensor: SensorPose) -> FloatArray:
    """The robot's pose whose sensor, at ``sensor``'s mount, is at ``sensor_on_map``."""
    sx, sy, rotation = sensor_on_map
    heading = wrap(rotation - sensor.yaw)
    c, s = math.cos(heading), math.sin(heading)
    return np.array([sx - (c * sensor.x - s * sensor.y), sy - (s * sensor.x + c * sensor.y),
                     heading])


def usable(z: FloatArray, ranging: Ranging) -> bool:
    """Whether a measured (range, bearing) can help place the robot."""
    return bool(np.isfinite(z).all() and z[0] > 0
                and (ranging.kind != "depth" or abs(z[1]) <= MAX_DEPTH_BEARING))


def place(sightings: Sequence[Sighting], sensor: SensorPose, ranging: Ranging,
          rest_of_state: FloatArray, rest_covariance: FloatArray,
          noise: Callable[[float], FloatArray],
          probability: float) -> tuple[FloatArray, FloatArray] | None:
    """The robot's pose and its covariance from one frame's ``sightings`` of distinct
    landmarks (each ``usable``), where they fit it (see the module's text); None where
    the frame cannot place the robot. ``rest_of_state`` and ``rest_covariance`` (the
    range's scale and its variance, where it is estimated) and ``noise`` (R of a
    measured range) are the filter's."""
    landmarks = [landmark for landmark, _ in sightings]
    if len(sightings) < 2 or len(set(landmarks)) < len(landmarks):
        return None
    scale = range_bearing.range_scale(np.append(np.zeros(3), rest_of_state), ranging)
    if not (math.isfinite(scale) and scale > 0):
        return None
    pairs = []
    for landmark, z in sightings:
        point = sensor_point(z, ranging, scale)
        if point is None:
            return None
        pairs.append((landmark, point))
    pose = robot_pose(sensor_pose_on_map(pairs), sensor)
    try:
        for _ in range(REFINE_STEPS):
            step, information, misfit = _weighted_step(pose, sightings, sensor, ranging,
                                                       rest_of_state, rest_covariance, noise)
            pose = pose + step
            pose[2] = wrap(pose[2])
        _, information, misfit = _weighted_step(pose, sightings, sensor, ranging,
                                                rest_of_state, rest_covariance, noise)
        covariance = np.linalg.inv(information)
    except (ValueError, np.linalg.LinAlgError):
        # an iterate on a landmark, or landmarks in one place (no heading from them)
        return None
    if not (misfit <= chi_square_quantile(2 * len(sightings) - 3, probability)
            and np.isfinite(pose).all() and np.isfinite(covariance).all()):
        return None
    return pose, 0.5 * (covariance + covariance.T)


def _weighted_step(pose: FloatArray, sightings: Sequence[Sighting], sensor: SensorPose,
                   ranging: Ranging, rest_of_state: FloatArray, rest_covariance: FloatArray,
                   noise: Callable[[float], FloatArray]) -> tuple[FloatArray, FloatArray, float]:
    """One Gauss-Newton step of the weighted fit at ``pose``; J' W J there; and the sum of
    the squared residuals over their noise (the scale's variance in the range's)."""
    state = np.append(pose, rest_of_state)
    information, gradient, misfit = np.zeros((3, 3)), np.zeros(3), 0.0
    for landmark, z in sightings:
        H = range_bearing.jacobian(state, landmark, sensor, ranging)
        J, rest = H[:, :3], H[:, 3:]
        W = np.linalg.inv(noise(float(z[0])) + rest @ rest_covariance @ rest.T)
        y = range_bearing.residual(z, range_bearing.expected(state, landmark, sensor, ranging))
        information += J.T @ W @ J
        gradient += J.T @ W @ y
        misfit += float(y @ W @ y)
    return cast(FloatArray, np.linalg.solve(information, gradient)), information, misfit
