"""Orientation conventions shared by the nodes that publish poses, and planar pose
composition (numpy only)."""

from __future__ import annotations

import math


def quaternion_from_rpy(
    roll: float, pitch: float, yaw: float
) -> tuple[float, float, float, float]:
    """(x, y, z, w) of the rotation yaw about z, then pitch about y, then roll about x, as
    ROS's tf2 and REP 103 define roll, pitch and yaw."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy)


def compose(a: tuple[float, float, float],
            b: tuple[float, float, float]) -> tuple[float, float, float]:
    """a (+) b: pose b, given in a's frame, in a's parent frame."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return (a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], _wrap(a[2] + b[2]))


def relative(a: tuple[float, float, float],
             b: tuple[float, float, float]) -> tuple[float, float, float]:
    """a^-1 (+) b: pose b in a's frame."""
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return (c * dx + s * dy, -s * dx + c * dy, _wrap(b[2] - a[2]))


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


def yaw_from_quaternion(x: float, y: float, z: float, w: float) -> float:
    """The rotation about z of a quaternion (REP 103), for planar poses."""
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
