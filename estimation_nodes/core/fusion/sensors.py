"""robot_localization's inputs: each configured sensor's messages turned into measurements.

A message here is anything with the ROS field names (an rclpy message, or one the
``rosbags`` library decoded): the same code serves the node and the offline run. Per
input, as the peer: a message not newer than the last one of its part (pose, twist,
acceleration) is dropped and counted; an IMU part whose first covariance entry is -1
is absent; a measurement whose covariance cannot be one (``steps.covariance_problem``)
is dropped and counted. An odometry message feeds its pose part (the pose entries of its
``_config``) and its twist part; a ``poseN`` message its pose part.

A pose part is placed in the world frame by its message's frame: the world frame itself,
or a frame whose ``Mount`` in the world is known; else it is dropped and counted. With
``_relative`` a pose is taken relative to the input's first one (the peer's
initial^-1 pose, before the frame); with ``_differential`` two consecutive poses are a
velocity (``inputs.pose_change``), the first one only remembered, and no frame is needed
(the change between two poses in one frame is the same in any). A pose with a
non-finite number is dropped and counted, so it is never remembered.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field

import numpy as np

from estimation_nodes.core.fusion import inputs
from estimation_nodes.core.fusion.filter import FusionFilter
from estimation_nodes.core.fusion.inputs import Mount
from estimation_nodes.core.fusion.state import ACCELERATION, ORIENTATION, POSE, ROLL, TWIST, \
    VROLL, rotation_from_quaternion, rotation_from_rpy
from estimation_nodes.core.fusion.steps import Measurement, covariance_problem
from estimation_nodes.core.validation import FloatArray


@dataclass(frozen=True)
class SensorConfig:
    """One ``odomN`` / ``poseN`` / ``twistN`` / ``imuN`` input, by the peer's parameter
    names."""

    name: str
    kind: str
    topic: str
    update: tuple[bool, ...]
    pose_threshold: float = math.inf
    twist_threshold: float = math.inf
    acceleration_threshold: float = math.inf
    remove_gravity: bool = False
    relative: bool = False
    differential: bool = False
    queue_size: int = 10
    #: An IMU whose gyro bias the filter estimates: the state entry of its roll rate's
    #: bias (pitch's and yaw's follow), None when not (beyond the peer).
    gyro_bias: int | None = None

    # What follows from the configuration alone is worked out once (a frozen dataclass
    # keeps a cached_property in its __dict__): every message asks it.

    @functools.cached_property
    def pose_part(self) -> str:
        """The name the peer gives the pose part's measurements."""
        return f"{self.name}_pose" if self.kind == "odom" else self.name

    @functools.cached_property
    def measures_pose(self) -> bool:
        return self.kind in ("odom", "pose") and any(self.update[POSE])

    @functools.cached_property
    def measures_twist(self) -> bool:
        return self.kind in ("odom", "twist") and any(self.update[TWIST])

    @functools.cached_property
    def imu_parts(self) -> tuple[bool, bool, bool]:
        """Whether an IMU's attitude, angular rates and linear acceleration are asked for."""
        return (any(self.update[ORIENTATION]), any(self.update[VROLL:VROLL + 3]),
                any(self.update[ACCELERATION]))

    @functools.cached_property
    def rate_entries(self) -> tuple[bool, ...]:
        """The update mask of an IMU's rates part: an IMU has no linear velocity."""
        return _entries(self.update, VROLL, VROLL + 3)


def gyro_biases(sensors: dict[str, SensorConfig], x: FloatArray) -> dict[str, FloatArray]:
    """Each IMU's estimated gyro bias (roll, pitch, yaw rates, rad/s, in the robot's
    frame) in the state ``x``, by input name."""
    return {name: x[sensor.gyro_bias:sensor.gyro_bias + 3]
            for name, sensor in sensors.items() if sensor.gyro_bias is not None}


#: The name ``set_pose`` goes by in the counts.
SET_POSE = "set_pose"


def stamp_ns(header) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


