"""``ekf_node`` and ``ukf_node``: robot_localization's nodes, taking its parameter files as
they are, over the package's fusion core.

Every parameter the file gives is taken (the node declares them from the overrides, as
the peer's inputs odom0, odom1, ... are open-ended) and read with the peer's names and
meanings (params/fusion.py); one the core does not act on yet is one warning line naming
it. The inputs ``odomN`` (nav_msgs/Odometry), ``poseN``
(geometry_msgs/PoseWithCovarianceStamped), ``twistN``
(geometry_msgs/TwistWithCovarianceStamped) and ``imuN`` (sensor_msgs/Imu) are queued as
they come; a timer at ``frequency`` on the node's clock (``/clock`` with
``use_sim_time``) runs the periodic update and publishes ``odometry/filtered``. A sensor
frame other than ``base_link_frame`` needs its mount, and a pose's frame other than
``world_frame`` its place in the world: ``sensor_mounts`` (this package's parameter,
["FRAME=x,y,z,roll,pitch,yaw", ...]) gives them, else the transform tree (``/tf_static``,
``/tf``: nodes/tf.py) at the message's time. With ``publish_tf`` the
estimate goes on ``/tf`` too: ``odom -> base_link`` when ``world_frame`` is the odom
frame, ``map -> odom`` (through the tree's ``odom -> base_link`` at the estimate's time)
when it is the map frame, stamped with the estimate's time plus
``transform_time_offset``. A pose on ``set_pose`` (geometry_msgs/PoseWithCovarianceStamped)
puts the estimate there, as the peer's topic does. With ``use_control`` the velocity
command on ``cmd_vel`` (geometry_msgs/Twist, taken at its arrival; TwistStamped with
``stamped_control``, in ``base_link_frame`` or no frame) enters each prediction
(core/fusion/control.py). With ``print_diagnostics`` the node
publishes ``/diagnostics`` every second: per input part the measurements applied, rejected
by the Mahalanobis threshold and dropped, by reason. A clock that jumps back (a bag played
again) resets the filter, as the peer does. A message with a non-finite value in what it
feeds is dropped and counted, so nothing NaN is ever published; a state that is not
finite or holds a negative variance is reset, not published.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from nav_msgs.msg import Odometry
from geometry_msgs.msg import (PoseWithCovarianceStamped, Twist, TwistStamped,
                               TwistWithCovarianceStamped)
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data, QoSProfile
from sensor_msgs.msg import Imu
from std_srvs.srv import Empty

try:   # robot_localization's own service types: its install's, or the ones pip builds
    from robot_localization.srv import SetPose, ToggleFilterProcessing
except ImportError:   # a ROS workspace without robot_localization: the topic only
    SetPose = ToggleFilterProcessing = None

from estimation_nodes.core.fusion import steps
from estimation_nodes.core.fusion.control import DroppedCommand, command_message
from estimation_nodes.core.fusion.filter import FusionFilter
from estimation_nodes.core.fusion.inputs import Mount
from estimation_nodes.core.fusion.sensors import SensorConfig, SensorInputs, gyro_biases
from estimation_nodes.core.fusion.state import quaternion_from_rpy, rotation_from_quaternion
from estimation_nodes.core.transforms.buffer import LookupFailed, TransformBuffer
from estimation_nodes.core.transforms.rigid import Transform
from estimation_nodes.nodes.diagnostics import status_array
from estimation_nodes.nodes.parameters import ConfigurationError
from estimation_nodes.nodes.process import main_for
from estimation_nodes.nodes.tf import TransformBroadcaster, TransformListener, to_message
from estimation_nodes.params.fusion import FusionConfigError, fusion_config

MESSAGE_TYPES = {"odom": Odometry, "pose": PoseWithCovarianceStamped,
                 "twist": TwistWithCovarianceStamped, "imu": Imu}
#: This package's own parameters (beyond robot_localization's).
SENSOR_MOUNTS = "sensor_mounts"
#: Seconds between /diagnostics messages (the peer's diagnostic_updater period).
DIAGNOSTICS_PERIOD = 1.0
#: The count of late measurements put in their place (smooth_lagged_data): not a problem.
LATE_SMOOTHED = "late, put in its place"
#: ... and of those older than the last set_pose or toggle off, taken at its time: asked for.
LATE_BEFORE_RESET = "late, before the last set_pose or toggle off"


def parse_mounts(entries: Sequence[str]) -> dict[str, Mount]:
    """``FRAME=x,y,z,roll,pitch,yaw`` entries (m, rad) as mounts by frame: a sensor frame's
    pose on the robot, or a pose input's frame's pose in the world frame."""
    mounts = {}
    for entry in entries:
        frame, _, numbers = entry.partition("=")
        try:
            values = [float(v) for v in numbers.split(",")]
        except ValueError:
            values = []
        if not frame or len(values) != 6 or not all(math.isfinite(v) for v in values):
            raise ConfigurationError(
                f"{SENSOR_MOUNTS}: {entry!r}: expected FRAME=x,y,z,roll,pitch,yaw (m, rad)")
        mounts[frame] = Mount.from_rpy(tuple(values[:3]), tuple(values[3:]))
    return mounts


class FusionNode(Node):
    """One robot_localization filter node (``kind`` "ekf" or "ukf")."""

    def __init__(self, kind: str = "ekf", **kwargs) -> None:
        kwargs.setdefault("automatically_declare_parameters_from_overrides", True)
        super().__init__(kwargs.pop("node_name", f"{kind}_filter_node"), **kwargs)
        params = {name: p.value for name, p in self._parameters.items()}
        try:
            self._config = fusion_config(params, kind)
            mounts = parse_mounts(params.get(SENSOR_MOUNTS, []) or [])
        except FusionConfigError as error:
            raise ConfigurationError(str(error)) from None
        for name in self._config.unsupported:
            self.get_logger().warning(f"parameter {name} is not supported yet: ignored")
        for note in self._config.notes:
            self.get_logger().warning(note)
        # The steps' kernels compiled (or loaded from numba's cache) now, not at the
        # first message.
        steps.prepare_compiled()
        self._fusion = FusionFilter(self._config.settings)
        self._given_mounts = mounts
        self._inputs = self._config.sensor_inputs(mounts)
        self.resets = 0
        self._last_published_ns = -1
        self._publisher = self.create_publisher(Odometry, "odometry/filtered", 10)
        self.tf_buffer = TransformBuffer()
        self._tf_listener = TransformListener(self, self.tf_buffer,
                                              on_jump_back=self._on_time_jump_back)
        self._tf_broadcaster = TransformBroadcaster(self) if self._config.publish_tf else None
        # Not self._subscriptions: that is rclpy's own list of the node's subscriptions.
        self._sensor_subscriptions = [self._subscribe(sensor)
                                      for sensor in self._config.sensors.values()]
        self._set_pose_subscription = self.create_subscription(
            PoseWithCovarianceStamped, "set_pose", self._on_set_pose, 1)
        self._create_services()
        if self._config.settings.control is not None:
            self._control_subscription = self.create_subscription(
                TwistStamped if self._config.stamped_control else Twist, "cmd_vel",
                self._on_command, 10)
        self._timer = self.create_timer(1.0 / self._config.frequency, self._on_timer)
        #: The counts at the last /diagnostics, to say what went wrong since.
        self._reported: dict[str, int] = {}
        if self._config.print_diagnostics:
            self._diagnostics_publisher = self.create_publisher(DiagnosticArray,
                                                                "/diagnostics", 10)
            self._diagnostics_timer = self.create_timer(DIAGNOSTICS_PERIOD,
                                                        self._publish_diagnostics)

    def _subscribe(self, sensor):
        qos = QoSProfile(depth=max(1, sensor.queue_size),
                         reliability=qos_profile_sensor_data.reliability)

        def on_message(msg) -> None:
            if not _finite(msg, sensor):
                self._inputs.drop(f"{sensor.name}: a non-finite value")
                self.get_logger().warning(
                    f"{sensor.name} ({sensor.topic}): a non-finite value: message dropped",
                    throttle_duration_sec=5.0)
                return
            for parent, frame in self._inputs.frames(sensor, msg):
                self._mount_from_tf(parent, frame, msg.header.stamp)
            self._inputs.add(sensor, msg, self._fusion)

        return self.create_subscription(MESSAGE_TYPES[sensor.kind], sensor.topic,
                                        on_message, qos)

    def _mount_from_tf(self, parent: str, frame: str, stamp) -> None:
        """``frame``'s mount in ``parent`` from the tree, unless ``sensor_mounts`` gives it;
        left unknown (the message is then dropped and counted) when the tree cannot say."""
        if frame in ("", parent) or frame in self._given_mounts:
            return
        time_ns = stamp.sec * 1_000_000_000 + stamp.nanosec
        try:
            try:
                t = self.tf_buffer.lookup(parent, frame, time_ns)
            except LookupFailed:
                t = self.tf_buffer.lookup(parent, frame)
        except LookupFailed as error:
            self._inputs.mounts.pop(frame, None)
            self.get_logger().warning(f"no mount for {frame!r}: {error}",
                                      throttle_duration_sec=5.0)
            return
        self._inputs.mounts[frame] = Mount(rotation_from_quaternion(*t.rotation),
                                           np.asarray(t.translation, dtype=float))

    def _on_command(self, msg: Twist | TwistStamped) -> None:
        """The robot's velocity command (the peer's control callbacks)."""
        try:
            command, stamp_ns = command_message(
                msg, self._config.stamped_control, self.get_clock().now().nanoseconds,
                self._config.base_link_frame)
        except DroppedCommand as why:
            self._inputs.drop(f"cmd_vel: {why}")
            self.get_logger().warning(f"cmd_vel: {why}: dropped", throttle_duration_sec=5.0)
            return
        self._fusion.command(command, stamp_ns)

    def _create_services(self) -> None:
        """The peer's services: ``reset`` (std_srvs/Empty), and ``set_pose`` and ``toggle``
        where robot_localization's types import."""
        #: Whether measurements are processed (the peer's ``toggle``).
        self.processing = True
        self._reset_service = self.create_service(Empty, "reset", self._on_reset)
        if SetPose is None:
            self.get_logger().info(
                "robot_localization's service types are not installed: no set_pose or toggle "
                "service (the set_pose topic works)")
            return
        self._set_pose_service = self.create_service(SetPose, "set_pose",
                                                     self._on_set_pose_request)
        self._toggle_service = self.create_service(ToggleFilterProcessing, "toggle",
                                                   self._on_toggle)

    def _on_set_pose_request(self, request, response):
        """The ``set_pose`` service: the topic's message, as the peer's does."""
        self._on_set_pose(request.pose)
        return response

    def _on_reset(self, request, response):
        self.get_logger().info("Received a request to reset filter.")
        self._reset()
        return response

    def _on_toggle(self, request, response):
        """Measurements processed or not; the estimate is published either way (the peer's
        ``toggle``)."""
        if request.on == self.processing:
            self.get_logger().warning("Service was called to toggle filter processing but "
                                      "state was already as requested.")
            response.status = False
        else:
            self.get_logger().info(f"Toggling filter measurement filtering to "
                                   f"{'On' if request.on else 'Off'}.")
            self.processing = request.on
            response.status = True
        return response

    def _on_set_pose(self, msg: PoseWithCovarianceStamped) -> None:
        """The estimate put at the pose (the peer's set_pose topic)."""
        self._mount_from_tf(self._config.world_frame, msg.header.frame_id, msg.header.stamp)
        if self._inputs.set_pose(msg, self._fusion, self.get_clock().now().nanoseconds):
            p = msg.pose.pose.position
            self.get_logger().info(f"set_pose: the estimate is at x {p.x:.3f} y {p.y:.3f} "
                                   f"z {p.z:.3f} in {msg.header.frame_id!r}")
        else:
            self.get_logger().warning(f"not used: {self._inputs.last_dropped}")

    def _publish_diagnostics(self) -> None:
        """The counts per input part: applied, rejected by its Mahalanobis threshold,
        dropped by reason; WARN with what was rejected or dropped since the last report."""
        counts = measurement_counts(self._fusion, self._inputs)
        problems = [f"{key}: {count - self._reported.get(key, 0)} since the last report"
                    for key, count in counts.items()
                    if not key.endswith((" applied", LATE_SMOOTHED, LATE_BEFORE_RESET))
                    and count > self._reported.get(key, 0)]
        self._reported = counts
        biases = {f"{name} gyro bias (rad/s)": " ".join(f"{v:.6f}" for v in bias)
                  for name, bias in gyro_biases(self._config.sensors, self._fusion.x).items()}
        values = {"initialized": self._fusion.initialized, "queued": self._fusion.queued,
                  "resets": self.resets, **counts, **biases}
        self._diagnostics_publisher.publish(status_array(self, "filter", values, problems))

    def _on_time_jump_back(self) -> None:
        """A clock that went back (a bag played again): start over, as the peer does."""
        self._reset()
        self.get_logger().warning("time jumped back: the filter was reset")

    def _reset(self) -> None:
        """Uninitialized, nothing queued, the inputs' first and last messages forgotten
        (their counts kept, as the filter's are: /diagnostics counts since the start)."""
        self._fusion.reset()
        dropped = self._inputs.dropped
        self._inputs = self._config.sensor_inputs(self._given_mounts)
        self._inputs.dropped = dropped
        self._last_published_ns = -1
        self.resets += 1

    def _on_timer(self) -> None:
        now_ns = self.get_clock().now().nanoseconds
        if self.processing:
            self._fusion.update(now_ns)
            self._fusion.differentiate(now_ns)
        else:
            for measurement in self._fusion.pause(now_ns):
                self._inputs.drop(f"{measurement.source}: processing toggled off")
        if not self._fusion.initialized or self._fusion.last_time_ns <= self._last_published_ns:
            return
        problem = state_problem(self._fusion.x, self._fusion.p)
        if problem:
            self.get_logger().error(f"the filter's state {problem}: resetting it")
            self._fusion.reset()
            return
        self._last_published_ns = self._fusion.last_time_ns
        odometry = self._odometry()
        self._publisher.publish(odometry)
        if self._tf_broadcaster is not None:
            self._broadcast(odometry)

    def _broadcast(self, odometry: Odometry) -> None:
        """The estimate on /tf: world -> base_link, or map -> odom when the world is the
        map (the odometry's own odom -> base_link taken out, at the estimate's time)."""
        p, q = odometry.pose.pose.position, odometry.pose.pose.orientation
        world_base = Transform((p.x, p.y, p.z), (q.x, q.y, q.z, q.w))
        stamp = self._fusion.last_time_ns + self._config.transform_time_offset_ns
        config = self._config
        if config.world_frame != config.map_frame or config.world_frame == config.odom_frame:
            self._tf_broadcaster.send([to_message(config.world_frame, config.base_link_frame,
                                                  stamp, world_base)])
            return
        try:
            odom_base = self.tf_buffer.lookup(config.odom_frame, config.base_link_frame,
                                              self._fusion.last_time_ns)
        except LookupFailed as error:
            self.get_logger().warning(f"map -> odom not published: {error}",
                                      throttle_duration_sec=5.0)
            return
        self._tf_broadcaster.send([to_message(config.map_frame, config.odom_frame, stamp,
                                              world_base * odom_base.inverse())])

    def _odometry(self) -> Odometry:
        x, p = self._fusion.x, self._fusion.p
        msg = Odometry()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(self._fusion.last_time_ns,
                                                                1_000_000_000)
        msg.header.frame_id = self._config.world_frame
        msg.child_frame_id = self._config.base_link_frame
        pose = msg.pose.pose
        pose.position.x, pose.position.y, pose.position.z = (float(v) for v in x[:3])
        qx, qy, qz, qw = quaternion_from_rpy(*(float(v) for v in x[3:6]))
        pose.orientation.x, pose.orientation.y = qx, qy
        pose.orientation.z, pose.orientation.w = qz, qw
        twist = msg.twist.twist
        twist.linear.x, twist.linear.y, twist.linear.z = (float(v) for v in x[6:9])
        twist.angular.x, twist.angular.y, twist.angular.z = (float(v) for v in x[9:12])
        msg.pose.covariance = [float(v) for v in p[:6, :6].ravel()]
        msg.twist.covariance = [float(v) for v in p[6:12, 6:12].ravel()]
        return msg


