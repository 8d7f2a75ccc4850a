"""ekf_node / ukf_node in-process: robot_localization's parameters in, odometry/filtered out,
equal to the core's loop on the same messages; pose inputs placed in the world frame; bad
input dropped, never a NaN published."""

from __future__ import annotations

import math

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from rclpy.parameter import Parameter
import rclpy.node
from rclpy.qos import QoSProfile, qos_profile_sensor_data

from estimation_nodes.core.fusion.state import quaternion_from_rpy
from estimation_nodes.core.transforms.rigid import Transform
from estimation_nodes.nodes.fusion_node import FusionNode
from estimation_nodes.nodes.parameters import ConfigurationError
from estimation_nodes.nodes.tf import StaticTransformBroadcaster, to_message
from tests.conftest import spin_until

TWIST_CONFIG = [False] * 6 + [True, True, True, False, False, True] + [False] * 3


def odom(t_ns: int, vx: float, wz: float) -> Odometry:
    msg = Odometry()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(t_ns, 1_000_000_000)
    msg.header.frame_id, msg.child_frame_id = "odom", "base_link"
    msg.twist.twist.linear.x = vx
    msg.twist.twist.angular.z = wz
    msg.twist.covariance = list(np.diag([1e-3, 1e-3, 1e-3, 1e3, 1e3, 1e-2]).ravel())
    return msg


@pytest.fixture
def fusion_node(context, executor):
    made = []

    def make(kind="ekf", **values):
        values.setdefault("odom0", "wheel/odom")
        values.setdefault("odom0_config", TWIST_CONFIG)
        values.setdefault("frequency", 50.0)
        node = FusionNode(kind, context=context, parameter_overrides=[
            Parameter(k, value=v) for k, v in values.items()])
        executor.add_node(node)
        made.append(node)
        return node

    yield make
    for node in made:
        node.destroy_node()


@pytest.mark.parametrize("kind", ["ekf", "ukf"])
def test_odometry_in_gives_a_moving_finite_estimate_out(fusion_node, collector_factory,
                                                        context, executor, kind):
    node = fusion_node(kind)
    collector = collector_factory({"odometry/filtered": (Odometry, QoSProfile(depth=100))})
    sender = rclpy.node.Node("odom_source", context=context)
    executor.add_node(sender)
    publisher = sender.create_publisher(Odometry, "wheel/odom", qos_profile_sensor_data)
    assert spin_until(executor, lambda: publisher.get_subscription_count() > 0, 10.0)
    t0 = node.get_clock().now().nanoseconds
    sent = 0

    def more() -> bool:
        nonlocal sent
        # One message per turn, stamped 20 ms apart from now on: 1 m/s forward.
        publisher.publish(odom(t0 + sent * 20_000_000, 1.0, 0.0))
        sent += 1
        poses = collector.messages["odometry/filtered"]
        return bool(poses) and poses[-1].pose.pose.position.x > 0.2

    assert spin_until(executor, more, 30.0)
    last = collector.messages["odometry/filtered"][-1]
    assert last.header.frame_id == "odom" and last.child_frame_id == "base_link"
    assert all(math.isfinite(v) for v in last.pose.covariance)
    assert last.twist.twist.linear.x == pytest.approx(1.0, abs=0.05)


def test_a_nan_reading_is_dropped_and_counted(fusion_node, context, executor):
    node = fusion_node()
    bad = odom(1_000_000_000, float("nan"), 0.0)
    node._sensor_subscriptions[0].callback(bad)
    assert node._inputs.dropped == {"odom0: a non-finite value": 1}
    assert node._fusion.queued == 0


def test_a_bad_parameter_stops_the_node_with_its_name(fusion_node):
    with pytest.raises(ConfigurationError, match="odom0_config: expected 15 booleans"):
        fusion_node(odom0_config=[True, False])
    with pytest.raises(ConfigurationError, match="sensor_mounts"):
        fusion_node(sensor_mounts=["imu_link=1,2"])


def test_a_clock_that_jumps_back_resets_the_filter(fusion_node, make_node, executor):
    """A bag played again (--loop): the peer resets on a jump back in time; so does ours."""
    from rosgraph_msgs.msg import Clock

    node = fusion_node(use_sim_time=True)
    clock = make_node("clock_source").create_publisher(Clock, "/clock", 10)

    def at(seconds: int) -> bool:
        msg = Clock()
        msg.clock.sec = seconds
        clock.publish(msg)
        return node.get_clock().now().nanoseconds == seconds * 1_000_000_000

    assert spin_until(executor, lambda: at(100), 10.0)
    node._sensor_subscriptions[0].callback(odom(100_000_000_000, 1.0, 0.0))
    assert spin_until(executor, lambda: at(101) and node._fusion.initialized, 10.0)
    assert spin_until(executor, lambda: at(5) and node.resets == 1, 10.0)
    assert not node._fusion.initialized