@dataclass
class SensorInputs:
    """Turns messages into queued measurements; counts what it drops and why."""

    sensors: dict[str, SensorConfig]
    #: Mounts by frame id: a sensor frame's pose in ``base_frame``, a pose input's frame's
    #: pose in ``world_frame`` (a frame is fixed either to the robot or to the world).
    mounts: dict[str, Mount] = field(default_factory=dict)
    base_frame: str = "base_link"
    gravity: float = inputs.GRAVITY
    #: ``two_d_mode``: every measurement also holds z, roll, pitch and their rates at 0.
    two_d: bool = False
    world_frame: str = "odom"
    #: How many were dropped, by "<input part>: <reason>"; the latest reason.
    dropped: dict[str, int] = field(default_factory=dict)
    last_dropped: str = ""
    _last: dict[str, int] = field(default_factory=dict)
    #: ``_relative``: each pose part's first pose.
    _initial: dict[str, Mount] = field(default_factory=dict)
    #: ``_differential``: each pose part's last pose, its time and covariance.
    _previous: dict[str, tuple[int, Mount, FloatArray]] = field(default_factory=dict)
    #: The stamp of the last ``set_pose``: what is not later is dropped.
    _set_pose_ns: int | None = None

    def drop(self, reason: str) -> None:
        """Count a message (or a part of one) dropped, by "<input part>: <reason>"."""
        self.dropped[reason] = self.dropped.get(reason, 0) + 1
        self.last_dropped = reason

    def mount(self, frame_id: str) -> Mount | None:
        if frame_id in ("", self.base_frame):
            return inputs.IDENTITY
        return self.mounts.get(frame_id)

    def placement(self, frame_id: str) -> Mount | None:
        """A pose input's frame in the world frame, None when unknown."""
        if frame_id == self.world_frame:
            return inputs.IDENTITY
        return self.mounts.get(frame_id)

    def frames(self, sensor: SensorConfig, msg) -> list[tuple[str, str]]:
        """The (parent, child) transforms a message of ``sensor`` needs: its sensor frame on
        the robot, its pose frame in the world (none for a differential pose)."""
        needed = []
        if sensor.measures_pose and not sensor.differential:
            needed.append((self.world_frame, msg.header.frame_id))
        if sensor.kind == "odom" and sensor.measures_twist:
            needed.append((self.base_frame, msg.child_frame_id))
        elif sensor.kind in ("twist", "imu"):
            needed.append((self.base_frame, msg.header.frame_id))
        return needed

    def _finite(self, part: str, covariance) -> bool:
        """Whether the covariance a part reads is all finite; dropped and counted if not (a
        rotation would spread a NaN to every entry, an inf would become NaNs)."""
        # Over a list of Python floats: numpy's isfinite().all() costs more on nine to 36.
        if all(map(math.isfinite, np.asarray(covariance, dtype=float).ravel().tolist())):
            return True
        self.drop(f"{part}: a non-finite covariance")
        return False

    def _newer(self, part: str, stamp: int) -> bool:
        if stamp < self._last.get(part, stamp):
            self.drop(f"{part}: older than the last one")
            return False
        self._last[part] = stamp
        return True

    def add(self, sensor: SensorConfig, msg, fusion: FusionFilter) -> int:
        """Queue the measurements of one message into ``fusion``; how many it queued."""
        if self._set_pose_ns is not None and stamp_ns(msg.header) <= self._set_pose_ns:
            self.drop(f"{sensor.name}: not after the last set_pose")
            return 0
        made = []
        if sensor.kind == "imu":
            made = self._imu(sensor, msg, fusion)
        if sensor.measures_pose:
            made += self._pose(sensor, msg)
        if sensor.measures_twist:
            made += self._twist(sensor, msg, fusion)
        if self.two_d:
            made = [inputs.force_two_d(measurement) for measurement in made]
        usable = [measurement for measurement in made if self._usable(measurement)]
        for measurement in usable:
            fusion.enqueue(measurement)
        return len(usable)

    def _usable(self, measurement: Measurement) -> bool:
        problem = covariance_problem(measurement)
        if problem:
            self.drop(f"{measurement.source}: {problem}")
        return problem is None

    def set_pose(self, msg, fusion: FusionFilter, now_ns: int) -> bool:
        """The peer's ``set_pose`` (a PoseWithCovarianceStamped): the filter takes the pose,
        placed in the world, as its state (``FusionFilter.set_pose``); the inputs forget
        their first and previous poses, and drop what is stamped at or before it. False
        when the pose cannot be used (dropped and counted as any input)."""
        read = self._read_pose(SET_POSE, msg)
        frame = self._place(SET_POSE, msg.header.frame_id) if read else None
        if read is None or frame is None:
            return False
        body, covariance = read
        measurement = inputs.pose(stamp_ns(msg.header), body, covariance, (True,) * 6 +
                                  (False,) * 9, frame, source=SET_POSE)
        if measurement is not None and self.two_d:
            measurement = inputs.force_two_d(measurement)
        if measurement is None or not self._usable(measurement):
            return False
        fusion.set_pose(measurement, now_ns)
        self._initial.clear()
        self._previous.clear()
        self._set_pose_ns = measurement.stamp_ns
        return True

    def _pose(self, sensor: SensorConfig, msg) -> list[Measurement]:
        part = sensor.pose_part
        if not self._newer(part, stamp_ns(msg.header)):
            return []
        read = self._read_pose(part, msg)
        if read is None:
            return []
        body, covariance = read
        if sensor.differential:
            made = self._pose_change(sensor, part, stamp_ns(msg.header), body, covariance)
        else:
            frame = self._place(part, msg.header.frame_id)
            if frame is None:
                return []
            if sensor.relative:
                body = self._initial.setdefault(part, body).inverse() * body
            made = inputs.pose(stamp_ns(msg.header), body, covariance, sensor.update, frame,
                               sensor.pose_threshold, part)
        return [made] if made else []

    def _read_pose(self, part: str, msg) -> tuple[Mount, FloatArray] | None:
        """The pose of a message with a pose (the robot's frame in the message's) and its
        covariance; None, dropped and counted, when a number is not finite."""
        p = msg.pose.pose
        position = _vector(p.position)
        quaternion = (p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w)
        if not (np.all(np.isfinite(position)) and all(map(math.isfinite, quaternion))):
            self.drop(f"{part}: a non-finite value")
            return None
        if not self._finite(part, msg.pose.covariance):
            return None
        if not any(quaternion):
            # The peer's reading of an unset orientation: no rotation.
            quaternion = (0.0, 0.0, 0.0, 1.0)
        return (Mount(rotation_from_quaternion(*quaternion), position),
                _matrix(msg.pose.covariance, 6))

    def _place(self, part: str, frame_id: str) -> Mount | None:
        frame = self.placement(frame_id)
        if frame is None:
            self.drop(f"{part}: no transform from {frame_id!r} to {self.world_frame!r}")
        return frame

    def _pose_change(self, sensor: SensorConfig, part: str, stamp: int, body: Mount,
                     covariance: FloatArray, turn: Mount | None = None
                     ) -> Measurement | None:
        previous = self._previous.get(part)
        self._previous[part] = (stamp, body, covariance)
        if previous is None:
            return None
        previous_stamp, previous_body, previous_covariance = previous
        if stamp == previous_stamp:
            self.drop(f"{part}: at the time of the one before, no velocity to take")
            return None
        measured = POSE if turn is None else ORIENTATION
        return inputs.pose_change(stamp, previous_body, body, (stamp - previous_stamp) * 1e-9,
                                  covariance + previous_covariance,
                                  _entries(sensor.update, measured.start, measured.stop),
                                  sensor.pose_threshold, part, turn)

    def _twist(self, sensor: SensorConfig, msg, fusion: FusionFilter) -> list[Measurement]:
        stamp = stamp_ns(msg.header)
        frame = msg.child_frame_id if sensor.kind == "odom" else msg.header.frame_id
        mount = self.mount(frame)
        if mount is None:
            self.drop(f"{sensor.name}: no transform from {frame!r} to {self.base_frame!r}")
            return []
        part = f"{sensor.name}_twist"
        if not (self._newer(part, stamp) and self._finite(part, msg.twist.covariance)):
            return []
        t = msg.twist.twist
        covariance = _matrix(msg.twist.covariance, 6)
        made = inputs.twist(
            stamp, _vector(t.linear), _vector(t.angular), covariance, sensor.update,
            fusion.x[VROLL:VROLL + 3], mount, sensor.twist_threshold, part)
        return [made] if made else []

    def _imu(self, sensor: SensorConfig, msg, fusion: FusionFilter) -> list[Measurement]:
        """The parts of an IMU reading its ``_config`` asks for, made at once
        (``inputs.imu_values``); an attitude taken ``_relative`` or ``_differential`` the
        pose inputs' way (``_imu_attitude``)."""
        stamp = stamp_ns(msg.header)
        mount = self.mount(msg.header.frame_id)
        if mount is None:
            self.drop(f"{sensor.name}: no transform from {msg.header.frame_id!r} "
                      f"to {self.base_frame!r}")
            return []
        names = _imu_parts(sensor.name)
        update = sensor.update
        asks_attitude, asks_rates, asks_acceleration = sensor.imu_parts
        has_orientation = _present(msg.orientation_covariance)
        q = msg.orientation
        quaternion = (q.x, q.y, q.z, q.w)
        attitude = asks_attitude and has_orientation \
            and self._newer(names.pose, stamp) \
            and self._finite(names.pose, msg.orientation_covariance)
        rates = asks_rates and _present(msg.angular_velocity_covariance) \
            and self._newer(names.twist, stamp) \
            and self._finite(names.twist, msg.angular_velocity_covariance)
        acceleration = asks_acceleration and _present(msg.linear_acceleration_covariance) \
            and self._newer(names.acceleration, stamp) \
            and self._finite(names.acceleration, msg.linear_acceleration_covariance)
        if not (attitude or rates or acceleration):
            return []
        plain_attitude = attitude and not (sensor.relative or sensor.differential)
        z, covariance = inputs.imu_values(
            quaternion if plain_attitude else None, _matrix3(msg.orientation_covariance),
            _vector(msg.angular_velocity), _matrix3(msg.angular_velocity_covariance),
            _vector(msg.linear_acceleration), _matrix3(msg.linear_acceleration_covariance),
            fusion.x[VROLL:VROLL + 3], fusion.angular_acceleration,
            self._attitude(sensor, has_orientation, quaternion, mount, fusion)
            if acceleration and sensor.remove_gravity else None, self.gravity, mount)
        made: list[Measurement | None] = []
        if plain_attitude:
            made.append(inputs.imu_measurement(stamp, z, covariance, update, ORIENTATION,
                                               mount.yaw_turn, sensor.pose_threshold,
                                               names.pose))
        elif attitude:
            made.append(self._imu_attitude(sensor, stamp, quaternion,
                                           _matrix3(msg.orientation_covariance), mount))
        if rates:
            made.append(_with_gyro_bias(sensor, inputs.imu_measurement(
                stamp, z, covariance, sensor.rate_entries, TWIST, mount,
                sensor.twist_threshold, names.twist)))
        if acceleration:
            made.append(inputs.imu_measurement(stamp, z, covariance, update, ACCELERATION,
                                               mount, sensor.acceleration_threshold,
                                               names.acceleration))
        return [m for m in made if m is not None]

    def _imu_attitude(self, sensor: SensorConfig, stamp: int, quaternion, covariance3: FloatArray,
                      mount: Mount) -> Measurement | None:
        """An IMU's attitude part, taken as the peer takes an IMU's orientation, as a pose:
        as it is, relative to the first one (``_relative``), or the rates between two
        (``_differential``)."""
        part = f"{sensor.name}_pose"
        attitude = Mount(inputs.imu_attitude(quaternion, mount))
        if sensor.differential:
            covariance = np.zeros((6, 6))
            covariance[3:, 3:] = covariance3
            return self._pose_change(sensor, part, stamp, attitude, covariance,
                                     mount.yaw_turn)
        if sensor.relative:
            attitude = self._initial.setdefault(part, attitude).inverse() * attitude
        return inputs.imu_orientation(stamp, attitude.rotation, covariance3, sensor.update,
                                      mount, sensor.pose_threshold, part)

    @staticmethod
    def _attitude(sensor: SensorConfig, has_orientation: bool, quaternion, mount: Mount,
                  fusion: FusionFilter):
        if not has_orientation:
            return rotation_from_rpy(*fusion.x[ROLL:ROLL + 3]) @ mount.rotation
        reported = rotation_from_quaternion(*quaternion)
        return reported @ mount.rotation if sensor.relative else reported


