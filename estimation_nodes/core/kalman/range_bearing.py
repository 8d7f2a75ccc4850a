"""Range and bearing to a known landmark, seen by a sensor mounted on the robot.

The sensor sits at ``(sx, sy)`` on the robot, facing ``yaw`` from the robot's
heading; from the robot's pose (x, y, theta) it is at::

    px = x + sx cos(theta) - sy sin(theta)
    py = y + sx sin(theta) + sy cos(theta)

and a landmark at (lx, ly) is seen at range sqrt(dx^2 + dy^2) and bearing
atan2(dy, dx) - theta - yaw, with dx = lx - px, dy = ly - py.

A camera that finds a landmark's distance from its apparent size in the image may
report not that range but the landmark's depth: its distance along the camera's
axis, range cos(bearing) (``Ranging("depth")``; the UTIAS MRCLAM cameras do, see
bench/landmarks/utias_calibration.py). Either may carry a scale (an uncalibrated lens or
target size): the reported value is ``scale`` times the true one.

That scale may also be estimated with the pose, as a fourth state: x = (x, y, theta,
scale). A state of four entries is read so, and ``ranging.scale`` is then only its
prior's mean (landmarks.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimation_nodes.core.kalman.unicycle import wrap
from estimation_nodes.core.validation import FloatArray

#: A landmark closer than this to the sensor has no defined bearing.
MIN_RANGE = 1e-6


@dataclass(frozen=True)
class SensorPose:
    """Where the sensor is mounted: (x, y) on the robot in m, yaw from its heading in rad."""

    x: float
    y: float
    yaw: float

    def __post_init__(self) -> None:
        for name in ("x", "y", "yaw"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value)):
                raise ValueError(f"sensor_pose.{name}: expected a finite number, got {value!r}")


def mount_covariance(x: FloatArray, sensor: SensorPose,
                     std: tuple[float, float, float]) -> FloatArray:
    """The robot pose's covariance that a mount known to ``std`` (x, y, yaw) adds, given
    where the sensor is (first order): the sensor's pose is what the observations fix,
    the robot's reference point is sensor_pose from it. A mount error (dx, dy, dyaw)
    moves the pose by -R(theta) (dx, dy) + dR/dtheta (x, y) dyaw, and the heading by
    -dyaw."""
    c, s = math.cos(x[2]), math.sin(x[2])
    # J = [[-c, s, u], [-s, -c, v], [0, 0, -1]]; J diag(std^2) J' written out (it is
    # published after every event)
    u, v = -s * sensor.x - c * sensor.y, c * sensor.x - s * sensor.y
    along, across, turn = std[0] ** 2, std[1] ** 2, std[2] ** 2
    xy = c * s * (along - across) + u * v * turn
    return np.array([[c * c * along + s * s * across + u * u * turn, xy, -u * turn],
                     [xy, s * s * along + c * c * across + v * v * turn, -v * turn],
                     [-u * turn, -v * turn, turn]])


RANGE_KINDS = ("euclidean", "depth")


@dataclass(frozen=True)
class Ranging:
    """What the sensor's range measures: 'euclidean' (the distance to the landmark) or
    'depth' (the distance along the sensor's axis), times ``scale``."""

    kind: str = "euclidean"
    scale: float = 1.0

    def __post_init__(self) -> None:
        if self.kind not in RANGE_KINDS:
            raise ValueError(f"range_model: expected one of {RANGE_KINDS}, got {self.kind!r}")
        if not (isinstance(self.scale, (int, float)) and math.isfinite(self.scale)
                and self.scale > 0):
            raise ValueError(f"range_scale: expected a finite number > 0, got {self.scale!r}")


EUCLIDEAN = Ranging()


def _offsets(x: FloatArray, landmark: tuple[float, float],
             sensor: SensorPose) -> tuple[float, float, float, float]:
    """dx, dy from the sensor to the landmark, and d px / d theta, d py / d theta."""
    c, s = math.cos(x[2]), math.sin(x[2])
    dpx = -sensor.x * s - sensor.y * c
    dpy = sensor.x * c - sensor.y * s
    px = x[0] + sensor.x * c - sensor.y * s
    py = x[1] + sensor.x * s + sensor.y * c
    return landmark[0] - px, landmark[1] - py, dpx, dpy


def range_scale(x: FloatArray, ranging: Ranging) -> float:
    """The range's scale: the state's fourth entry where it has one, else the model's."""
    return float(x[3]) if len(x) > 3 else ranging.scale


def expected(x: FloatArray, landmark: tuple[float, float], sensor: SensorPose,
             ranging: Ranging = EUCLIDEAN) -> FloatArray:
    """(range, bearing) of ``landmark`` from pose ``x`` (and scale, see range_scale)."""
    dx, dy, _, _ = _offsets(x, landmark, sensor)
    axis = x[2] + sensor.yaw
    return np.array([range_scale(x, ranging) * _distance(dx, dy, axis, ranging),
                     wrap(math.atan2(dy, dx) - axis)])


def _distance(dx: float, dy: float, axis: float, ranging: Ranging) -> float:
    """What the range measures before its scale: the distance, or the depth on ``axis``."""
    if ranging.kind == "depth":
        return dx * math.cos(axis) + dy * math.sin(axis)
    return math.hypot(dx, dy)


def jacobian(x: FloatArray, landmark: tuple[float, float], sensor: SensorPose,
             ranging: Ranging = EUCLIDEAN) -> FloatArray:
    """d (range, bearing) / d (x, y, theta), 2 x 3 (2 x 4 with d / d scale for a state of
    four); ValueError where the landmark sits on the sensor (no bearing)."""
    dx, dy, dpx, dpy = _offsets(x, landmark, sensor)
    q = dx * dx + dy * dy
    r = math.sqrt(q)
    if r < MIN_RANGE:
        raise ValueError(f"landmark: at {r:.3g} m from the sensor, its bearing is undefined")
    if ranging.kind == "depth":
        # depth = dx cos(a) + dy sin(a), a = theta + yaw, and dx, dy move with theta too
        c, s = math.cos(x[2] + sensor.yaw), math.sin(x[2] + sensor.yaw)
        distance_row = [-c, -s, -dpx * c - dpy * s - dx * s + dy * c]
    else:
        distance_row = [-dx / r, -dy / r, -(dx * dpx + dy * dpy) / r]
    scale = range_scale(x, ranging)
    rows = [[scale * d for d in distance_row],
            [dy / q, -dx / q, (dy * dpx - dx * dpy) / q - 1.0]]
    if len(x) > 3:
        rows[0].append(_distance(dx, dy, x[2] + sensor.yaw, ranging))
        rows[1].append(0.0)
    return np.array(rows)


def residual(z: FloatArray, predicted: FloatArray) -> FloatArray:
    """z - predicted, the bearing's difference wrapped to [-pi, pi)."""
    return np.array([z[0] - predicted[0], wrap(z[1] - predicted[1])])