def pose_stamped(t_ns: int, frame: str, position, yaw: float) -> PoseWithCovarianceStamped:
    msg = PoseWithCovarianceStamped()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(t_ns, 1_000_000_000)
    msg.header.frame_id = frame
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    p.x, p.y, p.z = position
    q.x, q.y, q.z, q.w = quaternion_from_rpy(0.0, 0.0, yaw)
    msg.pose.covariance = list(np.diag([1e-2, 1e-2, 1e-2, 1e-3, 1e-3, 1e-3]).ravel())
    return msg


#: A pose input's frame in odom: 10 m east, 2 m south, turned 90 degrees.
GPS_ORIGIN = Transform((10.0, -2.0, 0.0), quaternion_from_rpy(0.0, 0.0, math.pi / 2))


@pytest.mark.parametrize("placed_by", ["sensor_mounts", "tf_static"])
def test_a_pose_input_is_placed_in_the_world_frame(fusion_node, collector_factory, make_node,
                                                   context, executor, placed_by):
    values = {"pose0": "gps/pose", "pose0_config": [True, True, False, False, False, True] +
              [False] * 9}
    if placed_by == "sensor_mounts":
        values["sensor_mounts"] = [f"gps_origin=10,-2,0,0,0,{math.pi / 2!r}"]
    else:
        StaticTransformBroadcaster(make_node("gps_mount")).send(
            [to_message("odom", "gps_origin", 0, GPS_ORIGIN)])
    node = fusion_node(**values)
    if placed_by == "tf_static":
        assert spin_until(executor, lambda: node.tf_buffer.can_transform("odom", "gps_origin"),
                          10.0)
    collector = collector_factory({"odometry/filtered": (Odometry, QoSProfile(depth=100))})
    publisher = make_node("gps").create_publisher(PoseWithCovarianceStamped, "gps/pose",
                                                  qos_profile_sensor_data)
    assert spin_until(executor, lambda: publisher.get_subscription_count() > 0, 10.0)
    t0 = node.get_clock().now().nanoseconds

    def published() -> bool:
        publisher.publish(pose_stamped(t0, "gps_origin", (3.0, 1.0, 0.0), 0.2))
        return bool(collector.messages["odometry/filtered"])

    assert spin_until(executor, published, 10.0)
    last = collector.messages["odometry/filtered"][-1].pose.pose
    # (3, 1) turned 90 degrees is (-1, 3); plus the origin (10, -2).
    assert (last.position.x, last.position.y) == pytest.approx((9.0, 1.0), abs=1e-9)
    q = last.orientation
    assert 2.0 * math.atan2(q.z, q.w) == pytest.approx(math.pi / 2 + 0.2, abs=1e-9)
    assert node._inputs.dropped == {}


def test_a_pose_in_a_frame_with_no_place_in_the_world_is_dropped_and_counted(fusion_node):
    node = fusion_node(odom0_config=[True] * 6 + TWIST_CONFIG[6:])
    msg = odom(1_000_000_000, 1.0, 0.0)
    msg.header.frame_id = "elsewhere"
    node._sensor_subscriptions[0].callback(msg)
    assert node._inputs.dropped == {"odom0_pose: no transform from 'elsewhere' to 'odom'": 1}
    # The twist part does not depend on it: it was queued.
    assert node._fusion.queued == 1


def test_a_pose_on_set_pose_moves_the_estimate_there(fusion_node, collector_factory,
                                                    make_node, executor):
    node = fusion_node()
    collector = collector_factory({"odometry/filtered": (Odometry, QoSProfile(depth=100))})
    publisher = make_node("operator").create_publisher(PoseWithCovarianceStamped,
                                                       "set_pose", 1)
    assert spin_until(executor, lambda: publisher.get_subscription_count() > 0, 10.0)
    t0 = node.get_clock().now().nanoseconds
    node._sensor_subscriptions[0].callback(odom(t0, 0.0, 0.0))
    # As in the peer, set_pose moves an estimate: the filter has one once initialized.
    assert spin_until(executor, lambda: node._fusion.initialized, 10.0)
    publisher.publish(pose_stamped(t0 + 1, "odom", (4.0, -3.0, 0.0), 1.0))

    def at_the_set_pose() -> bool:
        poses = collector.messages["odometry/filtered"]
        return bool(poses) and poses[-1].pose.pose.position.x == pytest.approx(4.0)

    assert spin_until(executor, at_the_set_pose, 10.0)
    last = collector.messages["odometry/filtered"][-1]
    assert last.pose.pose.position.y == pytest.approx(-3.0)
    q = last.pose.pose.orientation
    assert 2.0 * math.atan2(q.z, q.w) == pytest.approx(1.0)
    assert node._fusion.counts.applied["set_pose"] == 1


