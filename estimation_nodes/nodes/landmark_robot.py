"""landmark_robot: a simulated unicycle among landmarks, for ekf_localizer.

Each step (``rate_hz``) the robot drives the twist its route commands, with errors
drawn from its ``noise.*`` parameters, and ``odom`` reports the commanded twist (as
a robot's controller does) with the pose it dead-reckons; ``true_pose`` is where it
truly is. At ``camera_rate_hz`` its camera sees the landmarks within range and
field of view, with the ``range_std``, ``range_std_per_m`` and ``bearing_std`` of
its parameters, as one ``landmark_observations`` cloud per frame. The simulator's
noise comes from its own parameters; a scenario file gives the localizer the same.
With ``hold_until_matched`` it starts only once the nodes of ``hold_for_nodes``
(the localizer, and a recorder if one is named) hear its odom and camera, so
they miss none of its run.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from sensor_msgs.msg import PointCloud2

from estimation_nodes.core.kalman import unicycle
from estimation_nodes.core.sim import landmarks as simulated
from estimation_nodes.nodes.grid_messages import fill_pose
from estimation_nodes.nodes.held_publisher import HOLD_CHECK_PERIOD_S
from estimation_nodes.nodes.landmark_messages import landmark_cloud
from estimation_nodes.nodes.parameters import declare_and_build
from estimation_nodes.nodes.process import main_for
from estimation_nodes.nodes.qos import INPUT_QOS, latched_qos
from estimation_nodes.nodes.stamps import set_stamp
from estimation_nodes.nodes.subscribers import start_once_heard
from estimation_nodes.params import topics
from estimation_nodes.params.landmarks import build_landmark_robot_settings
from estimation_nodes.params.specs import LANDMARK_ROBOT_SPECS


class LandmarkRobot(Node):
    """Odometry, camera frames and the truth of one simulated robot among landmarks."""

    node_name = "landmark_robot"

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(self.node_name, **kwargs)
        _, settings = declare_and_build(self, LANDMARK_ROBOT_SPECS,
                                        build_landmark_robot_settings)
        self._settings = settings
        self._rng = np.random.default_rng(None if settings.seed < 0 else settings.seed)
        points = np.array(list(settings.landmarks.values()))
        centre = points.mean(axis=0)
        spread = float(np.max(np.hypot(*(points - centre).T))) if len(points) > 1 else 2.0
        self._route = simulated.Wanderer(self._rng, settings.speed, settings.turn_rate,
                                         (float(centre[0]), float(centre[1])), spread)
        self._pose = settings.initial_pose.copy()
        self._odom_pose = settings.initial_pose.copy()
        self._dt = 1.0 / settings.rate_hz
        self._steps_per_frame = max(1, round(settings.rate_hz / settings.camera_rate_hz))
        self._steps = 0
        self._odom_pub = self.create_publisher(Odometry, topics.ODOM, INPUT_QOS)
        self._cloud_pub = self.create_publisher(PointCloud2, topics.LANDMARK_OBSERVATIONS,
                                                INPUT_QOS)
        self._truth_pub = self.create_publisher(PoseStamped, topics.TRUE_POSE, latched_qos(1))
        self.get_logger().info(
            f"ready: {len(settings.landmarks)} landmarks, start ({self._pose[0]:.2f}, "
            f"{self._pose[1]:.2f}, {math.degrees(self._pose[2]):.0f} deg), seed "
            f"{settings.seed}")
        if not settings.hold_until_matched:
            self._start()
            return
        start_once_heard(self, (self._odom_pub, self._cloud_pub), settings.hold_for_nodes,
                         self._start, "odom and landmark_observations", HOLD_CHECK_PERIOD_S)

    def _start(self) -> None:
        self.create_timer(self._dt, self._step)

    def _step(self) -> None:
        settings = self._settings
        if settings.duration and self._steps * self._dt >= settings.duration:
            if settings.exit_when_done:
                raise SystemExit(0)
            return
        v, w = self._route.command(self._pose, self._dt)
        self._pose = simulated.true_motion(self._pose, v, w, self._dt, settings.noise,
                                           self._rng)
        self._odom_pose = unicycle.move(self._odom_pose, v, w, self._dt)
        self._steps += 1
        stamp_ns = self.get_clock().now().nanoseconds
        self._publish_odometry(stamp_ns, v, w)
        truth = PoseStamped()
        set_stamp(truth.header, stamp_ns, "map")
        fill_pose(truth.pose, *self._pose.tolist())
        self._truth_pub.publish(truth)
        if self._steps % self._steps_per_frame == 0:
            seen = settings.camera.observe(self._pose, settings.landmarks, self._rng)
            self._cloud_pub.publish(landmark_cloud(stamp_ns, "camera", seen))

    def _publish_odometry(self, stamp_ns: int, v: float, w: float) -> None:
        odom = Odometry()
        set_stamp(odom.header, stamp_ns, "odom")
        odom.child_frame_id = "base_link"
        fill_pose(odom.pose.pose, *self._odom_pose.tolist())
        odom.twist.twist.linear.x, odom.twist.twist.angular.z = v, w
        self._odom_pub.publish(odom)


main = main_for(LandmarkRobot)

if __name__ == "__main__":
    main()
