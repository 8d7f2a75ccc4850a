"""Sensor readings turned into measurements of the state, as robot_localization prepares them.

Each function takes a reading in its sensor's frame, the sensor's mount (the rotation
and origin of the sensor frame in the robot's frame, ``Mount``), and the update mask from
the ``*_config`` parameter, and returns a ``Measurement`` (or None when nothing is left
to measure). The mask goes through the same rotation as the data: a measured axis
that the mount turns into another one measures that one.
- ``pose``: a pose given in some frame, placed in the world frame by that frame's
  ``Mount`` in the world (the peer's tf lookup from the message's frame to world_frame).
- ``pose_change``: two consecutive poses as the velocity that moves one to the other
  (``_differential``), with the peer's covariance (R_previous + R_current) dt.
- ``twist``: linear and angular velocity; v_base = R v + o x omega_state.
- ``imu_attitude``, ``imu_orientation``: an IMU reports its attitude in the world frame,
  so only the mount's angles are taken off (roll, pitch and yaw minus the mount's, the
  roll/pitch pair turned by the mount's yaw), not a frame change.
- ``acceleration``: gravity (0, 0, g) seen in the sensor's frame (through the sensor's
  world attitude) taken off when asked, then a_base = R a + o x alpha - (o x omega) x
  omega. (The peer's ROS 2 branch takes gravity off after the rotation into the
  robot's frame, with the sensor's attitude: for a sensor mounted turned, as the Husky's,
  that mixes frames; its bag tests' expected poses agree with the order here.)
- ``force_two_d``: ``two_d_mode``'s constraint added to any of them.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from estimation_nodes.core.fusion.state import (
    ACCELERATION, AZ, ORIENTATION, PITCH, POSE, ROLL, STATE_SIZE, TWIST, VPITCH, VROLL,
    VX, VZ, X, Z, rotation_from_quaternion, rotation_from_rpy, rpy_from_rotation, wrap)
from estimation_nodes.core.fusion import steps
from estimation_nodes.core.fusion.steps import Measurement, c_doubles
from estimation_nodes.core.validation import FloatArray

#: Standard gravity (m/s^2), robot_localization's default ``gravitational_acceleration``.
GRAVITY = 9.80665
#: What ``two_d_mode`` holds at zero: z, roll, pitch, their rates and the vertical acceleration.
PLANAR_ZEROS = (Z, ROLL, PITCH, VZ, VROLL, VPITCH, AZ)
#: The variance the peer gives those zeros.
PLANAR_VARIANCE = 1e-6
#: PLANAR_ZEROS as an index array, made once (a two_d_mode filter uses it per reading).
_PLANAR_INDEX = np.array(PLANAR_ZEROS)


@dataclass(frozen=True)
class Mount:
    """Where a frame sits in another: its rotation and origin there. A sensor's frame on the
    robot, a pose input's frame in the world, or a pose itself (the body's frame).

    What follows from the rotation alone (its angles, its yaw, the 6 x 6 block rotation, the
    masks it turns) is computed once per mount and kept: a sensor's mount serves every
    message, so its arrays are never changed in place."""

    rotation: FloatArray = field(default_factory=lambda: np.eye(3))
    origin: FloatArray = field(default_factory=lambda: np.zeros(3))

    @functools.cached_property
    def rpy(self) -> tuple[float, float, float]:
        """The rotation's roll, pitch and yaw (tf2's getRPY)."""
        return rpy_from_rotation(self.rotation)

    @functools.cached_property
    def yaw_turn(self) -> "Mount":
        """The rotation's yaw alone, at no origin."""
        return Mount(rotation_from_rpy(0.0, 0.0, self.rpy[2]))

    @functools.cached_property
    def rows(self) -> tuple[tuple[float, ...], ...]:
        """The rotation's rows as Python floats."""
        return tuple(tuple(row) for row in self.rotation.tolist())

    @functools.cached_property
    def six(self) -> FloatArray:
        """The rotation on both halves of a 6-vector (a pose or a twist)."""
        six = np.zeros((6, 6))
        six[:3, :3] = six[3:, 3:] = self.rotation
        return six

    def masked(self, mask: tuple[bool, ...]) -> list[bool]:
        """Which axes a mask of three, turned by the rotation, touches (the peer's row-length
        test): row i of R diag(mask) has the length sqrt(sum_j R_ij^2 mask_j)."""
        known = self.__dict__.setdefault("_masks", {})
        if mask not in known:
            lengths = np.sqrt((self.rotation * self.rotation) @ np.asarray(mask, dtype=float))
            known[mask] = [bool(length >= 1e-6) for length in lengths]
        return list(known[mask])

    def measured(self, update: tuple[bool, ...], part: slice) -> tuple[int, ...]:
        """The state entries of ``part`` (a pose or a twist, two blocks of three, or one
        block) that ``update`` measures once the rotation has turned each block: the
        same for every message of a sensor, so made once per mask and part."""
        known = self.__dict__.setdefault("_measured", {})
        key = (update, part.start, part.stop)
        if key not in known:
            mask = list(update)
            for start in range(part.start, part.stop, 3):
                mask[start:start + 3] = self.masked(tuple(update[start:start + 3]))
            known[key] = tuple(i for i in range(part.start, part.stop) if mask[i])
        return known[key]

    @classmethod
    def from_rpy(cls, xyz: tuple[float, float, float], rpy: tuple[float, float, float]
                 ) -> "Mount":
        return cls(rotation_from_rpy(*rpy), np.asarray(xyz, dtype=float))

    def __mul__(self, other: "Mount") -> "Mount":
        """``other``, given in this frame, in this frame's parent (tf2's composition)."""
        return Mount(self.rotation @ other.rotation, self.rotation @ other.origin + self.origin)

    def inverse(self) -> "Mount":
        return Mount(self.rotation.T, -self.rotation.T @ self.origin)


