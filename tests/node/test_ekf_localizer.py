"""ekf_localizer in-process: odometry and landmark clouds in, the poses the offline filter
computes from the same events out; bad input dropped and counted; parameters validated."""

from __future__ import annotations

import math

import numpy as np
import pytest
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from rclpy.parameter import Parameter
from sensor_msgs.msg import PointCloud2, PointField
from std_srvs.srv import Trigger

from estimation_nodes.core.kalman.landmarks import LandmarkLocalization
from estimation_nodes.nodes.ekf_localizer import EkfLocalizer, landmark_points
from estimation_nodes.nodes.grid_messages import covariance_3x3, planar_pose
from estimation_nodes.nodes.parameters import ConfigurationError
from estimation_nodes.nodes.qos import INPUT_QOS
from estimation_nodes.params.landmarks import build_ekf_localizer_settings
from estimation_nodes.params.specs import EKF_LOCALIZER_SPECS, spec_defaults
from tests.conftest import spin_until
from tests.unit.test_landmark_filters import LANDMARKS, simulated_events

T0 = 1_700_000_000.0      # stamps as a real robot's: Unix time


@pytest.fixture
def landmarks_file(tmp_path):
    path = tmp_path / "landmarks.yaml"
    path.write_text("landmarks:\n" + "".join(f"  - {{id: {k}, x: {x}, y: {y}}}\n"
                                             for k, (x, y) in LANDMARKS.items()))
    return path


@pytest.fixture
def localizer(context, executor, landmarks_file):
    made = []

    def make(**values):
        values.setdefault("landmarks_file", str(landmarks_file))
        values.setdefault("autostart", True)
        node = EkfLocalizer(context=context, parameter_overrides=[
            Parameter(k, value=v) for k, v in values.items()])
        executor.add_node(node)
        made.append(node)
        return node

    yield make
    for node in made:
        node.destroy_node()


def stamp(header, t: float) -> None:
    ns = int(round(t * 1e9))
    header.stamp.sec, header.stamp.nanosec = divmod(ns, 1_000_000_000)


def odom(t: float, v: float, w: float) -> Odometry:
    msg = Odometry()
    stamp(msg.header, t)
    msg.twist.twist.linear.x, msg.twist.twist.angular.z = v, w
    return msg


def cloud(t: float, observations) -> PointCloud2:
    msg = PointCloud2()
    stamp(msg.header, t)
    msg.header.frame_id = "camera"
    msg.fields = [PointField(name=n, offset=4 * i, datatype=d, count=1) for i, (n, d) in
                  enumerate([("x", 7), ("y", 7), ("z", 7), ("id", 6)])]
    msg.height, msg.width, msg.point_step = 1, len(observations), 16
    msg.row_step = 16 * len(observations)
    points = np.zeros(len(observations), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"),
                                                ("id", "<u4")])
    for i, o in enumerate(observations):
        points[i] = (o.range * math.cos(o.bearing), o.range * math.sin(o.bearing), 0, o.landmark)
    msg.data = points.tobytes()
    return msg


def offline(events, values):
    """The filter over the same events as the node receives them (ranges and bearings from
    the cloud's float32 x and y), in stamp order."""
    settings = build_ekf_localizer_settings(values, LANDMARKS)
    localization = LandmarkLocalization(settings.model, settings.initial_pose,
                                        settings.initial_covariance, T0 + events[0][0])
    for t, kind, data in sorted(events, key=lambda e: (e[0], e[1] == "frame")):
        if kind == "odom":
            localization.on_odometry(T0 + t, *data)
        else:
            localization.on_frame(T0 + t, landmark_points(cloud(T0 + t, data)))
    return localization


@pytest.mark.parametrize("kind, scale_std", [("ekf", 0.0), ("ukf", 0.0), ("ekf", 0.05),
                                             ("ukf", 0.05)])