def state_problem(x: np.ndarray, p: np.ndarray) -> str | None:
    """Why the state cannot be published, None when it can: a number not finite, or a
    negative variance (the UKF's covariance can lose its positive definiteness when an
    angle goes unobserved for long, with the default alpha's weight of about -1e6)."""
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(p))):
        return "is not finite"
    if np.any(np.diag(p) < 0.0):
        return "has a negative variance"
    return None


def measurement_counts(fusion: FusionFilter, inputs: SensorInputs) -> dict[str, int]:
    """"<part> applied" and "<part> rejected" for each part that has reached the filter,
    "<part> dropped: <reason>" for each reason a part was dropped for."""
    counts = fusion.counts
    values = {}
    for source in sorted(set(counts.applied) | set(counts.rejected)):
        values[f"{source} applied"] = counts.applied.get(source, 0)
        values[f"{source} rejected"] = counts.rejected.get(source, 0)
    for source, count in sorted(counts.smoothed.items()):
        values[f"{source} {LATE_SMOOTHED}"] = count
    for source, count in sorted(counts.beyond_history.items()):
        values[f"{source} late, older than history_length"] = count
    for source, count in sorted(counts.before_floor.items()):
        values[f"{source} {LATE_BEFORE_RESET}"] = count
    for reason, count in sorted(inputs.dropped.items()):
        part, _, why = reason.partition(": ")
        values[f"{part} dropped: {why}"] = count
    return values


