"""A lost landmark filter placed again by one frame of two landmarks or more."""

from __future__ import annotations

import math

import numpy as np
import pytest

from estimation_nodes.core.kalman import range_bearing, relocalization, ukf
from estimation_nodes.core.kalman.landmarks import LandmarkLocalization, LandmarkModel, Observation
from estimation_nodes.core.kalman.range_bearing import EUCLIDEAN, Ranging, SensorPose
from estimation_nodes.core.kalman.unicycle import UnicycleNoise, wrap

SENSOR = SensorPose(-0.03, 0.01, 0.02)
DEPTH = Ranging("depth", 1.03)
LANDMARKS = {1: (2.0, 1.0), 2: (-1.5, 2.5), 3: (0.5, -2.0), 4: (3.0, -1.0), 5: (2.5, 2.5)}
NOISE = UnicycleNoise(4e-4, 3e-3, 1e-6, 1e-4, 1.2e-2, 1.2e-3)


def R(measured_range: float) -> np.ndarray:
    return np.diag([(0.01 + 0.015 * measured_range) ** 2, 0.016 ** 2])


def sightings(pose, ranging, ids=LANDMARKS, rng=None):
    """The landmarks of ``ids`` as the sensor on ``pose`` sees them (noise from ``rng``)."""
    seen = []
    for key in ids:
        z = range_bearing.expected(np.append(pose, ranging.scale), LANDMARKS[key], SENSOR,
                                   ranging)
        if rng is not None:
            z = z + rng.normal(0.0, np.sqrt(np.diag(R(z[0]))))
        if z[0] > 0.2 and abs(z[1]) < 1.2:
            seen.append((key, z))
    return seen


def place(sightings, ranging, scale_variance=0.0):
    return relocalization.place(sightings, SENSOR, ranging, np.array([ranging.scale]),
                                np.array([[scale_variance]]), R, 0.999)


@pytest.mark.parametrize("ranging", [EUCLIDEAN, DEPTH], ids=["distance", "depth"])
def test_two_landmarks_or_more_give_the_exact_pose_where_the_frame_is_exact(ranging):
    rng = np.random.default_rng(3)
    placed = 0
    for _ in range(200):
        pose = np.array([*rng.uniform(-1, 1.5, 2), rng.uniform(-math.pi, math.pi)])
        seen = sightings(pose, ranging)
        found = place([(LANDMARKS[k], z) for k, z in seen], ranging)
        if len(seen) < 2:
            assert found is None
            continue
        placed += 1
        np.testing.assert_allclose(found[0][:2], pose[:2], atol=1e-9)
        assert abs(wrap(found[0][2] - pose[2])) < 1e-9
        assert np.all(np.linalg.eigvalsh(found[1]) > 0)
    assert placed > 50


def test_a_noisy_frame_places_the_robot_near_its_pose_with_the_covariance_of_its_error():
    rng = np.random.default_rng(4)
    errors, nees = [], []
    for _ in range(400):
        pose = np.array([*rng.uniform(-1, 1.5, 2), rng.uniform(-math.pi, math.pi)])
        seen = sightings(pose, DEPTH, rng=rng)
        found = place([(LANDMARKS[k], z) for k, z in seen], DEPTH)
        if len(seen) >= 3 and found is not None:
            error = found[0] - pose
            error[2] = wrap(error[2])
            errors.append(np.hypot(error[0], error[1]))
            nees.append(error @ np.linalg.solve(found[1], error))
    assert len(errors) > 60 and np.median(errors) < 0.1
    # the normalized error of a 3-dof pose averages 3 where the covariance is its spread
    assert 2.0 < np.mean(nees) < 4.5, np.mean(nees)


def test_a_frame_that_cannot_place_the_robot_places_nothing():
    pose = np.array([0.2, 0.1, 0.4])
    seen = dict(sightings(pose, DEPTH))
    assert len(seen) >= 3
    one = [(LANDMARKS[1], seen[1])]
    twice = [(LANDMARKS[1], seen[1]), (LANDMARKS[1], seen[1])]
    for frame in (one, twice, []):
        assert place(frame, DEPTH) is None
    # a misidentified landmark: the frame's points are not where the map has them
    swapped = [(LANDMARKS[2] if key == 1 else LANDMARKS[key], z) for key, z in seen.items()]
    assert place(swapped, DEPTH) is None


@pytest.mark.parametrize("dof, exact", [(1, 10.828), (3, 16.266), (9, 27.877)])
def test_the_chi_square_quantile_is_close_to_the_tables(dof, exact):
    assert relocalization.chi_square_quantile(dof, 0.999) == pytest.approx(exact, rel=0.04)
    assert relocalization.chi_square_quantile(dof, 1.0) == math.inf


