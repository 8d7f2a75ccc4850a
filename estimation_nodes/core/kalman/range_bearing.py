"""Range and bearing to a known landmark, seen by a sensor mounted on the robot.

The sensor sits at ``(sx, sy)`` on the robot, facing ``yaw`` from the robot's
heading; from the robot's pose (x, y, theta) it is at::

    px = x + sx cos(theta) - sy sin(theta)
    py = y + sx sin(theta) + sy cos(theta)

and a landmark at (lx, ly) is seen at range sqrt(dx^2 + dy^2) and bearing
atan2(dy, dx) - theta - yaw, with dx = lx - px, dy = ly - py.
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


def _offsets(x: FloatArray, landmark: tuple[float, float],
             sensor: SensorPose) -> tuple[float, float, float, float]:
    """dx, dy from the sensor to the landmark, and d px / d theta, d py / d theta."""
    c, s = math.cos(x[2]), math.sin(x[2])
    dpx = -sensor.x * s - sensor.y * c
    dpy = sensor.x * c - sensor.y * s
    px = x[0] + sensor.x * c - sensor.y * s
    py = x[1] + sensor.x * s + sensor.y * c
    return landmark[0] - px, landmark[1] - py, dpx, dpy


def expected(x: FloatArray, landmark: tuple[float, float], sensor: SensorPose) -> FloatArray:
    """(range, bearing) of ``landmark`` from pose ``x``."""
    dx, dy, _, _ = _offsets(x, landmark, sensor)
    return np.array([math.hypot(dx, dy), wrap(math.atan2(dy, dx) - x[2] - sensor.yaw)])


def jacobian(x: FloatArray, landmark: tuple[float, float], sensor: SensorPose) -> FloatArray:
    """d (range, bearing) / d (x, y, theta), 2 x 3; ValueError where the landmark sits on
    the sensor (no bearing)."""
    dx, dy, dpx, dpy = _offsets(x, landmark, sensor)
    q = dx * dx + dy * dy
    r = math.sqrt(q)
    if r < MIN_RANGE:
        raise ValueError(f"landmark: at {r:.3g} m from the sensor, its bearing is undefined")
    return np.array([
        [-dx / r, -dy / r, -(dx * dpx + dy * dpy) / r],
        [dy / q, -dx / q, (dy * dpx - dx * dpy) / q - 1.0],
    ])


def residual(z: FloatArray, predicted: FloatArray) -> FloatArray:
    """z - predicted, the bearing's difference wrapped to [-pi, pi)."""
    return np.array([z[0] - predicted[0], wrap(z[1] - predicted[1])])
