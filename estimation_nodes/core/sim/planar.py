"""The simulated planar robot: wandering without collisions, odometry noise, a ray-cast scan.

Poses are (x, y, yaw) in the map frame (m, rad). The world is the map at its
own resolution: ``occupied`` cells stop beams, and ``clearance`` (the
distance from each cell to the nearest obstacle) keeps the robot
``radius`` away from walls. The noise is the localizer's own model: odometry
as the odometry motion model samples it (Probabilistic Robotics Table 5.6),
ranges as the likelihood field assumes (Gaussian hits, some random readings).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import distance_transform_edt

from estimation_nodes.core import geometry
from estimation_nodes.core.grid.motion import OdometryNoise
from estimation_nodes.core.grid.occupancy import OCCUPIED, UNKNOWN, OccupancyMap
from estimation_nodes.core.validation import FloatArray

Pose = tuple[float, float, float]


@dataclass(frozen=True)
class PlanarWorld:
    """``occupied`` (H, W) bool and ``clearance`` (H, W) m, row 0 at ``origin``'s y."""

    occupied: np.ndarray
    clearance: FloatArray
    resolution: float
    origin: tuple[float, float]

    def cell(self, x: float, y: float) -> tuple[int, int] | None:
        """(row, col) of a point; None off the map."""
        col = math.floor((x - self.origin[0]) / self.resolution)
        row = math.floor((y - self.origin[1]) / self.resolution)
        rows, cols = self.occupied.shape
        return (row, col) if 0 <= row < rows and 0 <= col < cols else None

    def clearance_at(self, x: float, y: float) -> float:
        """Distance (m) to the nearest obstacle; 0 off the map."""
        cell = self.cell(x, y)
        return 0.0 if cell is None else float(self.clearance[cell])


def ray_cast(world: PlanarWorld, pose: Pose, angles: FloatArray, max_range: float) -> FloatArray:
    """Range to the first occupied cell along each beam; inf where none is within
    ``max_range`` (REP 117's "no return"). Beams are marched in steps of a quarter cell."""
    step = world.resolution / 4
    distances = np.arange(step, max_range + step, step)
    theta = pose[2] + np.asarray(angles, dtype=np.float64)
    xs = pose[0] + np.cos(theta)[:, None] * distances[None, :]
    ys = pose[1] + np.sin(theta)[:, None] * distances[None, :]
    cols = np.floor((xs - world.origin[0]) / world.resolution).astype(np.int64)
    rows = np.floor((ys - world.origin[1]) / world.resolution).astype(np.int64)
    height, width = world.occupied.shape
    inside = (rows >= 0) & (rows < height) & (cols >= 0) & (cols < width)
    hit = np.zeros(inside.shape, dtype=bool)
    hit[inside] = world.occupied[rows[inside], cols[inside]]
    first = np.argmax(hit, axis=1)
    found = hit[np.arange(hit.shape[0]), first]
    return np.where(found, distances[first], np.inf)


def noisy_ranges(ranges: FloatArray, rng: np.random.Generator, sigma: float,
                 random_fraction: float, max_range: float) -> FloatArray:
    """What a laser reports: the true range plus Gaussian noise, or with probability
    ``random_fraction`` a random reading uniform over the range."""
    noisy = ranges + sigma * rng.standard_normal(ranges.shape)
    random = rng.random(ranges.shape) < random_fraction
    noisy = np.where(random, rng.uniform(0.0, max_range, ranges.shape), noisy)
    noisy = np.where(np.isfinite(ranges) | random, noisy, np.inf)
    return np.where(noisy >= max_range, np.inf, np.maximum(noisy, 0.0))


def compose(pose: Pose, delta: tuple[float, float, float]) -> Pose:
    """A pose moved by (rot1, trans, rot2)."""
    rot1, trans, rot2 = delta
    heading = pose[2] + rot1
    return (pose[0] + trans * math.cos(heading), pose[1] + trans * math.sin(heading),
            _wrap(pose[2] + rot1 + rot2))


def sensor_at(pose: Pose, mounting: tuple[float, float, float]) -> Pose:
    """Where a sensor mounted at ``mounting`` (x, y, yaw on the robot) is, with the robot
    at ``pose``."""
    return geometry.compose(pose, mounting)


def sample_odometry(delta: tuple[float, float, float], noise: OdometryNoise,
                    rng: np.random.Generator) -> tuple[float, float, float]:
    """The motion odometry reports for a true ``delta``, drawn from the odometry motion
    model with ``noise``'s alphas (Probabilistic Robotics Table 5.6, as std devs)."""
    rot1, trans, rot2 = delta
    rot_std = noise.alpha1 * (abs(rot1) + abs(rot2)) + noise.alpha2 * trans
    trans_std = noise.alpha3 * trans + noise.alpha4 * (abs(rot1) + abs(rot2))
    return (rot1 + rot_std / 2 * rng.standard_normal(),
            trans + trans_std * rng.standard_normal(),
            rot2 + rot_std / 2 * rng.standard_normal())


@dataclass
class Wanderer:
    """A seeded route: straight ahead while the way is clear, turning on the spot (in a
    direction drawn when the turn begins) until it is clear again."""

    rng: np.random.Generator
    speed: float
    turn_rate: float
    radius: float
    turning: float = 0.0

    def step(self, world: PlanarWorld, pose: Pose, dt: float) -> tuple[float, float, float]:
        """The true (rot1, trans, rot2) of the next ``dt`` seconds."""
        ahead = self._clear(world, pose, self.speed * dt) and self._clear(
            world, pose, max(self.radius, self.speed * 1.0))
        if ahead and not (self.turning and self.rng.random() < 0.7):
            self.turning = 0.0
            # A slight random drift, so the route covers the map rather than a loop.
            drift = 0.15 * dt * self.rng.standard_normal()
            return (0.0, self.speed * dt, drift)
        if not self.turning:
            self.turning = self.rng.choice((-1.0, 1.0))
        return (self.turning * self.turn_rate * dt, 0.0, 0.0)

    def _clear(self, world: PlanarWorld, pose: Pose, distance: float) -> bool:
        x = pose[0] + distance * math.cos(pose[2])
        y = pose[1] + distance * math.sin(pose[2])
        return world.clearance_at(x, y) > self.radius


def free_place(world: PlanarWorld, rng: np.random.Generator, radius: float) -> Pose:
    """A pose drawn uniformly among the cells at least ``radius`` from every obstacle."""
    rows, cols = np.nonzero(world.clearance > radius)
    if rows.size == 0:
        raise ValueError(f"robot_radius: no place on the map is {radius} m from every obstacle")
    index = int(rng.integers(rows.size))
    x = world.origin[0] + (cols[index] + 0.5) * world.resolution
    y = world.origin[1] + (rows[index] + 0.5) * world.resolution
    return (float(x), float(y), float(rng.uniform(-math.pi, math.pi)))


def _wrap(angle: float) -> float:
    return math.pi - (math.pi - angle) % (2 * math.pi)


def planar_world(occupancy: OccupancyMap) -> PlanarWorld:
    """The simulated robot's world at the map's resolution: occupied cells stop beams;
    the clearance keeps it off obstacles and out of unknown space."""
    occupied = occupancy.cells >= OCCUPIED
    blocked = occupied | (occupancy.cells == UNKNOWN)
    clearance = distance_transform_edt(~blocked) * occupancy.resolution
    return PlanarWorld(occupied=occupied, clearance=clearance,
                       resolution=occupancy.resolution, origin=occupancy.origin)
