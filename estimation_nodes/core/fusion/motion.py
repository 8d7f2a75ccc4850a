"""robot_localization's motion model: constant acceleration, omnidirectional, in 3-D.

The pose moves by the twist and acceleration (both in the robot's frame) rotated into
the world by the current roll, pitch and yaw: p' = p + R (v dt + a dt^2 / 2); the
angles move by the body rates through the Euler-rate matrix; v' = v + a dt; the rates
and the acceleration stay. ``transfer`` is that linear map at the state's angles (the
peer's ``transfer_function_``), ``jacobian`` adds the derivatives in the angles (its
``transfer_function_jacobian_``).

``write_transfer`` and ``write_angle_derivatives`` hold the formulas once, in the subset
of Python that numba compiles: compiled.py compiles these same functions for its kernels.
"""

from __future__ import annotations

import math

import numpy as np

from estimation_nodes.core.fusion.state import (
    AX, AY, AZ, PITCH, ROLL, VPITCH, VROLL, VX, VY, VYAW, VZ, X, Y, YAW, Z)
from estimation_nodes.core.validation import FloatArray


def transfer(x: FloatArray, dt: float) -> FloatArray:
    """The transition matrix at the state's angles: x' = F x."""
    f = np.eye(x.shape[0])      # gyro biases past the 15 entries: constant
    write_transfer(x, dt, f)
    return f


def jacobian(x: FloatArray, dt: float) -> FloatArray:
    """d(F(x) x)/dx: the transfer matrix plus the derivatives of the rotation in the angles."""
    j = transfer(x, dt)
    write_angle_derivatives(x, dt, j)
    return j


def write_transfer(x: FloatArray, dt: float, f: FloatArray) -> None:
    """F's entries off the identity, written into ``f`` (an identity matrix, or an ``f``
    this wrote before: it writes the same entries whatever the state)."""
    roll, pitch, yaw = x[ROLL], x[PITCH], x[YAW]
    sr, cr = math.sin(roll), math.cos(roll)
    sp, cp = math.sin(pitch), math.cos(pitch)
    sy, cy = math.sin(yaw), math.cos(yaw)
    cpi = 1.0 / cp
    tp = sp * cpi
    rotation = ((cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr),
                (sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr),
                (-sp, cp * sr, cp * cr))
    # Entry by entry, not as array expressions: in a compiled kernel each of those would
    # allocate a temporary, for every sigma point of every UKF step.
    for row in range(3):
        for column in range(3):
            f[X + row, VX + column] = rotation[row][column] * dt
            f[X + row, AX + column] = 0.5 * rotation[row][column] * dt * dt
    f[ROLL, VROLL] = dt
    f[ROLL, VPITCH] = sr * tp * dt
    f[ROLL, VYAW] = cr * tp * dt
    f[PITCH, VPITCH] = cr * dt
    f[PITCH, VYAW] = -sr * dt
    f[YAW, VPITCH] = sr * cpi * dt
    f[YAW, VYAW] = cr * cpi * dt
    f[VX, AX] = dt
    f[VY, AY] = dt
    f[VZ, AZ] = dt


def write_angle_derivatives(x: FloatArray, dt: float, j: FloatArray) -> None:
    """The Jacobian's derivatives in the angles, written into ``j`` (F, from
    ``write_transfer``)."""
    roll, pitch, yaw = x[ROLL], x[PITCH], x[YAW]
    sr, cr = math.sin(roll), math.cos(roll)
    sp, cp = math.sin(pitch), math.cos(pitch)
    sy, cy = math.sin(yaw), math.cos(yaw)
    cpi = 1.0 / cp
    tp = sp * cpi
    vx, vy, vz = x[VX], x[VY], x[VZ]
    ax, ay, az = x[AX], x[AY], x[AZ]
    half_dt2 = 0.5 * dt * dt

    def moved(c0: float, c1: float, c2: float) -> float:
        """The displacement along (c0, c1, c2), a row of a derivative of the rotation."""
        return (c0 * vx + c1 * vy + c2 * vz) * dt + (c0 * ax + c1 * ay + c2 * az) * half_dt2

    j[X, ROLL] = moved(0.0, cy * sp * cr + sy * sr, -cy * sp * sr + sy * cr)
    j[X, PITCH] = moved(-cy * sp, cy * cp * sr, cy * cp * cr)
    j[X, YAW] = moved(-sy * cp, -sy * sp * sr - cy * cr, -sy * sp * cr + cy * sr)
    j[Y, ROLL] = moved(0.0, sy * sp * cr - cy * sr, -sy * sp * sr - cy * cr)
    j[Y, PITCH] = moved(-sy * sp, sy * cp * sr, sy * cp * cr)
    j[Y, YAW] = moved(cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr)
    j[Z, ROLL] = moved(0.0, cp * cr, -cp * sr)
    j[Z, PITCH] = moved(-cp, -sp * sr, -sp * cr)
    vpitch, vyaw = x[VPITCH], x[VYAW]
    j[ROLL, ROLL] = 1.0 + (cr * tp * vpitch - sr * tp * vyaw) * dt
    j[ROLL, PITCH] = (cpi * cpi * sr * vpitch + cpi * cpi * cr * vyaw) * dt
    j[PITCH, ROLL] = (-sr * vpitch - cr * vyaw) * dt
    j[YAW, ROLL] = (cr * cpi * vpitch - sr * cpi * vyaw) * dt
    j[YAW, PITCH] = (sr * tp * cpi * vpitch + cr * tp * cpi * vyaw) * dt