@pytest.mark.timeout(300)
def test_the_published_pose_is_the_offline_filter_s(localizer, collector_factory, executor,
                                                    landmarks_file, kind, scale_std):
    # All 20 s of events at once, the two topics taken in whatever order: a horizon as
    # long as the run lets every late event take its place. With scale_std the range's
    # scale is a fourth state: the pose published is the state's pose part.
    node = localizer(filter=kind, initial_pose=[0.0, 0.0, 0.3],
                     initial_covariance=[0.04, 0.04, 0.02], reorder_horizon=30.0,
                     range_scale_std=scale_std)
    seen = collector_factory({"pose": PoseWithCovarianceStamped})
    publisher_node = seen.node
    odom_pub = publisher_node.create_publisher(Odometry, "odom", INPUT_QOS)
    cloud_pub = publisher_node.create_publisher(PointCloud2, "landmark_observations", INPUT_QOS)
    assert spin_until(executor, lambda: odom_pub.get_subscription_count() == 1
                      and cloud_pub.get_subscription_count() == 1 and seen.all_matched(), 10)
    events = simulated_events(4, seconds=20.0)
    for t, kind_, data in events:
        if kind_ == "odom":
            odom_pub.publish(odom(T0 + t, *data))
        else:
            cloud_pub.publish(cloud(T0 + t, data))
    # Each late event recomputes the filter from its place on: with the UKF and both cores
    # busy, more than a minute.
    assert spin_until(executor, lambda: node.handled["odom"] + node.handled["frame"]
                      == len(events), 240), node.handled
    values = {**spec_defaults(EKF_LOCALIZER_SPECS), "filter": kind,
              "landmarks_file": str(landmarks_file), "initial_pose": [0.0, 0.0, 0.3],
              "initial_covariance": [0.04, 0.04, 0.02], "reorder_horizon": 30.0,
              "range_scale_std": scale_std}
    expected = offline(events, values)
    assert expected.x.size == (4 if scale_std else 3)
    np.testing.assert_allclose(node.localization.x, expected.x, atol=1e-12)
    np.testing.assert_allclose(node.localization.P, expected.P, atol=1e-12)
    assert spin_until(executor, lambda: seen.count("pose") >= 1, 10)
    last_t = T0 + events[-1][0]
    assert spin_until(executor, lambda: abs(
        seen.messages["pose"][-1].header.stamp.sec
        + seen.messages["pose"][-1].header.stamp.nanosec * 1e-9 - last_t) < 1e-6, 10)
    published = seen.messages["pose"][-1]
    np.testing.assert_allclose(planar_pose(published.pose.pose)[:2], expected.x[:2], atol=1e-9)
    np.testing.assert_allclose(covariance_3x3(published.pose.covariance),
                               expected.pose_covariance, atol=1e-12)
    assert published.header.frame_id == "map"
    assert node.localization.counts == expected.counts
    assert "events_too_late" not in node.handled


def test_bad_messages_are_dropped_and_counted_and_change_nothing(localizer, executor,
                                                                 collector_factory):
    node = localizer()
    helper = collector_factory({}).node
    odom_pub = helper.create_publisher(Odometry, "odom", INPUT_QOS)
    cloud_pub = helper.create_publisher(PointCloud2, "landmark_observations", INPUT_QOS)
    assert spin_until(executor, lambda: odom_pub.get_subscription_count() == 1
                      and cloud_pub.get_subscription_count() == 1, 10)
    odom_pub.publish(odom(T0, 0.1, 0.0))
    assert spin_until(executor, lambda: node.handled["odom"] == 1, 10)
    before = (node.localization.x.copy(), node.localization.P.copy(), node.localization.t)
    broken = cloud(T0 + 1, [])
    broken.fields = broken.fields[:2]
    cloud_pub.publish(broken)
    odom_pub.publish(odom(T0 + 1, math.nan, 0.0))
    truncated = cloud(T0 + 1, [])
    truncated.width = 5
    cloud_pub.publish(truncated)
    assert spin_until(executor, lambda: sum(node.rejected.values()) == 3, 10), node.rejected
    assert node.rejected == {"malformed_landmarks": 2, "bad_odom": 1}
    np.testing.assert_array_equal(node.localization.x, before[0])
    np.testing.assert_array_equal(node.localization.P, before[1])
    from tests.unit.test_landmark_filters import Observation

    cloud_pub.publish(cloud(T0 + 2, [Observation(99, 2.0, 0.1)]))
    assert spin_until(executor, lambda: node.localization.counts["unknown"] == 1, 10)


