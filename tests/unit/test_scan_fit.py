"""The pose refined by the scan's fit on the map's own resolution (core/grid/scan_fit.py)."""

import math

import numpy as np
import pytest

from estimation_nodes.core.grid import scan_fit
from estimation_nodes.core.grid.likelihood_field import SensorField, grid_model
from estimation_nodes.core.grid.localization import GridLocalization
from estimation_nodes.core.grid.motion import OdometryNoise
from estimation_nodes.core.grid.occupancy import FREE, OCCUPIED, OccupancyMap
from estimation_nodes.core.sim import planar

RESOLUTION = 0.05


def room() -> OccupancyMap:
    """A 6 m x 5 m room at 0.05 m with a pillar and an alcove: no two poses see the same."""
    cells = np.full((100, 120), FREE, dtype=np.int8)
    cells[[0, -1], :] = OCCUPIED
    cells[:, [0, -1]] = OCCUPIED
    cells[30:38, 70:76] = OCCUPIED          # a pillar
    cells[60:99, 20] = OCCUPIED             # a wall part-way
    return OccupancyMap(cells=cells, resolution=RESOLUTION, origin=(-1.0, 0.5))


def sensor(laser_pose=(0.0, 0.0, 0.0)) -> SensorField:
    return SensorField(z_hit=0.95, z_rand=0.05, sigma_hit=0.1, max_range=10.0,
                       max_distance=2.0, laser_pose=laser_pose)


def scan_from(occupancy: OccupancyMap, pose, laser_pose=(0.0, 0.0, 0.0), beams=90):
    world = planar.planar_world(occupancy)
    angles = np.linspace(-math.pi, math.pi, beams, endpoint=False)
    laser = planar.sensor_at(pose, laser_pose)
    return planar.ray_cast(world, laser, angles, 10.0), angles


@pytest.mark.parametrize("laser_pose", [(0.0, 0.0, 0.0), (0.25, 0.05, 0.1)])
def test_the_fit_moves_a_pose_towards_the_one_the_scan_was_taken_from(laser_pose):
    occupancy = room()
    model = grid_model(occupancy, 0.1, 72, sensor(laser_pose), 10**7, scan_fit=True)
    truth = (2.013, 2.468, 0.4123)
    ranges, angles = scan_from(occupancy, truth, laser_pose)
    keep = np.isfinite(ranges)
    start = (truth[0] + 0.06, truth[1] - 0.05, truth[2] + 0.05)
    fitted = scan_fit.fitted_pose(model.scan_fit, start, ranges[keep], angles[keep],
                                  0.1, math.radians(5))
    assert math.hypot(fitted[0] - truth[0], fitted[1] - truth[1]) < 0.02
    assert abs(math.remainder(fitted[2] - truth[2], 2 * math.pi)) < math.radians(1)
    field = model.scan_fit
    assert field.score(np.array(fitted), ranges[keep], angles[keep]) > \
        field.score(np.array(start), ranges[keep], angles[keep])


def test_the_fit_stays_within_its_reach_and_keeps_a_pose_nothing_improves():
    occupancy = room()
    model = grid_model(occupancy, 0.1, 36, sensor(), 10**7, scan_fit=True)
    truth = (2.0, 2.5, 0.0)
    ranges, angles = scan_from(occupancy, truth)
    keep = np.isfinite(ranges)
    far = (truth[0] + 0.5, truth[1], truth[2])
    fitted = scan_fit.fitted_pose(model.scan_fit, far, ranges[keep], angles[keep], 0.1, 0.05)
    assert abs(fitted[0] - far[0]) <= 0.1 + 1e-9 and abs(fitted[1] - far[1]) <= 0.1 + 1e-9
    assert abs(fitted[2] - far[2]) <= 0.05 + 1e-9
    # No beam: nothing to fit.
    assert scan_fit.fitted_pose(model.scan_fit, far, np.zeros(0), np.zeros(0), 0.1, 0.05) == far


def test_bilinear_is_exact_at_cell_centres_and_linear_between_them():
    values = np.arange(12.0).reshape(3, 4) ** 1.5
    rows, cols = np.array([0.0, 2.0, 1.0, 0.5]), np.array([0.0, 3.0, 2.0, 1.5])
    got = scan_fit._bilinear(values, rows, cols, -7.0)
    assert got[:3].tolist() == [values[0, 0], values[2, 3], values[1, 2]]
    expected = np.mean([values[0, 1], values[0, 2], values[1, 1], values[1, 2]])
    assert got[3] == pytest.approx(expected, abs=1e-12)
    assert scan_fit._bilinear(values, np.array([-0.1, 1.0]), np.array([1.0, 3.5]),
                              -7.0).tolist() == [-7.0, -7.0]


def test_the_localizer_publishes_the_fitted_pose_and_keeps_the_belief_s_figures():
    occupancy = room()
    noise = OdometryNoise(0.05, 0.05, 0.05, 0.05)
    plain = GridLocalization(grid_model(occupancy, 0.1, 72, sensor(), 10**7), noise,
                             0.0, 0.0, 10.0)
    fitting = GridLocalization(grid_model(occupancy, 0.1, 72, sensor(), 10**7, scan_fit=True),
                               noise, 0.0, 0.0, 10.0)
    truth = (2.013, 2.468, 0.4123)
    ranges, angles = scan_from(occupancy, truth)
    keep = np.isfinite(ranges)
    for localization in (plain, fitting):
        localization.set_prior(truth, np.diag([0.01, 0.01, 0.01]))
    # No scan yet: the belief's pose.
    assert fitting.estimate(0.3, 0.2).pose == plain.estimate(0.3, 0.2).pose
    for localization in (plain, fitting):
        localization.on_odometry((0.0, 0.0, 0.0), 1)
        localization.update(ranges[keep], angles[keep], 1)
    ours, theirs = fitting.estimate(0.3, 0.2), plain.estimate(0.3, 0.2)
    np.testing.assert_array_equal(ours.covariance, theirs.covariance)
    assert ours.quality == theirs.quality
    error = [math.hypot(e.pose[0] - truth[0], e.pose[1] - truth[1]) for e in (ours, theirs)]
    assert error[0] < error[1] and error[0] < 0.02
    # A new prior: the last scan is no longer the belief's.
    fitting.set_prior(truth, np.diag([0.01, 0.01, 0.01]))
    plain.set_prior(truth, np.diag([0.01, 0.01, 0.01]))
    assert fitting.estimate(0.3, 0.2).pose == plain.estimate(0.3, 0.2).pose
