"""Rigid transforms in 3-D as ROS's tf2 keeps them: a translation and a unit quaternion
(x, y, z, w), composed, inverted and interpolated as tf2 does (the translation linearly,
the rotation by spherical linear interpolation), in plain float arithmetic.

``Transform(t, q)`` maps a point given in the child frame to the parent frame:
``p_parent = R(q) p_child + t``. ``a * b`` is ``b`` expressed in ``a``'s parent frame
(tf2's ``a * b``), so ``T_map_odom * T_odom_base == T_map_base``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from estimation_nodes.core.errors import InvalidInputError

Vector = tuple[float, float, float]
Quaternion = tuple[float, float, float, float]

#: How far from 1 a quaternion's norm may be and still be taken (then normalized); tf2
#: refuses a quaternion whose squared norm is off by more than 0.1.
NORM_TOLERANCE = 0.05


@dataclass(frozen=True)
class Transform:
    """A rigid transform: ``translation`` (m) and ``rotation`` (x, y, z, w)."""

    translation: Vector = (0.0, 0.0, 0.0)
    rotation: Quaternion = (0.0, 0.0, 0.0, 1.0)

    @classmethod
    def checked(cls, translation, rotation) -> "Transform":
        """A transform from untrusted numbers: finite, the quaternion normalized where it is
        a unit quaternion up to rounding; ``InvalidInputError`` saying what is wrong else."""
        t = tuple(float(v) for v in translation)
        q = tuple(float(v) for v in rotation)
        if len(t) != 3 or len(q) != 4:
            raise InvalidInputError("a transform needs 3 translation and 4 rotation values")
        if not all(math.isfinite(v) for v in (*t, *q)):
            raise InvalidInputError(f"a transform with a non-finite value: {t}, {q}")
        norm = math.sqrt(sum(v * v for v in q))
        if abs(norm - 1.0) > NORM_TOLERANCE:
            raise InvalidInputError(f"rotation {q} is not a unit quaternion (norm {norm:.6g})")
        return cls(t, tuple(v / norm for v in q))  # type: ignore[arg-type]

    @classmethod
    def planar(cls, x: float, y: float, yaw: float) -> "Transform":
        """The transform of a planar pose (x, y, yaw about z)."""
        return cls((float(x), float(y), 0.0), (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)))

    def as_planar(self) -> tuple[float, float, float]:
        """(x, y, yaw): the translation's x and y and the rotation about z (REP 103)."""
        x, y, z, w = self.rotation
        yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
        return self.translation[0], self.translation[1], yaw

    def __mul__(self, other: "Transform") -> "Transform":
        return Transform(_add(self.translation, rotate(self.rotation, other.translation)),
                         _multiply(self.rotation, other.rotation))

    def inverse(self) -> "Transform":
        conjugate = _conjugate(self.rotation)
        t = rotate(conjugate, self.translation)
        return Transform((-t[0], -t[1], -t[2]), conjugate)

    def apply(self, point: Vector) -> Vector:
        """A point given in the child frame, in the parent frame."""
        return _add(self.translation, rotate(self.rotation, point))


def interpolate(a: Transform, b: Transform, ratio: float) -> Transform:
    """The transform ``ratio`` (0 to 1) of the way from ``a`` to ``b``: translation
    linearly, rotation by slerp along the shorter arc (tf2's interpolation)."""
    t = tuple(pa + ratio * (pb - pa) for pa, pb in zip(a.translation, b.translation))
    return Transform(t, slerp(a.rotation, b.rotation, ratio))  # type: ignore[arg-type]


def slerp(q0: Quaternion, q1: Quaternion, ratio: float) -> Quaternion:
    """Spherical linear interpolation between unit quaternions, along the shorter arc."""
    dot = sum(a * b for a, b in zip(q0, q1))
    if dot < 0.0:  # q and -q are one rotation: take the nearer of the two
        q1, dot = tuple(-v for v in q1), -dot  # type: ignore[assignment]
    if dot > 0.9995:
        # Nearly equal: sin(theta) ~ 0, where linear interpolation is as exact.
        mixed = [a + ratio * (b - a) for a, b in zip(q0, q1)]
    else:
        theta = math.acos(dot)
        w0 = math.sin((1.0 - ratio) * theta) / math.sin(theta)
        w1 = math.sin(ratio * theta) / math.sin(theta)
        mixed = [w0 * a + w1 * b for a, b in zip(q0, q1)]
    norm = math.sqrt(sum(v * v for v in mixed))
    return tuple(v / norm for v in mixed)  # type: ignore[return-value]


def rotate(q: Quaternion, v: Vector) -> Vector:
    """v rotated by the unit quaternion q: v + 2 w (u x v) + 2 u x (u x v), u = (x, y, z)."""
    x, y, z, w = q
    cx, cy, cz = y * v[2] - z * v[1], z * v[0] - x * v[2], x * v[1] - y * v[0]
    return (v[0] + 2.0 * (w * cx + y * cz - z * cy),
            v[1] + 2.0 * (w * cy + z * cx - x * cz),
            v[2] + 2.0 * (w * cz + x * cy - y * cx))


def _multiply(a: Quaternion, b: Quaternion) -> Quaternion:
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz)


def _conjugate(q: Quaternion) -> Quaternion:
    return (-q[0], -q[1], -q[2], q[3])


def _add(a: Vector, b: Vector) -> Vector:
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])
