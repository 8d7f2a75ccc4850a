"""A simulated unicycle among landmarks: what it truly does, what its odometry says and what
its camera sees, each drawn from the simulator's own noise parameters.

The robot wanders: its commanded twist is redrawn every ``hold`` seconds, and it turns
back toward the landmarks' centre when it strays beyond ``radius`` of it. Its true
motion over a step is the commanded one plus errors drawn from a UnicycleNoise (the
variances per metre, radian and second that the filter assumes, given as the
simulator's own parameters). The camera sees each landmark within ``max_range`` and
``field_of_view`` at a range and a bearing with Gaussian errors.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimation_nodes.core.kalman import range_bearing, unicycle
from estimation_nodes.core.kalman.range_bearing import SensorPose
from estimation_nodes.core.kalman.unicycle import UnicycleNoise, wrap


@dataclass(frozen=True)
class Camera:
    """What the simulated camera sees: within ``max_range`` m and ``field_of_view`` rad
    (centred on its axis), with range std ``range_std + range_std_per_m * range``."""

    sensor: SensorPose
    max_range: float
    field_of_view: float
    range_std: float
    range_std_per_m: float
    bearing_std: float

    def observe(self, pose: np.ndarray, landmarks: dict[int, tuple[float, float]],
                rng: np.random.Generator) -> list[tuple[int, float, float]]:
        """(id, range, bearing) of each landmark in view, with noise."""
        seen = []
        for key, landmark in sorted(landmarks.items()):
            r, b = range_bearing.expected(pose, landmark, self.sensor)
            if r <= self.max_range and abs(b) <= self.field_of_view / 2:
                std = self.range_std + self.range_std_per_m * r
                seen.append((key, max(r + std * rng.standard_normal(), 1e-3),
                             wrap(b + self.bearing_std * rng.standard_normal())))
        return seen


@dataclass
class Wanderer:
    """Commanded twists: a speed and a turn rate redrawn every ``hold`` s, and a turn back
    toward ``centre`` beyond ``radius``."""

    rng: np.random.Generator
    speed: float
    turn_rate: float
    centre: tuple[float, float]
    radius: float
    hold: float = 2.0
    _left: float = 0.0
    _twist: tuple[float, float] = (0.0, 0.0)

    def command(self, pose: np.ndarray, dt: float) -> tuple[float, float]:
        self._left -= dt
        away = math.hypot(pose[0] - self.centre[0], pose[1] - self.centre[1])
        if away > self.radius:
            toward = math.atan2(self.centre[1] - pose[1], self.centre[0] - pose[0])
            turn = wrap(toward - pose[2])
            return (self.speed * 0.5, math.copysign(self.turn_rate, turn)
                    if abs(turn) > 0.2 else 0.0)
        if self._left <= 0:
            self._left = self.hold
            self._twist = (self.speed * self.rng.uniform(0.3, 1.0),
                           self.turn_rate * self.rng.uniform(-1.0, 1.0))
        return self._twist


def true_motion(pose: np.ndarray, v: float, w: float, dt: float, noise: UnicycleNoise,
                rng: np.random.Generator) -> np.ndarray:
    """The pose after a step commanded at (v, w): the step's distance and turn with errors
    of the noise's variances."""
    var_d, var_phi = noise.variances(v * dt, w * dt, dt)
    d = v * dt + math.sqrt(var_d) * rng.standard_normal()
    phi = w * dt + math.sqrt(var_phi) * rng.standard_normal()
    return unicycle.move(pose, d / dt, phi / dt, dt) if dt > 0 else pose
