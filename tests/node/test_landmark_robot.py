"""landmark_robot and ekf_localizer in one process: the simulated robot's odometry and
camera frames, and the localizer following it by its landmarks where odometry alone
drifts."""

from __future__ import annotations

import math

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from rclpy.parameter import Parameter
from sensor_msgs.msg import PointCloud2

from estimation_nodes.nodes.ekf_localizer import EkfLocalizer
from estimation_nodes.nodes.grid_messages import planar_pose
from estimation_nodes.nodes.landmark_messages import landmark_points
from estimation_nodes.nodes.landmark_robot import LandmarkRobot
from estimation_nodes.nodes.parameters import ConfigurationError
from estimation_nodes.nodes.qos import INPUT_QOS, latched_qos
from tests.conftest import spin_until

NOISY = {"noise.translation_per_m": 4e-3, "noise.rotation_per_rad": 0.05,
         "noise.rotation_per_s": 5e-3}


def stamp_ns(msg) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


@pytest.fixture
def nodes(context, executor):
    made = []

    def make(node_class, **values):
        values.setdefault("landmarks_file", "landmarks_room.yaml")
        node = node_class(context=context, parameter_overrides=[
            Parameter(k, value=v) for k, v in values.items()])
        executor.add_node(node)
        made.append(node)
        return node

    yield make
    for node in made:
        node.destroy_node()


@pytest.mark.parametrize("kind", ["ekf", "ukf"])
def test_the_localizer_follows_the_robot_where_odometry_drifts(nodes, executor,
                                                               collector_factory, kind):
    seen = collector_factory({"pose": PoseWithCovarianceStamped,
                              "true_pose": (PoseStamped, latched_qos(1000)),
                              "odom": (Odometry, INPUT_QOS)})
    localizer = nodes(EkfLocalizer, filter=kind, initial_covariance=[0.01, 0.01, 0.01],
                      autostart=True,
                      **NOISY)
    nodes(LandmarkRobot, seed=11, rate_hz=50.0, camera_rate_hz=5.0, **NOISY)
    assert spin_until(executor, lambda: localizer.handled["frame"] >= 60, 90), \
        localizer.handled
    truths = {stamp_ns(m): planar_pose(m.pose) for m in seen.messages["true_pose"]}
    errors, drifts = [], []
    odometry = {stamp_ns(m): planar_pose(m.pose.pose) for m in seen.messages["odom"]}
    for pose in seen.messages["pose"][-150:]:
        truth = truths.get(stamp_ns(pose))
        if truth is not None and stamp_ns(pose) in odometry:
            estimate = planar_pose(pose.pose.pose)
            errors.append(math.hypot(estimate[0] - truth[0], estimate[1] - truth[1]))
            dead = odometry[stamp_ns(pose)]
            drifts.append(math.hypot(dead[0] - truth[0], dead[1] - truth[1]))
    assert len(errors) > 75
    assert np.median(errors) < 0.1, np.median(errors)
    assert np.median(drifts) > 2 * np.median(errors), (np.median(drifts), np.median(errors))
    assert localizer.localization.counts["used"] > 60


def test_the_camera_sees_only_what_is_in_range_and_in_view(nodes, executor,
                                                            collector_factory):
    seen = collector_factory({"landmark_observations": (PointCloud2, INPUT_QOS)})
    # Standing at the origin, facing landmark 19 at (1.2, -0.4): 1.26 m away, in view;
    # landmark 20 at (0.1, 1.1) is 1.1 m away but 1.8 rad off the axis, 18 is behind.
    # No localizer here: the robot starts without waiting for one to hear it.
    nodes(LandmarkRobot, seed=3, hold_until_matched=False, camera_max_range=2.0,
          camera_field_of_view=0.5,
          range_std=1e-6, range_std_per_m=0.0, bearing_std=1e-6, speed=0.0, turn_rate=0.0,
          initial_pose=[0.0, 0.0, math.atan2(-0.4, 1.2)],
          **{name: 0.0 for name in ("noise.translation_per_m", "noise.translation_per_rad",
                                    "noise.translation_per_s", "noise.rotation_per_m",
                                    "noise.rotation_per_rad", "noise.rotation_per_s")})
    assert spin_until(executor, lambda: seen.count("landmark_observations") >= 3, 30)
    for cloud in seen.messages["landmark_observations"]:
        observations = landmark_points(cloud)
        assert [o.landmark for o in observations] == [19]
        assert observations[0].range == pytest.approx(math.hypot(1.2, 0.4), abs=1e-4)
        assert observations[0].bearing == pytest.approx(0.0, abs=1e-4)


def test_a_robot_without_landmarks_does_not_start(nodes):
    with pytest.raises(ConfigurationError, match="landmarks_file"):
        nodes(LandmarkRobot, landmarks_file="")
