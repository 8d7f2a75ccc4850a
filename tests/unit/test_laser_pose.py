"""The laser's mounting pose (laser_pose): beams start where the laser sits on the robot."""

from __future__ import annotations

import math

import numpy as np
import pytest

from estimation_nodes.core import errors
from estimation_nodes.core.grid.belief import most_likely_state, pose_of
from estimation_nodes.core.grid.laser import beam_endpoints, scan_log_likelihood
from estimation_nodes.core.grid.likelihood_field import SensorField, grid_model
from estimation_nodes.core.sim import planar
from estimation_nodes.params import map_files as maps
from tests.conftest import REPO


def sensor(laser_pose=(0.0, 0.0, 0.0)):
    return SensorField(z_hit=0.5, z_rand=0.5, sigma_hit=0.2, max_range=12.0,
                       max_distance=2.0, laser_pose=laser_pose)


@pytest.fixture(scope="module")
def office():
    return maps.read_map_file(REPO / "maps" / "office.yaml")


def test_endpoints_start_at_the_laser(office):
    mount = (0.3, -0.1, 0.4)
    model = grid_model(office, 0.4, 12, sensor(mount), 10**6)
    ranges, angles = np.array([1.0, 2.5, 0.7]), np.array([-1.0, 0.0, 2.0])
    ends = beam_endpoints(model, ranges, angles)
    for k, heading in enumerate(model.headings()):
        for b, (r, a) in enumerate(zip(ranges, angles)):
            x = mount[0] * math.cos(heading) - mount[1] * math.sin(heading) \
                + r * math.cos(heading + mount[2] + a)
            y = mount[0] * math.sin(heading) + mount[1] * math.cos(heading) \
                + r * math.sin(heading + mount[2] + a)
            assert tuple(ends[k, b]) == (math.floor(0.5 + y / 0.4), math.floor(0.5 + x / 0.4))


def test_a_laser_at_the_centre_scores_as_before(office):
    centred = grid_model(office, 0.4, 12, sensor(), 10**6)
    ranges, angles = np.array([1.0, 2.5, 0.7]), np.array([-1.0, 0.0, 2.0])
    theta = centred.headings()[:, None] + angles[None, :]
    r = ranges[None, :] / 0.4
    np.testing.assert_array_equal(beam_endpoints(centred, ranges, angles)[..., 1],
                                  np.floor(0.5 + r * np.cos(theta)))


def test_the_scan_of_a_laser_ahead_of_the_centre_finds_the_robot_not_the_laser(office):
    world = planar.planar_world(office)
    mount = (0.4, 0.0, 0.0)
    mounted = grid_model(office, 0.2, 36, sensor(mount), 10**7)
    centred = grid_model(office, 0.2, 36, sensor(), 10**7)
    xs, ys = mounted.cell_centres()
    free_rows, free_cols = np.nonzero(mounted.free)
    # A free cell with the laser 0.4 m ahead (two cells) in free space too.
    index = next(n for n in range(0, free_rows.size, 97)
                 if free_cols[n] + 2 < xs.size and mounted.free[free_rows[n], free_cols[n] + 2]
                 and mounted.free[free_rows[n], free_cols[n] - 2])
    robot = (float(xs[free_cols[index]]), float(ys[free_rows[index]]), 0.0)
    laser = planar.sensor_at(robot, mount)
    angles = np.linspace(-math.pi, math.pi, 90, endpoint=False)
    ranges = planar.ray_cast(world, laser, angles, 12.0)
    seen = np.isfinite(ranges)

    def best(model):
        scores = scan_log_likelihood(model, ranges[seen], angles[seen])
        scores[:, ~model.free] = -np.inf
        return pose_of(model, most_likely_state(np.exp(scores - scores.max())))

    found = best(mounted)
    assert math.hypot(found[0] - robot[0], found[1] - robot[1]) < 0.15
    # Without its mounting pose the filter puts the robot where the laser is.
    wrong = best(centred)
    assert math.hypot(wrong[0] - laser[0], wrong[1] - laser[1]) < 0.15


@pytest.mark.parametrize("bad, says", [((0.0, math.nan, 0.0), "finite"),
                                       ((1.0, 2.0), "finite numbers"),
                                       ((200.0, 0.0, 0.0), "within 100 m")])
def test_a_bad_mounting_pose_is_refused_with_its_name(bad, says):
    with pytest.raises(errors.InvalidInputError, match=f"laser_pose.*{says}"):
        sensor(bad)


def test_a_sensor_sits_where_its_mounting_pose_puts_it():
    assert planar.sensor_at((1.0, 2.0, math.pi / 2), (0.5, 0.1, 0.2)) == pytest.approx(
        (0.9, 2.5, math.pi / 2 + 0.2))