def _with_gyro_bias(sensor: SensorConfig, measurement: Measurement | None
                    ) -> Measurement | None:
    """An IMU's rates, read as the rates plus its gyro's bias when the filter estimates
    that (the bias in the robot's frame: the mount turns a bias as it turns the rates)."""
    if measurement is None or sensor.gyro_bias is None:
        return measurement
    biased = tuple((index, sensor.gyro_bias + index - VROLL) for index in measurement.indices
                   if VROLL <= index < VROLL + 3)
    return dataclasses.replace(measurement, biased=biased)


def _present(covariance) -> bool:
    """Whether an IMU message has the part of this covariance (-1 first: it has not)."""
    return abs(float(covariance[0]) + 1.0) >= 1e-9


def _vector(v) -> np.ndarray:
    return np.array([v.x, v.y, v.z], dtype=float)


def _matrix3(values) -> np.ndarray:
    return _matrix(values, 3)


def _matrix(values, size: int) -> np.ndarray:
    """A message's covariance as an array of its own: a bag reader's arrays are views of
    the read-only file buffer, and numba compiles a kernel anew for read-only arguments
    (a second version of each, at the first reading, that warm_up does not make)."""
    return np.array(values, dtype=float).reshape(size, size)


@dataclass(frozen=True)
class _ImuParts:
    """The names an IMU input's parts go by in the counts (the peer's)."""

    pose: str
    twist: str
    acceleration: str


@functools.cache
def _imu_parts(name: str) -> _ImuParts:
    return _ImuParts(f"{name}_pose", f"{name}_twist", f"{name}_acceleration")


@functools.cache
def _entries(update: tuple[bool, ...], start: int, stop: int) -> tuple[bool, ...]:
    """The update mask with only the entries start..stop-1 left: an IMU has no position and
    no linear velocity."""
    return tuple(flag and start <= i < stop for i, flag in enumerate(update))