def test_a_landmarks_file_is_needed_and_checked(localizer, tmp_path):
    with pytest.raises(ConfigurationError, match="landmarks_file"):
        localizer(landmarks_file="")
    bad = tmp_path / "bad.yaml"
    bad.write_text("landmarks:\n  - {id: 6, x: 1.0}\n")
    with pytest.raises(ConfigurationError, match="expected {id, x, y}"):
        localizer(landmarks_file=str(bad))
    twice = tmp_path / "twice.yaml"
    twice.write_text("landmarks:\n  - {id: 6, x: 1.0, y: 2}\n  - {id: 6, x: 0, y: 0}\n")
    with pytest.raises(ConfigurationError, match="given twice"):
        localizer(landmarks_file=str(twice))


def test_parameters_are_validated_at_run_time_and_reset_restarts(localizer, executor):
    node = localizer()
    assert not node.set_parameters([Parameter("gate_probability", value=0.2)])[0].successful
    assert not node.set_parameters([Parameter("initial_covariance",
                                              value=[1.0, -1.0, 1.0])])[0].successful
    assert not node.set_parameters([Parameter("filter", value="ukf")])[0].successful
    assert node.set_parameters([Parameter("range_std", value=0.2)])[0].successful
    assert node._settings.model.range_std == 0.2
    assert node.get_parameter("initial_pose").type_ == Parameter.Type.DOUBLE_ARRAY
    client = node.create_client(Trigger, "~/reset")
    assert client.wait_for_service(timeout_sec=5)
    future = client.call_async(Trigger.Request())
    assert spin_until(executor, future.done, 10) and future.result().success
    assert node.localization is None


@pytest.mark.timeout(60)
def test_waits_for_its_lifecycle_and_puts_map_to_odom_on_tf(localizer, collector_factory,
                                                             executor, context):
    """Unconfigured until a lifecycle manager configures and activates it; then after an
    odometry message, map -> odom on /tf composed with that message's pose is the pose."""
    import rclpy.node
    from tf2_msgs.msg import TFMessage

    from estimation_nodes.core.transforms.rigid import Transform
    from estimation_nodes.nodes.grid_messages import fill_pose
    from estimation_nodes.nodes.tf import TF_QOS, from_message

    node = localizer(autostart=False, transform_tolerance=0.0)
    seen = collector_factory({"pose": PoseWithCovarianceStamped, "/tf": (TFMessage, TF_QOS)})
    sender = rclpy.node.Node("odom_source", context=context)
    executor.add_node(sender)
    publisher = sender.create_publisher(Odometry, "odom", INPUT_QOS)
    assert not node.active and not node.configured_handles         # nothing made before configure
    node.trigger_configure()
    assert node.configured_handles and not node.active
    node.trigger_activate()
    assert node.active
    assert spin_until(executor, lambda: publisher.get_subscription_count() > 0, 10.0)
    msg = odom(T0, 0.5, 0.1)
    fill_pose(msg.pose.pose, 3.0, -1.0, 0.7)       # where the wheels think the robot is
    publisher.publish(msg)
    assert spin_until(executor, lambda: seen.count("pose") and seen.count("/tf"), 10.0)
    pose = planar_pose(seen.messages["pose"][-1].pose.pose)
    parent, child, stamp_ns, map_odom = from_message(seen.messages["/tf"][-1].transforms[0])
    assert (parent, child, stamp_ns) == ("map", "odom", int(T0 * 1e9))
    composed = (map_odom * Transform.planar(3.0, -1.0, 0.7)).as_planar()
    np.testing.assert_allclose(composed[:2], pose[:2], atol=1e-9)
    assert abs(math.remainder(composed[2] - pose[2], 2 * math.pi)) < 1e-9
