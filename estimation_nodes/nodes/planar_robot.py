"""planar_robot: a simulated robot on a map, for the grid localizer (no map_server needed).

It reads ``map_file`` and publishes it on ``map`` (latched, as map_server
does). At ``rate_hz`` it moves: along a seeded collision-free wandering
route, or as ``cmd_vel`` (geometry_msgs/Twist) says while commands keep
coming (within 0.5 s). Each step it publishes ``odom`` (nav_msgs/Odometry,
its pose integrated from noisy motion, the localizer's own noise model),
``scan`` (sensor_msgs/LaserScan ray-cast from the true pose, with the noise
the likelihood field assumes; inf for no return, REP 117) and ``true_pose``
(geometry_msgs/PoseStamped). ``kidnap_after`` teleports it once. With
``hold_until_matched`` it starts only once the nodes of ``hold_for_nodes``
(the localizer, and a recorder if one is named) hear its odom and scan, so
they miss none of its run.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
from geometry_msgs.msg import PoseStamped, Twist
from nav_msgs.msg import OccupancyGrid, Odometry
from rclpy.node import Node
from sensor_msgs.msg import LaserScan

from estimation_nodes.core import errors
from estimation_nodes.core.sim import planar
from estimation_nodes.nodes.grid_messages import fill_pose, occupancy_grid
from estimation_nodes.nodes.held_publisher import HOLD_CHECK_PERIOD_S
from estimation_nodes.nodes.parameters import ConfigurationError, declare_and_build
from estimation_nodes.nodes.process import main_for
from estimation_nodes.nodes.qos import latched_qos
from estimation_nodes.nodes.subscribers import start_once_heard
from estimation_nodes.params import topics
from estimation_nodes.params.grid import PlanarRobotSettings, build_planar_robot_settings
from estimation_nodes.params.specs import PLANAR_ROBOT_SPECS

#: A cmd_vel older than this (s) no longer drives the robot: it wanders again.
COMMAND_TIMEOUT_S = 0.5


class PlanarRobot(Node):
    """Ground truth, odometry and a laser scan of one robot on a map."""

    node_name = "planar_robot"

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(self.node_name, **kwargs)
        try:
            _, settings = declare_and_build(self, PLANAR_ROBOT_SPECS,
                                            build_planar_robot_settings)
        except errors.MapError as error:
            raise ConfigurationError(str(error)) from None
        self._settings = settings
        occupancy = settings.map
        self._sensor, self._noise = settings.sensor, settings.noise
        self._world = planar.planar_world(occupancy)
        seed = settings.seed
        self._rng = np.random.default_rng(None if seed < 0 else seed)
        self._pose = self._initial_pose(settings)
        self._odom_pose: planar.Pose = (0.0, 0.0, 0.0)
        self._wanderer = planar.Wanderer(self._rng, settings.speed, settings.turn_rate,
                                         settings.robot_radius)
        self._command: tuple[float, float, float] | None = None    # (v, w, when)
        self._dt = 1.0 / settings.rate_hz
        self._elapsed = 0.0
        self._kidnapped = False
        beams = settings.beams
        self._angles = -math.pi + 2 * math.pi * np.arange(beams) / beams
        map_pub = self.create_publisher(OccupancyGrid, topics.MAP, latched_qos(1))
        map_pub.publish(occupancy_grid(occupancy.cells, occupancy.resolution, occupancy.origin,
                                       "map", self.get_clock().now().to_msg()))
        self._odom_pub = self.create_publisher(Odometry, topics.ODOM, 50)
        self._scan_pub = self.create_publisher(LaserScan, topics.SCAN, 10)
        self._truth_pub = self.create_publisher(PoseStamped, topics.TRUE_POSE, latched_qos(1))
        self.create_subscription(Twist, topics.CMD_VEL, self._on_cmd_vel, 10)
        self.get_logger().info(
            f"ready: map {occupancy.cells.shape[1]} x {occupancy.cells.shape[0]} cells, start "
            f"({self._pose[0]:.2f}, {self._pose[1]:.2f}, {math.degrees(self._pose[2]):.0f} "
            f"deg), seed {seed}")
        if not settings.hold_until_matched:
            self._start()
            return
        start_once_heard(self, (self._odom_pub, self._scan_pub), settings.hold_for_nodes,
                         self._start, "odom and scan", HOLD_CHECK_PERIOD_S)

    def _start(self) -> None:
        self.create_timer(self._dt, self._step)

    def _initial_pose(self, settings: PlanarRobotSettings) -> planar.Pose:
        pose = settings.initial_pose
        if pose is not None:
            if self._world.clearance_at(pose[0], pose[1]) <= settings.robot_radius:
                raise ConfigurationError(f"initial_pose: {list(pose)} is not "
                                         f"{settings.robot_radius} m from every obstacle")
            return pose
        try:
            return planar.free_place(self._world, self._rng, settings.robot_radius)
        except ValueError as error:
            raise ConfigurationError(str(error)) from None

    def _on_cmd_vel(self, msg: Twist) -> None:
        if math.isfinite(msg.linear.x) and math.isfinite(msg.angular.z):
            self._command = (msg.linear.x, msg.angular.z, time.monotonic())

    def _true_motion(self) -> tuple[float, float, float]:
        command = self._command
        if command is not None and time.monotonic() - command[2] < COMMAND_TIMEOUT_S:
            return (command[1] * self._dt / 2, command[0] * self._dt, command[1] * self._dt / 2)
        return self._wanderer.step(self._world, self._pose, self._dt)

    def _step(self) -> None:
        settings = self._settings
        if settings.duration and self._elapsed >= settings.duration:
            if settings.exit_when_done:
                raise SystemExit(0)
            return
        self._elapsed += self._dt
        delta = self._true_motion()
        moved = planar.compose(self._pose, delta)
        if self._world.clearance_at(moved[0], moved[1]) > settings.robot_radius:
            self._pose = moved
        else:
            delta = (0.0, 0.0, 0.0)        # blocked: it stays where it is
        if settings.kidnap_after and not self._kidnapped \
                and self._elapsed >= settings.kidnap_after:
            self._kidnapped = True
            self._pose = planar.free_place(self._world, self._rng, settings.robot_radius)
            self.get_logger().info(f"kidnapped to ({self._pose[0]:.2f}, {self._pose[1]:.2f})")
        self._odom_pose = planar.compose(self._odom_pose,
                                         planar.sample_odometry(delta, self._noise, self._rng))
        stamp = self.get_clock().now().to_msg()
        self._publish_odom(stamp, delta)
        self._publish_scan(stamp)
        truth = PoseStamped()
        truth.header.stamp, truth.header.frame_id = stamp, "map"
        fill_pose(truth.pose, *self._pose)
        self._truth_pub.publish(truth)

    def _publish_odom(self, stamp, delta) -> None:
        odom = Odometry()
        odom.header.stamp, odom.header.frame_id, odom.child_frame_id = stamp, "odom", "base_link"
        fill_pose(odom.pose.pose, *self._odom_pose)
        odom.twist.twist.linear.x = delta[1] / self._dt
        odom.twist.twist.angular.z = (delta[0] + delta[2]) / self._dt
        self._odom_pub.publish(odom)

    def _publish_scan(self, stamp) -> None:
        sensor = self._sensor
        # From the laser's place on the robot (laser_pose), as a mounted laser sees.
        laser = planar.sensor_at(self._pose, sensor.laser_pose)
        true_ranges = planar.ray_cast(self._world, laser, self._angles, sensor.max_range)
        ranges = planar.noisy_ranges(true_ranges, self._rng, self._settings.scan_noise_std,
                                     self._settings.scan_random_fraction, sensor.max_range)
        scan = LaserScan()
        scan.header.stamp, scan.header.frame_id = stamp, "base_link"
        scan.angle_min = float(self._angles[0])
        scan.angle_max = float(self._angles[-1])
        scan.angle_increment = float(2 * math.pi / len(self._angles))
        scan.time_increment, scan.scan_time = 0.0, self._dt
        scan.range_min, scan.range_max = 0.05, float(sensor.max_range)
        scan.ranges = ranges.astype(np.float32).tolist()
        self._scan_pub.publish(scan)


main = main_for(PlanarRobot)

if __name__ == "__main__":
    main()