IDENTITY = Mount()


def _measurement(stamp_ns: int, z: FloatArray, covariance: FloatArray,
                 candidates: tuple[int, ...], threshold: float, source: str
                 ) -> Measurement | None:
    """The measurement of the ``candidates`` entries whose value is finite (a sensor's NaN
    leaves its entry unmeasured), None when none is."""
    values = z.tolist()
    indices = tuple(i for i in candidates if math.isfinite(values[i]))
    if not indices:
        return None
    return Measurement(stamp_ns, z, covariance, indices, threshold, source)


def _cross(a: FloatArray, b: FloatArray) -> FloatArray:
    """a x b for 3-vectors (numpy's cross costs more than the rest of a reading; so do
    numpy's scalars: the products are of Python floats)."""
    a0, a1, a2 = a.tolist()
    b0, b1, b2 = b.tolist()
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


def _twist_numpy(linear: FloatArray, angular: FloatArray, covariance6: FloatArray,
                 state_rates: FloatArray, mount: Mount) -> tuple[FloatArray, FloatArray]:
    r = mount.rotation
    z = np.zeros(STATE_SIZE)
    z[VX:VX + 3] = r @ linear + _cross(mount.origin, state_rates)
    z[VROLL:VROLL + 3] = r @ angular
    covariance = np.zeros((STATE_SIZE, STATE_SIZE))
    rot6 = mount.six
    covariance[TWIST, TWIST] = rot6 @ covariance6 @ rot6.T
    return z, covariance


def twist(stamp_ns: int, linear: FloatArray, angular: FloatArray, covariance6: FloatArray,
          update: tuple[bool, ...], state_rates: FloatArray, mount: Mount = IDENTITY,
          threshold: float = math.inf, source: str = "", compiled: bool = True
          ) -> Measurement | None:
    """A twist (linear and angular velocity in the sensor's frame) as a measurement."""
    r = mount.rotation
    kernels = steps.kernels(compiled)
    if kernels is not None:
        z, covariance = kernels.twist_values(*map(c_doubles, (
            r, mount.origin, linear, angular, covariance6, state_rates)))
    else:
        z, covariance = _twist_numpy(linear, angular, covariance6, state_rates, mount)
    return _measurement(stamp_ns, z, covariance, mount.measured(update, TWIST), threshold,
                        source)


def pose(stamp_ns: int, body: Mount, covariance6: FloatArray, update: tuple[bool, ...],
         frame: Mount = IDENTITY, threshold: float = math.inf, source: str = ""
         ) -> Measurement | None:
    """A pose (``body``: the robot's frame in the message's frame) as a measurement of x, y,
    z, roll, pitch and yaw in the world: ``frame * body``, ``frame`` being the message's
    frame in the world. Its covariance and mask turn with the frame's rotation."""
    placed = frame * body
    z = np.zeros(STATE_SIZE)
    z[X:X + 3] = placed.origin
    z[ROLL:ROLL + 3] = rpy_from_rotation(placed.rotation)
    rot6 = frame.six
    covariance = np.zeros((STATE_SIZE, STATE_SIZE))
    covariance[POSE, POSE] = rot6 @ covariance6 @ rot6.T
    return _measurement(stamp_ns, z, covariance, frame.measured(update, POSE), threshold,
                        source)