def kidnapped_events(pose, seconds, ids):
    """A robot standing at ``pose``: odometry at rest, frames of ``ids`` at 3 Hz."""
    rng = np.random.default_rng(5)
    events = []
    for step in range(int(seconds * 3)):
        t = step / 3
        events.append((t, "odom", (0.0, 0.0)))
        frame = [Observation(k, *z) for k, z in sightings(pose, DEPTH, ids, rng)]
        events.append((t + 0.01, "frame", frame))
    return events


def model(kind):
    points = ukf.SigmaPoints(0.5, 2.0, 0.0) if kind == "ukf" else None
    return LandmarkModel(kind, NOISE, 0.01, 0.015, 0.016, SENSOR, LANDMARKS, 0.999, 2.0,
                         (1.0, 0.5), points, DEPTH)


@pytest.mark.parametrize("kind", ["ekf", "ukf"])
def test_a_kidnapped_filter_is_placed_again_by_a_frame_after_recovery_time(kind):
    pose = np.array([0.3, -0.2, 0.5])
    # confident, 2.5 m and 120 degrees from where the robot stands
    localization = LandmarkLocalization(model(kind), (-1.5, 1.2, 0.5 + 2.1),
                                        np.diag([1e-4, 1e-4, 1e-4]), 0.0)
    placed_at = None
    for t, kind_of_event, data in kidnapped_events(pose, 6.0, LANDMARKS):
        if kind_of_event == "odom":
            localization.on_odometry(t, *data)
            continue
        localization.on_frame(t, data)
        if placed_at is None and localization.counts["relocalized"]:
            placed_at = t
    assert placed_at is not None and 2.0 <= placed_at < 2.5, placed_at
    assert localization.counts["relocalized"] == 1 and localization.counts["recoveries"] == 0
    assert np.hypot(*(localization.pose[:2] - pose[:2])) < 0.05
    assert abs(wrap(localization.pose[2] - pose[2])) < math.radians(2)


def test_frames_of_one_landmark_leave_the_recovery_to_the_widening():
    pose = np.array([0.3, -0.2, 0.5])
    localization = LandmarkLocalization(model("ekf"), (0.0, 0.4, 0.5 - 0.6),
                                        np.diag([1e-4, 1e-4, 1e-4]), 0.0)
    for t, kind_of_event, data in kidnapped_events(pose, 6.0, [1]):
        if kind_of_event == "odom":
            localization.on_odometry(t, *data)
        else:
            localization.on_frame(t, data)
    assert localization.counts["relocalized"] == 0 and localization.counts["recoveries"] >= 1


@pytest.mark.parametrize("kind", ["ekf", "ukf"])
def test_the_frame_that_places_the_robot_is_not_applied_again(kind):
    # the placed pose and covariance are the frame's information: applied once
    pose = np.array([0.3, -0.2, 0.5])
    localization = LandmarkLocalization(model(kind), (-1.5, 1.2, 2.6),
                                        np.diag([1e-4, 1e-4, 1e-4]), 0.0)
    frame = [Observation(k, *z) for k, z in sightings(pose, DEPTH, rng=np.random.default_rng(6))]
    outcomes = localization.on_frame(3.0, frame)      # after recovery_time unused
    found = relocalization.place([(LANDMARKS[o.landmark], np.array([o.range, o.bearing]))
                                  for o in frame], SENSOR, DEPTH, np.zeros(0),
                                 np.zeros((0, 0)), R, 0.999)
    assert found is not None and localization.counts["relocalized"] == 1
    np.testing.assert_array_equal(localization.pose, found[0])
    np.testing.assert_array_equal(localization.pose_covariance, found[1])
    assert [o.verdict for o in outcomes] == ["used"] * len(frame)


def test_what_cannot_place_is_left_out_and_the_rest_places():
    pose = np.array([-1.0, 0.0, 0.0])             # four landmarks in view
    good = [Observation(k, *z) for k, z in sightings(pose, DEPTH)]
    assert len(good) >= 4
    bad = [Observation(good[0].landmark, 9.0, 0.1),      # an id twice: both copies out
           Observation(99, 2.0, 0.1),                     # not on the map
           Observation(good[1].landmark, math.nan, 0.0)]  # no range, and an id twice
    localization = LandmarkLocalization(model("ekf"), (-1.5, 1.2, 2.6),
                                        np.diag([1e-4, 1e-4, 1e-4]), 0.0)
    outcomes = localization.on_frame(3.0, good + bad)
    assert localization.counts["relocalized"] == 1
    # placed by good[2:] alone, exact frames: exactly where the robot is
    assert np.hypot(*(localization.pose[:2] - pose[:2])) < 1e-9
    assert [o.verdict for o in outcomes[2:len(good)]] == ["used"] * (len(good) - 2)
    assert outcomes[len(good) + 1].verdict == "unknown"
    assert outcomes[len(good) + 2].verdict == "invalid"
    assert len(outcomes) == len(good) + len(bad)
