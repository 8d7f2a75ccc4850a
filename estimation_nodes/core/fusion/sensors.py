"""robot_localization's inputs: each configured sensor's messages turned into measurements.

A message here is anything with the ROS field names (an rclpy message, or one the
``rosbags`` library decoded): the same code serves the node and the offline run. Per
input, as the peer: a message not newer than the last one of its part (pose, twist,
acceleration) is dropped and counted; an IMU part whose first covariance entry is -1
is absent; an odometry message feeds its twist part here (its pose part when its
``_config`` asks for one is not supported yet and is refused when configured).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from estimation_nodes.core.fusion import inputs
from estimation_nodes.core.fusion.filter import FusionFilter
from estimation_nodes.core.fusion.inputs import Mount
from estimation_nodes.core.fusion.state import POSE, ROLL, VROLL, rotation_from_quaternion, \
    rotation_from_rpy
from estimation_nodes.core.fusion.steps import Measurement


@dataclass(frozen=True)
class SensorConfig:
    """One ``odomN`` / ``twistN`` / ``imuN`` input, by the peer's parameter names."""

    name: str
    kind: str
    topic: str
    update: tuple[bool, ...]
    pose_threshold: float = math.inf
    twist_threshold: float = math.inf
    acceleration_threshold: float = math.inf
    remove_gravity: bool = False
    relative: bool = False
    queue_size: int = 10


def stamp_ns(header) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


@dataclass
class SensorInputs:
    """Turns messages into queued measurements; counts what it drops and why."""

    sensors: dict[str, SensorConfig]
    #: Mounts by frame id (the sensor frame's pose in ``base_link_frame``).
    mounts: dict[str, Mount] = field(default_factory=dict)
    base_frame: str = "base_link"
    gravity: float = inputs.GRAVITY
    #: ``two_d_mode``: every measurement also holds z, roll, pitch and their rates at 0.
    two_d: bool = False
    dropped: dict[str, int] = field(default_factory=dict)
    _last: dict[str, int] = field(default_factory=dict)

    def _drop(self, reason: str) -> None:
        self.dropped[reason] = self.dropped.get(reason, 0) + 1

    def mount(self, frame_id: str) -> Mount | None:
        if frame_id in ("", self.base_frame):
            return inputs.IDENTITY
        return self.mounts.get(frame_id)

    def _newer(self, part: str, stamp: int) -> bool:
        if stamp < self._last.get(part, stamp):
            self._drop(f"{part}: older than the last one")
            return False
        self._last[part] = stamp
        return True

    def add(self, sensor: SensorConfig, msg, fusion: FusionFilter) -> int:
        """Queue the measurements of one message into ``fusion``; how many it queued."""
        if sensor.kind == "imu":
            made = self._imu(sensor, msg, fusion)
        else:
            made = self._odometry(sensor, msg, fusion)
        if self.two_d:
            made = [inputs.force_two_d(measurement) for measurement in made]
        for measurement in made:
            fusion.enqueue(measurement)
        return len(made)

    def _odometry(self, sensor: SensorConfig, msg, fusion: FusionFilter) -> list[Measurement]:
        stamp = stamp_ns(msg.header)
        frame = msg.child_frame_id if sensor.kind == "odom" else msg.header.frame_id
        mount = self.mount(frame)
        if mount is None:
            self._drop(f"{sensor.name}: no transform from {frame!r} to {self.base_frame!r}")
            return []
        part = f"{sensor.name}_twist"
        if not self._newer(part, stamp):
            return []
        t = msg.twist.twist
        covariance = np.asarray(msg.twist.covariance, dtype=float).reshape(6, 6)
        made = inputs.twist(
            stamp, _vector(t.linear), _vector(t.angular), covariance, sensor.update,
            fusion.x[VROLL:VROLL + 3], mount, sensor.twist_threshold, part)
        return [made] if made else []

    def _imu(self, sensor: SensorConfig, msg, fusion: FusionFilter) -> list[Measurement]:
        stamp = stamp_ns(msg.header)
        mount = self.mount(msg.header.frame_id)
        if mount is None:
            self._drop(f"{sensor.name}: no transform from {msg.header.frame_id!r} "
                       f"to {self.base_frame!r}")
            return []
        made: list[Measurement | None] = []
        has_orientation = abs(msg.orientation_covariance[0] + 1.0) >= 1e-9
        q = msg.orientation
        quaternion = (q.x, q.y, q.z, q.w)
        if any(sensor.update[POSE.start + 3:POSE.stop]) and has_orientation \
                and self._newer(f"{sensor.name}_pose", stamp):
            made.append(inputs.imu_orientation(
                stamp, quaternion, _matrix3(msg.orientation_covariance), sensor.update,
                mount, sensor.pose_threshold, f"{sensor.name}_pose"))
        if any(sensor.update[VROLL:VROLL + 3]) \
                and abs(msg.angular_velocity_covariance[0] + 1.0) >= 1e-9 \
                and self._newer(f"{sensor.name}_twist", stamp):
            covariance = np.zeros((6, 6))
            covariance[3:, 3:] = _matrix3(msg.angular_velocity_covariance)
            made.append(inputs.twist(
                stamp, np.zeros(3), _vector(msg.angular_velocity), covariance,
                _rates_only(sensor.update), fusion.x[VROLL:VROLL + 3], mount,
                sensor.twist_threshold, f"{sensor.name}_twist"))
        if any(sensor.update[12:15]) \
                and abs(msg.linear_acceleration_covariance[0] + 1.0) >= 1e-9 \
                and self._newer(f"{sensor.name}_acceleration", stamp):
            made.append(inputs.acceleration(
                stamp, _vector(msg.linear_acceleration),
                _matrix3(msg.linear_acceleration_covariance), sensor.update,
                fusion.x[VROLL:VROLL + 3], fusion.angular_acceleration,
                self._attitude(sensor, has_orientation, quaternion, mount, fusion),
                sensor.remove_gravity, self.gravity, mount, sensor.acceleration_threshold,
                f"{sensor.name}_acceleration"))
        return [m for m in made if m is not None]

    @staticmethod
    def _attitude(sensor: SensorConfig, has_orientation: bool, quaternion, mount: Mount,
                  fusion: FusionFilter):
        if not has_orientation:
            return rotation_from_rpy(*fusion.x[ROLL:ROLL + 3]) @ mount.rotation
        reported = rotation_from_quaternion(*quaternion)
        return reported @ mount.rotation if sensor.relative else reported


def _vector(v) -> np.ndarray:
    return np.array([v.x, v.y, v.z], dtype=float)


def _matrix3(values) -> np.ndarray:
    return np.asarray(values, dtype=float).reshape(3, 3)


def _rates_only(update: tuple[bool, ...]) -> tuple[bool, ...]:
    """An IMU's twist part: its angular rates (it has no linear velocity)."""
    return tuple(flag and VROLL <= i < VROLL + 3 for i, flag in enumerate(update))