def pose_change(stamp_ns: int, previous: Mount, current: Mount, dt: float,
                covariance6: FloatArray, update: tuple[bool, ...], threshold: float = math.inf,
                source: str = "", turn: Mount | None = None) -> Measurement | None:
    """Two consecutive poses ``dt`` apart as the twist that moves ``previous`` to ``current``
    (the peer's ``_differential``): the change previous^-1 current, in the previous pose's
    frame, over dt: its translation / dt and its roll, pitch, yaw / dt.

    ``covariance6`` is the sum of the two poses' covariances; the twist's is that times dt,
    as the peer has it. The pose entries of ``update`` say which rates are measured. An
    IMU's ``turn`` (its mount's ``yaw_turn``) turns the mask and the covariance, as for its
    attitude.
    """
    change = previous.inverse() * current
    if turn is not None:
        rot6 = turn.six
        covariance6 = rot6 @ covariance6 @ rot6.T
        update = (*turn.masked(tuple(update[X:X + 3])),
                  *turn.masked(tuple(update[ROLL:ROLL + 3])))
    twist_update = [False] * STATE_SIZE
    twist_update[TWIST] = update[POSE]
    return twist(stamp_ns, change.origin / dt,
                 np.asarray(rpy_from_rotation(change.rotation)) / dt, covariance6 * dt,
                 tuple(twist_update), np.zeros(3), IDENTITY, threshold, source)


def imu_attitude(quaternion: tuple[float, float, float, float], mount: Mount) -> FloatArray:
    """An IMU's attitude (x, y, z, w, in the world frame) as the robot's, a rotation: the
    mount's angles taken off (roll, pitch and yaw minus the mount's), the roll/pitch pair
    turned by the mount's yaw, as the peer does (not a frame change)."""
    roll0, pitch0, yaw0 = mount.rpy
    roll, pitch, yaw = rpy_from_rotation(rotation_from_quaternion(*quaternion))
    offsets = (wrap(roll - roll0), wrap(pitch - pitch0), wrap(yaw - yaw0))
    # T offsets over Python floats: numpy's product and its scalars cost more on three.
    turned = (sum(t * o for t, o in zip(row, offsets)) for row in mount.yaw_turn.rows)
    return rotation_from_rpy(*turned)


def _orientation_numpy(attitude: FloatArray, covariance3: FloatArray, turn: Mount
                       ) -> tuple[FloatArray, FloatArray]:
    z = np.zeros(STATE_SIZE)
    z[ROLL:ROLL + 3] = rpy_from_rotation(attitude)
    covariance = np.zeros((STATE_SIZE, STATE_SIZE))
    covariance[ORIENTATION, ORIENTATION] = turn.rotation @ covariance3 @ turn.rotation.T
    return z, covariance


def imu_orientation(stamp_ns: int, attitude: FloatArray, covariance3: FloatArray,
                    update: tuple[bool, ...], mount: Mount = IDENTITY,
                    threshold: float = math.inf, source: str = "", compiled: bool = True
                    ) -> Measurement | None:
    """An IMU's attitude (``imu_attitude``, maybe relative to its first) as a roll, pitch,
    yaw measurement; its covariance and mask turned by the mount's yaw (``yaw_turn``: a
    sideways IMU's pitch is the robot's roll)."""
    turn = mount.yaw_turn
    kernels = steps.kernels(compiled)
    if kernels is not None:
        z, covariance = kernels.orientation_values(*map(c_doubles, (
            attitude, turn.rotation, covariance3)))
    else:
        z, covariance = _orientation_numpy(attitude, covariance3, turn)
    return _measurement(stamp_ns, z, covariance, turn.measured(update, ORIENTATION),
                        threshold, source)


def _acceleration_numpy(linear: FloatArray, covariance3: FloatArray, state_rates: FloatArray,
                        angular_acceleration: FloatArray, seen_from: FloatArray | None,
                        gravity: float, mount: Mount) -> tuple[FloatArray, FloatArray]:
    r, o = mount.rotation, mount.origin
    if seen_from is not None:
        linear = linear - seen_from.T @ np.array([0.0, 0.0, gravity])
    a = r @ linear + _cross(o, angular_acceleration) \
        - _cross(_cross(o, state_rates), state_rates)
    z = np.zeros(STATE_SIZE)
    z[ACCELERATION] = a
    covariance = np.zeros((STATE_SIZE, STATE_SIZE))
    covariance[ACCELERATION, ACCELERATION] = r @ covariance3 @ r.T
    return z, covariance


def acceleration(stamp_ns: int, linear: FloatArray, covariance3: FloatArray,
                 update: tuple[bool, ...], state_rates: FloatArray,
                 angular_acceleration: FloatArray, attitude: FloatArray | None,
                 remove_gravity: bool, gravity: float = GRAVITY, mount: Mount = IDENTITY,
                 threshold: float = math.inf, source: str = "", compiled: bool = True
                 ) -> Measurement | None:
    """A linear acceleration in the sensor's frame as a measurement in the robot's.

    ``attitude`` is the sensor frame's attitude in the world (a rotation matrix): the
    reading's own orientation, or the state's roll/pitch/yaw composed with the mount when
    the IMU reports none.
    """
    r, o = mount.rotation, mount.origin
    # Gravity (0, 0, g) in the world, seen in the sensor's frame; none kept when not asked.
    seen_from = attitude if remove_gravity and attitude is not None else None
    kernels = steps.kernels(compiled)
    if kernels is not None:
        z, covariance = kernels.acceleration_values(
            *map(c_doubles, (r, o, linear, covariance3, state_rates, angular_acceleration,
                             r if seen_from is None else seen_from)),
            0.0 if seen_from is None else gravity)
    else:
        z, covariance = _acceleration_numpy(linear, covariance3, state_rates,
                                            angular_acceleration, seen_from, gravity, mount)
    return _measurement(stamp_ns, z, covariance, mount.measured(update, ACCELERATION),
                        threshold, source)


