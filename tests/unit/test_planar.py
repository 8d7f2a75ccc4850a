"""The simulated planar robot: ray casting, a route that never collides, its noise."""

import math

import numpy as np
import pytest

from estimation_nodes.core.grid.motion import OdometryNoise
from estimation_nodes.core.grid.occupancy import OCCUPIED, OccupancyMap
from estimation_nodes.core.sim import planar
from estimation_nodes.params import map_files as maps
from tests.conftest import REPO


def box_world(size=40, resolution=0.1):
    """A square room of ``size`` cells with one-cell walls, origin at (0, 0)."""
    cells = np.zeros((size, size), dtype=np.int8)
    cells[0, :] = cells[-1, :] = cells[:, 0] = cells[:, -1] = OCCUPIED
    return planar.planar_world(OccupancyMap(cells, resolution, (0.0, 0.0)))


def test_ray_cast_hits_the_walls_where_geometry_says():
    world = box_world()
    ranges = planar.ray_cast(world, (2.0, 2.0, 0.0), np.array([0.0, math.pi / 2, math.pi]),
                             10.0)
    # The walls' inner faces are at 0.1 and 3.9 m; a quarter-cell march finds them within
    # a quarter cell.
    np.testing.assert_allclose(ranges, [1.9, 1.9, 1.9], atol=0.026)
    diagonal = planar.ray_cast(world, (2.0, 2.0, 0.0), np.array([math.pi / 4]), 10.0)
    assert diagonal[0] == pytest.approx(1.9 * math.sqrt(2), abs=0.05)


def test_no_return_is_inf():
    world = box_world()
    assert planar.ray_cast(world, (2.0, 2.0, 0.0), np.array([0.0]), 1.0)[0] == math.inf


def test_the_wanderer_never_comes_closer_than_its_radius_to_a_wall():
    occupancy = maps.read_map_file(REPO / "maps" / "office.yaml")
    world = planar.planar_world(occupancy)
    rng = np.random.default_rng(1)
    pose = planar.free_place(world, rng, 0.25)
    wanderer = planar.Wanderer(rng, speed=0.5, turn_rate=1.0, radius=0.25)
    travelled = 0.0
    for _ in range(3000):
        delta = wanderer.step(world, pose, 0.1)
        moved = planar.compose(pose, delta)
        if world.clearance_at(moved[0], moved[1]) > 0.25:
            pose = moved
            travelled += delta[1]
        assert world.clearance_at(pose[0], pose[1]) > 0.25
    assert travelled > 50.0           # it wanders, not turns on the spot for ever


def test_odometry_noise_follows_the_alphas():
    rng = np.random.default_rng(2)
    noise = OdometryNoise(alpha1=0.0, alpha2=0.0, alpha3=0.1, alpha4=0.0)
    samples = np.array([planar.sample_odometry((0.0, 1.0, 0.0), noise, rng)
                        for _ in range(4000)])
    assert samples[:, 1].std() == pytest.approx(0.1, rel=0.1)
    assert np.all(samples[:, [0, 2]] == 0.0)


def test_noisy_ranges_keep_no_return_and_clip_to_the_range():
    rng = np.random.default_rng(3)
    ranges = np.array([1.0, math.inf, 11.99])
    noisy = planar.noisy_ranges(ranges, rng, 0.05, 0.0, 12.0)
    assert noisy[1] == math.inf and abs(noisy[0] - 1.0) < 0.3