def _finite(msg, sensor: SensorConfig) -> bool:
    """Whether every number the fusion may read of ``msg`` is finite."""
    if isinstance(msg, Imu):
        values = [msg.orientation.x, msg.orientation.y, msg.orientation.z, msg.orientation.w,
                  msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z,
                  msg.linear_acceleration.x, msg.linear_acceleration.y,
                  msg.linear_acceleration.z, *msg.orientation_covariance,
                  *msg.angular_velocity_covariance, *msg.linear_acceleration_covariance]
        return all(math.isfinite(v) for v in values)
    values = []
    if sensor.measures_pose:
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        values += [p.x, p.y, p.z, q.x, q.y, q.z, q.w, *msg.pose.covariance]
    if sensor.measures_twist:
        t = msg.twist.twist
        values += [t.linear.x, t.linear.y, t.linear.z, t.angular.x, t.angular.y, t.angular.z,
                   *msg.twist.covariance]
    return all(math.isfinite(v) for v in values)


class EkfNode(FusionNode):
    node_name = "ekf_filter_node"

    def __init__(self, **kwargs) -> None:
        super().__init__("ekf", **kwargs)


class UkfNode(FusionNode):
    node_name = "ukf_filter_node"

    def __init__(self, **kwargs) -> None:
        super().__init__("ukf", **kwargs)


ekf_main = main_for(EkfNode)
ukf_main = main_for(UkfNode)