def imu_values(quaternion: tuple[float, float, float, float] | None,
               orientation_covariance: FloatArray, angular: FloatArray,
               angular_covariance: FloatArray, linear: FloatArray,
               linear_covariance: FloatArray, state_rates: FloatArray,
               angular_acceleration: FloatArray, gravity_attitude: FloatArray | None,
               gravity: float = GRAVITY, mount: Mount = IDENTITY, compiled: bool = True
               ) -> tuple[FloatArray, FloatArray]:
    """One IMU reading's three parts in one z and one 15 x 15 covariance, each in its own
    entries (the orientation's, the angular rates', the linear acceleration's), as
    ``imu_orientation`` of ``imu_attitude``, ``twist`` with no linear part and
    ``acceleration`` make them: one computation for the three, the measurements then
    sharing the arrays (each reads only its entries). ``quaternion`` None: no attitude
    (the reading has none, or it is taken another way); ``gravity_attitude`` as
    ``acceleration``'s ``attitude`` when gravity is to be taken off, None to keep it."""
    kernels = steps.kernels(compiled)
    turn = mount.yaw_turn
    if kernels is not None:
        return kernels.imu_values(
            np.array(quaternion or (0.0, 0.0, 0.0, 1.0)), np.array(mount.rpy),
            turn.rotation, c_doubles(orientation_covariance), quaternion is not None,
            mount.rotation, mount.origin, *map(c_doubles, (
                angular, angular_covariance, linear, linear_covariance, state_rates,
                angular_acceleration,
                mount.rotation if gravity_attitude is None else gravity_attitude)),
            0.0 if gravity_attitude is None else gravity)
    twist6 = np.zeros((6, 6))
    twist6[3:, 3:] = angular_covariance
    z, covariance = _twist_numpy(np.zeros(3), angular, twist6, state_rates, mount)
    parts = [(ACCELERATION, _acceleration_numpy(linear, linear_covariance, state_rates,
                                                angular_acceleration, gravity_attitude,
                                                gravity, mount))]
    if quaternion is not None:
        parts.append((ORIENTATION, _orientation_numpy(imu_attitude(quaternion, mount),
                                                      orientation_covariance, turn)))
    for part, (part_z, part_covariance) in parts:
        z[part] = part_z[part]
        covariance[part, part] = part_covariance[part, part]
    return z, covariance


def imu_measurement(stamp_ns: int, z: FloatArray, covariance: FloatArray,
                    update: tuple[bool, ...], part: slice, turn: Mount,
                    threshold: float = math.inf, source: str = "") -> Measurement | None:
    """The measurement of ``part`` (ORIENTATION, TWIST or ACCELERATION) of ``imu_values``'
    z and covariance: the entries ``update`` asks for, turned by ``turn`` (the mount's
    ``yaw_turn`` for the orientation, the mount itself for the others)."""
    return _measurement(stamp_ns, z, covariance, turn.measured(update, part), threshold,
                        source)


def force_two_d(measurement: Measurement) -> Measurement:
    """The measurement saying also that z, roll, pitch, vz, vroll, vpitch and az are 0, with
    variance 1e-6, whatever the sensor said of them (the peer's ``forceTwoD``, which
    ``two_d_mode`` applies to every measurement, so the state stays in the plane).

    Their cross terms with the other entries are zeroed. The peer keeps the message's,
    which belong to the values replaced and can leave R indefinite.
    """
    z = measurement.z.copy()
    z[_PLANAR_INDEX] = 0.0
    covariance = measurement.covariance.copy()
    covariance[_PLANAR_INDEX, :] = 0.0
    covariance[:, _PLANAR_INDEX] = 0.0
    covariance[_PLANAR_INDEX, _PLANAR_INDEX] = PLANAR_VARIANCE
    indices = tuple(sorted(set(measurement.indices).union(PLANAR_ZEROS)))
    # A zero said of a rate is of the rate itself, not of a gyro's reading of it.
    biased = tuple(pair for pair in measurement.biased if pair[0] not in PLANAR_ZEROS)
    return Measurement(measurement.stamp_ns, z, covariance, indices, measurement.threshold,
                       measurement.source, biased)
