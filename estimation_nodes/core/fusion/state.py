"""The 15-entry state of robot_localization and the rotations it is expressed with.

The state is x, y, z, roll, pitch, yaw (the pose in the world frame), vx, vy, vz,
vroll, vpitch, vyaw (the twist in the robot's frame) and ax, ay, az (the linear
acceleration in the robot's frame); after them, 3 entries per IMU whose gyro bias is
estimated. Rotations follow tf2: ``rotation_from_rpy`` is
``Matrix3x3::setRPY`` (R = Rz(yaw) Ry(pitch) Rx(roll)), ``rpy_from_rotation`` its
``getRPY``, ``wrap`` is ``angles::normalize_angle`` (into [-pi, pi]).
"""

from __future__ import annotations

import math

import numpy as np

from estimation_nodes.core.validation import FloatArray

X, Y, Z, ROLL, PITCH, YAW, VX, VY, VZ, VROLL, VPITCH, VYAW, AX, AY, AZ = range(15)
STATE_SIZE = 15
#: The state's entries by the names robot_localization's ``*_config`` arrays list them in.
NAMES = ("x", "y", "z", "roll", "pitch", "yaw", "vx", "vy", "vz",
         "vroll", "vpitch", "vyaw", "ax", "ay", "az")
ANGLES = (ROLL, PITCH, YAW)
#: Entries a gyro's estimated bias takes after the 15 (its roll, pitch and yaw rates'
#: biases, in the robot's frame): beyond the peer, for the IMUs that ask for it.
GYRO_BIAS_SIZE = 3
POSE = slice(X, YAW + 1)
ORIENTATION = slice(ROLL, YAW + 1)
TWIST = slice(VX, VYAW + 1)
ACCELERATION = slice(AX, AZ + 1)


def wrap(angle: float) -> float:
    """``angles::normalize_angle``: the same angle in [-pi, pi]."""
    positive = math.fmod(math.fmod(angle, 2.0 * math.pi) + 2.0 * math.pi, 2.0 * math.pi)
    return positive - 2.0 * math.pi if positive > math.pi else positive


def wrap_state_angles(x: FloatArray) -> FloatArray:
    """The state with roll, pitch and yaw wrapped (a new array)."""
    wrapped = x.copy()
    for index in ANGLES:
        wrapped[index] = wrap(float(x[index]))
    return wrapped


def rotation_from_rpy(roll: float, pitch: float, yaw: float) -> FloatArray:
    """tf2's ``setRPY``: Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ])


def rpy_from_rotation(rotation: FloatArray) -> tuple[float, float, float]:
    """tf2's ``getRPY`` (its first solution): pitch in [-pi/2, pi/2]."""
    m = rotation
    if abs(m[2, 0]) >= 1.0:
        yaw = 0.0
        delta = math.atan2(m[2, 1], m[2, 2])
        pitch = -math.pi / 2.0 if m[2, 0] > 0 else math.pi / 2.0
        roll = delta if m[2, 0] < 0 else -delta
        return roll, pitch, yaw
    pitch = -math.asin(m[2, 0])
    cp = math.cos(pitch)
    roll = math.atan2(m[2, 1] / cp, m[2, 2] / cp)
    yaw = math.atan2(m[1, 0] / cp, m[0, 0] / cp)
    return roll, pitch, yaw


def rotation_from_quaternion(x: float, y: float, z: float, w: float) -> FloatArray:
    """The rotation of a quaternion, normalized first as tf2 does for one off unit length."""
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def quaternion_from_rpy(roll: float, pitch: float, yaw: float) -> tuple[float, ...]:
    """tf2's ``Quaternion::setRPY``: (x, y, z, w)."""
    hr, hp, hy = roll / 2.0, pitch / 2.0, yaw / 2.0
    cr, sr = math.cos(hr), math.sin(hr)
    cp, sp = math.cos(hp), math.sin(hp)
    cy, sy = math.cos(hy), math.sin(hy)
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy)
