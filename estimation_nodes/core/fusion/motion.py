"""robot_localization's motion model: constant acceleration, omnidirectional, in 3-D.

The pose moves by the twist and acceleration (both in the robot's frame) rotated into
the world by the current roll, pitch and yaw: p' = p + R (v dt + a dt^2 / 2); the
angles move by the body rates through the Euler-rate matrix; v' = v + a dt; the rates
and the acceleration stay. ``transfer`` is that linear map at the state's angles (the
peer's ``transfer_function_``), ``jacobian`` adds the derivatives in the angles (its
``transfer_function_jacobian_``).
"""

from __future__ import annotations

import math

import numpy as np

from estimation_nodes.core.fusion.state import (
    AX, AY, AZ, PITCH, ROLL, STATE_SIZE, VPITCH, VROLL, VX, VY, VYAW, VZ, X, Y, YAW, Z)
from estimation_nodes.core.validation import FloatArray


def _trig(x: FloatArray) -> tuple[float, ...]:
    """sin and cos of roll, pitch and yaw."""
    roll, pitch, yaw = float(x[ROLL]), float(x[PITCH]), float(x[YAW])
    return (math.sin(roll), math.cos(roll), math.sin(pitch), math.cos(pitch),
            math.sin(yaw), math.cos(yaw))


def transfer(x: FloatArray, dt: float) -> FloatArray:
    """The transition matrix at the state's angles: x' = F x."""
    sr, cr, sp, cp, sy, cy = _trig(x)
    cpi = 1.0 / cp
    tp = sp * cpi
    f = np.eye(STATE_SIZE)
    rotation = np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ])
    f[X:Z + 1, VX:VZ + 1] = rotation * dt
    f[X:Z + 1, AX:AZ + 1] = 0.5 * rotation * dt * dt
    f[ROLL, VROLL] = dt
    f[ROLL, VPITCH] = sr * tp * dt
    f[ROLL, VYAW] = cr * tp * dt
    f[PITCH, VPITCH] = cr * dt
    f[PITCH, VYAW] = -sr * dt
    f[YAW, VPITCH] = sr * cpi * dt
    f[YAW, VYAW] = cr * cpi * dt
    f[VX, AX] = f[VY, AY] = f[VZ, AZ] = dt
    return f


def jacobian(x: FloatArray, dt: float) -> FloatArray:
    """d(F(x) x)/dx: the transfer matrix plus the derivatives of the rotation in the angles."""
    sr, cr, sp, cp, sy, cy = _trig(x)
    cpi = 1.0 / cp
    tp = sp * cpi
    v = x[VX:VZ + 1]
    a = x[AX:AZ + 1]
    half_dt2 = 0.5 * dt * dt

    def moved(coefficients: tuple[float, float, float]) -> float:
        c = np.asarray(coefficients)
        return float(c @ v * dt + c @ a * half_dt2)

    j = transfer(x, dt)
    j[X, ROLL] = moved((0.0, cy * sp * cr + sy * sr, -cy * sp * sr + sy * cr))
    j[X, PITCH] = moved((-cy * sp, cy * cp * sr, cy * cp * cr))
    j[X, YAW] = moved((-sy * cp, -sy * sp * sr - cy * cr, -sy * sp * cr + cy * sr))
    j[Y, ROLL] = moved((0.0, sy * sp * cr - cy * sr, -sy * sp * sr - cy * cr))
    j[Y, PITCH] = moved((-sy * sp, sy * cp * sr, sy * cp * cr))
    j[Y, YAW] = moved((cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr))
    j[Z, ROLL] = moved((0.0, cp * cr, -cp * sr))
    j[Z, PITCH] = moved((-cp, -sp * sr, -sp * cr))
    vpitch, vyaw = x[VPITCH], x[VYAW]
    j[ROLL, ROLL] = 1.0 + (cr * tp * vpitch - sr * tp * vyaw) * dt
    j[ROLL, PITCH] = (cpi * cpi * sr * vpitch + cpi * cpi * cr * vyaw) * dt
    j[PITCH, ROLL] = (-sr * vpitch - cr * vyaw) * dt
    j[YAW, ROLL] = (cr * cpi * vpitch - sr * cpi * vyaw) * dt
    j[YAW, PITCH] = (sr * tp * cpi * vpitch + cr * tp * cpi * vyaw) * dt
    return j
