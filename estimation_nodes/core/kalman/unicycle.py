"""The unicycle: a wheeled robot driven by its forward speed v and turn rate w.

Over a step of ``dt`` seconds the robot travels d = v dt along the heading at
the step's midpoint and turns by phi = w dt (second order in dt, and no
division by w, so a straight drive is no special case)::

    x' = x + d cos(theta + phi / 2)
    y' = y + d sin(theta + phi / 2)
    theta' = theta + phi

The speeds a robot reports are not the speeds it drove: the distance and the
turn of a step carry errors whose variance grows with the distance and the
turn themselves (and a little with time, for the robot that stands still and
yet slips). Variances add over steps, so these coefficients do not depend on
the rate at which the odometry comes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimation_nodes.core.validation import FloatArray, check_finite

TWO_PI = 2.0 * math.pi


def wrap(angle: float) -> float:
    """An angle in [-pi, pi)."""
    return (angle + math.pi) % TWO_PI - math.pi


@dataclass(frozen=True)
class UnicycleNoise:
    """Variances of a step's distance d and turn phi, per unit of motion and of time.

    var(d) = translation_per_m |d| + translation_per_rad |phi| + translation_per_s dt
    var(phi) = rotation_per_m |d| + rotation_per_rad |phi| + rotation_per_s dt
    """

    translation_per_m: float
    translation_per_rad: float
    translation_per_s: float
    rotation_per_m: float
    rotation_per_rad: float
    rotation_per_s: float

    def __post_init__(self) -> None:
        for name in ("translation_per_m", "translation_per_rad", "translation_per_s",
                     "rotation_per_m", "rotation_per_rad", "rotation_per_s"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"{name}: expected a finite number >= 0, got {value!r}")

    def variances(self, d: float, phi: float, dt: float) -> tuple[float, float]:
        """(var(d), var(phi)) of one step."""
        d, phi = abs(d), abs(phi)
        return (self.translation_per_m * d + self.translation_per_rad * phi
                + self.translation_per_s * dt,
                self.rotation_per_m * d + self.rotation_per_rad * phi + self.rotation_per_s * dt)


def check_motion(v: float, w: float, dt: float) -> tuple[float, float, float]:
    """Finite speeds and a finite dt >= 0, as floats; ValueError naming the bad one."""
    # the usual case first, cheaply: a filter predicts at every odometry message
    if isinstance(v, float) and isinstance(w, float) and isinstance(dt, float) \
            and math.isfinite(v) and math.isfinite(w) and math.isfinite(dt) and dt >= 0:
        return float(v), float(w), float(dt)
    v, w, dt = check_finite("v", v), check_finite("w", w), check_finite("dt", dt)
    if dt < 0:
        raise ValueError(f"dt: expected a time step >= 0, got {dt!r}")
    return v, w, dt


def move(x: FloatArray, v: float, w: float, dt: float) -> FloatArray:
    """The pose after driving at (v, w) for dt from pose x = (x, y, theta)."""
    d, phi = v * dt, w * dt
    heading = x[2] + 0.5 * phi
    return np.array([x[0] + d * math.cos(heading), x[1] + d * math.sin(heading),
                     wrap(x[2] + phi)])


def jacobians(x: FloatArray, v: float, w: float, dt: float) -> tuple[FloatArray, FloatArray]:
    """d move / d x (3 x 3) and d move / d (d, phi) (3 x 2), at x."""
    d, phi = v * dt, w * dt
    heading = x[2] + 0.5 * phi
    c, s = math.cos(heading), math.sin(heading)
    F = np.array([[1.0, 0.0, -d * s], [0.0, 1.0, d * c], [0.0, 0.0, 1.0]])
    G = np.array([[c, -0.5 * d * s], [s, 0.5 * d * c], [0.0, 1.0]])
    return F, G


def process_noise(x: FloatArray, v: float, w: float, dt: float,
                  noise: UnicycleNoise) -> FloatArray:
    """The step's noise in state space, G diag(var(d), var(phi)) G'."""
    _, G = jacobians(x, v, w, dt)
    var_d, var_phi = noise.variances(v * dt, w * dt, dt)
    return (G * np.array([var_d, var_phi])) @ G.T