def test_diagnostics_count_each_inputs_measurements_applied_rejected_and_dropped(
        fusion_node, collector_factory, executor):
    node = fusion_node(print_diagnostics=True, odom0_twist_rejection_threshold=2.0)
    collector = collector_factory({"/diagnostics": (DiagnosticArray, 10)})
    t0 = node.get_clock().now().nanoseconds - 1_000_000_000
    on_odom = node._sensor_subscriptions[0].callback
    on_odom(odom(t0, 1.0, 0.0))
    on_odom(odom(t0 + 20_000_000, 50.0, 0.0))         # 49 m/s off: beyond 2 sigma
    on_odom(odom(t0 + 10_000_000, 1.0, 0.0))          # older than the last one
    on_odom(odom(t0 + 30_000_000, math.nan, 0.0))

    def reported() -> dict[str, str]:
        statuses = [status for msg in collector.messages["/diagnostics"]
                    for status in msg.status]
        return {v.key: v.value for v in statuses[-1].values} if statuses else {}

    assert spin_until(executor, lambda: reported().get("odom0_twist rejected") == "1", 10.0)
    values = reported()
    assert {key: values[key] for key in values if key.startswith("odom0")} == {
        "odom0_twist applied": "1", "odom0_twist rejected": "1",
        "odom0_twist dropped: older than the last one": "1",
        "odom0 dropped: a non-finite value": "1"}
    status = collector.messages["/diagnostics"][-1].status[0]
    assert status.level == DiagnosticStatus.WARN
    assert "odom0_twist rejected: 1 since the last report" in status.message


@pytest.mark.parametrize("stamped", [False, True])
def test_cmd_vel_speeds_the_estimate_up_between_measurements(fusion_node, make_node, executor,
                                                             stamped):
    """use_control: one odometry reading at rest, then only commands of 1 m/s: the
    estimate's speed follows them (a TwistStamped in another frame is dropped, counted)."""
    from geometry_msgs.msg import Twist, TwistStamped

    node = fusion_node("ekf", use_control=True, stamped_control=stamped, control_timeout=0.5,
                       sensor_timeout=0.05, control_config=[True] + [False] * 5,
                       acceleration_limits=[2.0] + [0.0] * 5)
    sender = make_node("commander")
    wheels = sender.create_publisher(Odometry, "wheel/odom", qos_profile_sensor_data)
    commands = sender.create_publisher(TwistStamped if stamped else Twist, "cmd_vel", 10)
    assert spin_until(executor, lambda: wheels.get_subscription_count() > 0
                      and commands.get_subscription_count() > 0, 10.0)
    wheels.publish(odom(node.get_clock().now().nanoseconds, 0.0, 0.0))
    assert spin_until(executor, lambda: node._fusion.initialized, 10.0)

    def command(frame: str = "base_link"):
        twist = Twist()
        twist.linear.x = 1.0
        if not stamped:
            return twist
        msg = TwistStamped()
        msg.header.stamp = node.get_clock().now().to_msg()
        msg.header.frame_id, msg.twist = frame, twist
        return msg

    def faster() -> bool:
        commands.publish(command())
        return node._fusion.x[6] > 0.3

    assert spin_until(executor, faster, 20.0)
    if stamped:
        commands.publish(command("odom"))
        assert spin_until(executor, lambda: any(
            "cmd_vel: frame 'odom'" in reason for reason in node._inputs.dropped), 5.0)


def test_a_late_measurement_is_put_in_its_place_and_reported_without_a_warning(
        fusion_node, collector_factory, executor):
    """smooth_lagged_data: odom1's reading, older than odom0's already taken, goes in its
    place (the core's tests prove the arithmetic); /diagnostics counts it, and it is no
    problem."""
    node = fusion_node(print_diagnostics=True, smooth_lagged_data=True, history_length=5.0,
                       odom1="other/odom", odom1_config=TWIST_CONFIG)
    collector = collector_factory({"/diagnostics": (DiagnosticArray, 10)})
    t0 = node.get_clock().now().nanoseconds - 1_000_000_000
    on_odom0, on_odom1 = (subscription.callback
                          for subscription in node._sensor_subscriptions)
    on_odom0(odom(t0, 1.0, 0.0))
    on_odom0(odom(t0 + 40_000_000, 1.0, 0.0))
    assert spin_until(executor, lambda: node._fusion.last_time_ns == t0 + 40_000_000, 10.0)
    on_odom1(odom(t0 + 20_000_000, 1.0, 0.0))

    def reported() -> dict[str, str]:
        statuses = [status for msg in collector.messages["/diagnostics"]
                    for status in msg.status]
        return {v.key: v.value for v in statuses[-1].values} if statuses else {}

    assert spin_until(executor, lambda: reported().get(
        "odom1_twist late, put in its place") == "1", 10.0)
    assert reported()["odom1_twist applied"] == "1"
    assert collector.messages["/diagnostics"][-1].status[0].level == DiagnosticStatus.OK


def test_an_estimated_gyro_bias_is_reported_in_diagnostics(fusion_node, collector_factory,
                                                           executor):
    node = fusion_node(print_diagnostics=True, imu0="imu/data", imu0_gyro_bias=True,
                       imu0_config=[False] * 9 + [True] * 3 + [False] * 3)
    assert node._fusion.x.shape == (18,)
    collector = collector_factory({"/diagnostics": (DiagnosticArray, 10)})
    assert spin_until(executor, lambda: bool(collector.messages["/diagnostics"]), 10.0)
    values = {v.key: v.value for v in collector.messages["/diagnostics"][-1].status[0].values}
    assert values["imu0 gyro bias (rad/s)"] == "0.000000 0.000000 0.000000"


def call(executor, client, request):
    assert spin_until(executor, client.service_is_ready, 10.0)
    future = client.call_async(request)
    assert spin_until(executor, future.done, 10.0)
    return future.result()


def test_the_peers_services_set_pose_reset_and_toggle(fusion_node, make_node, executor):
    """robot_localization's types (its install's, or the ones the pip install builds)."""
    from robot_localization.srv import SetPose, ToggleFilterProcessing
    from std_srvs.srv import Empty

    node = fusion_node()
    operator = make_node("operator")
    t0 = node.get_clock().now().nanoseconds
    on_odom = node._sensor_subscriptions[0].callback
    on_odom(odom(t0, 0.0, 0.0))
    assert spin_until(executor, lambda: node._fusion.initialized, 10.0)

    request = SetPose.Request(pose=pose_stamped(t0 + 1, "odom", (4.0, -3.0, 0.0), 1.0))
    call(executor, operator.create_client(SetPose, "set_pose"), request)
    assert node._fusion.x[0] == pytest.approx(4.0) and node._fusion.x[1] == pytest.approx(-3.0)

    toggle = operator.create_client(ToggleFilterProcessing, "toggle")
    assert call(executor, toggle, ToggleFilterProcessing.Request(on=False)).status
    assert not call(executor, toggle, ToggleFilterProcessing.Request(on=False)).status
    now = node.get_clock().now().nanoseconds
    on_odom(odom(now, 1.0, 0.0))
    assert spin_until(executor, lambda: node._inputs.dropped.get(
        "odom0_twist: processing toggled off") == 1, 10.0)
    assert node._fusion.x[6] == 0.0                 # not taken
    assert call(executor, toggle, ToggleFilterProcessing.Request(on=True)).status

    def taken() -> bool:
        on_odom(odom(node.get_clock().now().nanoseconds, 1.0, 0.0))
        return node._fusion.x[6] > 0.5

    assert spin_until(executor, taken, 10.0)

    call(executor, operator.create_client(Empty, "reset"), Empty.Request())
    assert not node._fusion.initialized and node.resets == 1
    # /diagnostics counts since the start: a reset forgets the inputs' messages, not them.
    assert node._inputs.dropped["odom0_twist: processing toggled off"] == 1


def test_a_state_with_a_negative_variance_is_reset_not_published(fusion_node,
                                                                  collector_factory, executor):
    """A covariance that is no longer one (the UKF's, with an angle unobserved for long)
    is never published: the filter starts over, as for a state that is not finite. (The
    EKF's prediction keeps the broken entry negative; the UKF's could mend it first.)"""
    node = fusion_node("ekf")
    collector = collector_factory({"odometry/filtered": (Odometry, QoSProfile(depth=100))})
    t0 = node.get_clock().now().nanoseconds
    node._sensor_subscriptions[0].callback(odom(t0, 1.0, 0.0))
    assert spin_until(executor, lambda: node._fusion.initialized, 10.0)
    broken = node._fusion.p.copy()
    broken[5, 5] = -1.0
    node._fusion.p = broken
    assert spin_until(executor, lambda: not node._fusion.initialized, 10.0)
    for msg in collector.messages["odometry/filtered"]:
        assert min(msg.pose.covariance[::7]) >= 0.0
