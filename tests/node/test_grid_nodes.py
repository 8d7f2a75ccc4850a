"""grid_localizer and planar_robot in-process: localization from no prior, bad input, services."""

import math

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
from nav_msgs.msg import OccupancyGrid, Odometry
from rclpy.parameter import Parameter
from sensor_msgs.msg import LaserScan
from std_msgs.msg import Float64
from std_srvs.srv import Trigger

from estimation_nodes.core.grid import failure
from estimation_nodes.nodes.grid_localizer import GridLocalizer
from estimation_nodes.nodes.grid_messages import fill_pose, planar_pose
from estimation_nodes.nodes.parameters import ConfigurationError
from estimation_nodes.nodes.planar_robot import PlanarRobot
from estimation_nodes.nodes.qos import INPUT_QOS, latched_qos
from tests.conftest import REPO, spin_until

CORRIDOR = str(REPO / "maps" / "corridor.yaml")


#: grid_localizer as the simulator runs it: active at start, odometry from the odom topic.
STANDALONE = {"autostart": True, "odometry_source": "topic"}


def params(**values):
    return [Parameter(k, value=v) for k, v in values.items()]


@pytest.fixture
def nodes(context, executor):
    made = []

    def make(node_class, **values):
        if node_class is GridLocalizer:
            values = {**STANDALONE, **values}
        node = node_class(context=context, parameter_overrides=params(**values))
        executor.add_node(node)
        made.append(node)
        return node

    yield make
    for node in made:
        node.destroy_node()


def test_the_localizer_finds_the_simulated_robot_without_an_initial_pose(nodes, executor,
                                                                         collector_factory):
    localizer = nodes(GridLocalizer, map_file=CORRIDOR, heading_bins=36)
    seen = collector_factory({"pose": PoseWithCovarianceStamped,
                              "true_pose": (PoseStamped, latched_qos(1000)),
                              "localization_quality": Float64,
                              "belief_map": OccupancyGrid})
    # Before the robot moves: the belief uniform over the corridor, the quality low.
    assert spin_until(executor, lambda: seen.count("localization_quality") >= 1, 10.0)
    first_quality = [seen.messages["localization_quality"][0].data]
    nodes(PlanarRobot, map_file=CORRIDOR, seed=3, rate_hz=20.0)
    assert spin_until(executor, lambda: localizer.localization is not None
                      and localizer.localization.updates >= 15, 60.0)
    # Every update's duration is kept for /diagnostics' median, 99th percentile, maximum.
    assert len(localizer.update_times) == localizer.handled["scan"] >= 15
    figures = localizer.update_time_figures()
    assert 0 < figures["median"] <= figures["p99"] <= figures["max"] \
        == max(localizer.update_times) * 1e3
    # The truth when the last scan used was taken: the pose carries that scan's stamp.
    last = seen.messages["pose"][-1]
    truths = {(m.header.stamp.sec, m.header.stamp.nanosec): m for m in seen.messages["true_pose"]}
    truth = planar_pose(truths[(last.header.stamp.sec, last.header.stamp.nanosec)].pose)
    estimate = planar_pose(last.pose.pose)
    assert math.hypot(estimate[0] - truth[0], estimate[1] - truth[1]) < 0.3
    assert abs(math.remainder(estimate[2] - truth[2], 2 * math.pi)) < math.radians(10)
    # Not sure at first (uniform over the corridor), sure at the end.
    assert first_quality[0] < 0.01 and seen.messages["localization_quality"][-1].data > 0.9
    grid = seen.messages["belief_map"][-1]
    assert (grid.info.width, grid.info.height, round(grid.info.resolution, 6)) == (160, 40, 0.1)
    assert max(grid.data) == 100 and min(grid.data) >= 0
    covariance = np.array(seen.messages["pose"][-1].pose.covariance).reshape(6, 6)
    assert np.all(np.isfinite(covariance)) and covariance[0, 0] > 0 and covariance[5, 5] > 0


def scan(ranges, angle_increment=0.1):
    msg = LaserScan()
    msg.angle_min, msg.angle_increment = -math.pi, angle_increment
    msg.range_min, msg.range_max = 0.05, 12.0
    msg.ranges = [float(r) for r in ranges]
    return msg


def odom(x, y, yaw):
    msg = Odometry()
    fill_pose(msg.pose.pose, x, y, yaw)
    return msg


def drive(executor, localizer, publishers, messages):
    for topic, msg in messages:
        publishers[topic].publish(msg)
        spin_until(executor, lambda: False, 0.05)


def test_bad_messages_are_dropped_counted_and_never_make_a_nan_belief(nodes, executor,
                                                                      collector_factory):
    localizer = nodes(GridLocalizer, map_file=CORRIDOR, heading_bins=8)
    driver = collector_factory({"pose": PoseWithCovarianceStamped}, name="driver")
    publishers = {t: driver.node.create_publisher(m, t, 10) for t, m in (
        ("scan", LaserScan), ("odom", Odometry), ("initialpose", PoseWithCovarianceStamped))}
    assert spin_until(executor, lambda: all(p.get_subscription_count() for p in
                                            publishers.values()), 10.0)
    drive(executor, localizer, publishers, [
        ("odom", odom(0.0, 0.0, 0.0)),
        ("scan", scan([float("nan")] * 30 + [1.0] * 33)),      # NaN ranges: dropped beams
        ("scan", scan([1.0] * 63, angle_increment=0.0)),          # a scan with no geometry
        ("odom", odom(float("nan"), 0.0, 0.0)),
        ("odom", odom(5.0, 0.0, 0.0)),                            # a jump past max_odom_jump
        ("scan", scan([float("inf")] * 63)),                      # no return at all: fine
    ])
    assert spin_until(executor, lambda: localizer.rejected["odom_jump"] == 1, 5.0)
    assert localizer.rejected["nan_ranges"] == 30
    assert localizer.rejected["bad_scan"] == 1
    assert localizer.rejected["non_finite_odom"] == 1
    belief = localizer.localization.belief
    assert np.all(np.isfinite(belief)) and belief.sum() == pytest.approx(1.0)


def test_a_repeated_odometry_stamp_is_counted_and_the_first_pose_kept(nodes, executor,
                                                                       collector_factory):
    localizer = nodes(GridLocalizer, map_file=CORRIDOR, heading_bins=8)
    driver = collector_factory({"pose": PoseWithCovarianceStamped}, name="driver")
    wheels = driver.node.create_publisher(Odometry, "odom", 10)
    assert spin_until(executor, lambda: wheels.get_subscription_count() > 0, 10.0)
    for x in (1.0, 1.2):                        # one stamp, two poses (as real logs have)
        msg = odom(x, 0.0, 0.0)
        msg.header.stamp.sec = 7
        wheels.publish(msg)
    assert spin_until(executor, lambda: localizer.handled["odom_repeated_stamp"] == 1, 5.0)
    assert localizer.handled["odom"] == 1 and not localizer.rejected
    assert localizer.localization._odometry_at(7 * 10**9) == pytest.approx((1.0, 0.0, 0.0))


def test_odometry_that_comes_while_the_localizer_is_busy_is_all_taken(nodes, executor,
                                                                      collector_factory):
    """A real log's odometry plays at 160 Hz: an update that keeps the localizer from its
    queue for 5 s (a loaded machine) must lose none of it, or the next pose taken looks
    like a jump past max_odom_jump and is dropped. Here the executor does not spin while
    5 s of it at 200 Hz, 1 cm apart, are published; then every pose is followed."""
    localizer = nodes(GridLocalizer, map_file=CORRIDOR, heading_bins=8, max_odom_jump=1.0)
    driver = collector_factory({"pose": PoseWithCovarianceStamped}, name="driver")
    wheels = driver.node.create_publisher(Odometry, "odom", INPUT_QOS)     # holds 1000
    assert spin_until(executor, lambda: wheels.get_subscription_count() > 0, 10.0)
    poses = 1000
    for n in range(poses):
        msg = odom(1.0 + 0.01 * n, 0.5, 0.0)
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(10**9 + n * 5_000_000, 10**9)
        wheels.publish(msg)
    assert spin_until(executor, lambda: localizer.handled["odom"] == poses, 20.0), \
        (localizer.handled, localizer.rejected)
    assert not localizer.rejected


def corridor_localizer_with_driver(nodes, executor, collector_factory):
    """A localizer on the corridor, and odometry and laser publishers it hears."""
    localizer = nodes(GridLocalizer, map_file=CORRIDOR, heading_bins=8)
    driver = collector_factory({"pose": PoseWithCovarianceStamped}, name="driver")
    wheels = driver.node.create_publisher(Odometry, "odom", 10)
    laser = driver.node.create_publisher(LaserScan, "scan", 10)
    assert spin_until(executor, lambda: wheels.get_subscription_count() > 0
                      and laser.get_subscription_count() > 0, 10.0)
    return localizer, wheels, laser


def test_a_scan_waits_odom_wait_for_the_odometry_of_its_time(nodes, executor,
                                                            collector_factory):
    """A real log's odometry comes at 2 Hz in places: a scan whose odometry comes 0.5 s
    after it is answered with the default odom_wait (1 s)."""
    localizer, wheels, laser = corridor_localizer_with_driver(nodes, executor,
                                                              collector_factory)
    for stamp_s, publisher, msg in ((1, wheels, odom(1.0, 0.5, 0.0)),
                                    (2, laser, scan([1.0] * 63))):
        msg.header.stamp.sec = stamp_s
        publisher.publish(msg)
    assert spin_until(executor, lambda: bool(localizer._waiting_scans), 5.0)
    spin_until(executor, lambda: False, 0.5)           # the odometry of 2 s comes late
    late = odom(1.0, 0.5, 0.0)
    late.header.stamp.sec = 2
    wheels.publish(late)
    assert spin_until(executor, lambda: localizer.handled["scan"] == 1, 5.0), \
        (localizer.handled, localizer.rejected)
    assert not localizer.rejected


def test_scans_that_wait_together_are_taken_in_order(nodes, executor, collector_factory):
    """A real log's scans come in pairs 0.05 s apart, before the odometry of their time:
    both wait, and both are taken, in order, when it comes (none superseded)."""
    localizer, wheels, laser = corridor_localizer_with_driver(nodes, executor,
                                                              collector_factory)
    first = odom(1.0, 0.5, 0.0)
    first.header.stamp.sec = 1
    wheels.publish(first)
    assert spin_until(executor, lambda: localizer.handled["odom"] == 1, 5.0)
    for waiting, nanosec in enumerate((0, 50_000_000), start=1):
        msg = scan([1.0] * 63)
        msg.header.stamp.sec, msg.header.stamp.nanosec = 2, nanosec
        laser.publish(msg)
        assert spin_until(executor, lambda n=waiting: len(localizer._waiting_scans) == n, 5.0)
    late = odom(1.0, 0.5, 0.0)
    late.header.stamp.sec, late.header.stamp.nanosec = 2, 100_000_000
    wheels.publish(late)
    # the first updates (a localizer's first scan always does); the second, 0 m later, is
    # not due: both answered by the update rule
    assert spin_until(executor, lambda: localizer.handled["scan_without_motion"] == 1, 5.0), \
        (localizer.handled, localizer.rejected)
    assert localizer.handled["scan"] == 1 and not localizer.handled["scan_superseded"]
    assert not localizer.rejected and not localizer._waiting_scans


def test_scans_the_localizer_never_saw_are_counted_and_reported(nodes, executor,
                                                               collector_factory):
    localizer = nodes(GridLocalizer, map_file=CORRIDOR, heading_bins=8,
                      diagnostics_period=0.1)
    driver = collector_factory({"/diagnostics": (DiagnosticArray, 10)}, name="driver")
    laser = driver.node.create_publisher(LaserScan, "scan", 10)
    assert spin_until(executor, lambda: laser.get_subscription_count() > 0, 10.0)
    # A laser at 10 Hz whose scans at 1.2, 1.3 and 1.4 s never reached the node.
    for stamp_s in (1.0, 1.1, 1.5, 1.6):
        msg = scan([1.0] * 63)
        msg.scan_time = 0.1
        msg.header.stamp.sec, msg.header.stamp.nanosec = int(stamp_s), round(stamp_s % 1 * 1e9)
        received = localizer.scan_gaps.received
        # Best effort may lose one on the way (it would count as missed): sent again until
        # taken; a copy taken twice counts nothing.
        for _ in range(50):
            laser.publish(msg)
            if spin_until(executor, lambda r=received: localizer.scan_gaps.received > r, 0.2):
                break
        assert localizer.scan_gaps.received > received, f"scan {stamp_s} never taken"
    assert localizer.scan_gaps.missed == 3

    def reported(msg):
        status = msg.status[0]
        values = {v.key: v.value for v in status.values}
        return "falling behind the laser: 3 scans missed" in status.message \
            and values["scans_missed"] == "3"

    assert spin_until(executor, lambda: any(reported(m) for m in
                                            driver.messages["/diagnostics"]), 10.0)


def corridor_initial_pose() -> PoseWithCovarianceStamped:
    """(4.05, 2.05, 0) in the corridor, 0.1 m and 0.03 rad sure."""
    msg = PoseWithCovarianceStamped()
    fill_pose(msg.pose.pose, 4.05, 2.05, 0.0)
    cov = np.zeros((6, 6))
    cov[0, 0] = cov[1, 1] = 0.01
    cov[5, 5] = 0.001
    msg.pose.covariance = cov.ravel().tolist()
    return msg


def test_initial_pose_then_global_localization(nodes, executor, collector_factory):
    localizer = nodes(GridLocalizer, map_file=CORRIDOR, heading_bins=72)
    driver = collector_factory({"localization_quality": Float64}, name="driver")
    initial = driver.node.create_publisher(PoseWithCovarianceStamped, "initialpose", 10)
    assert spin_until(executor, lambda: initial.get_subscription_count() == 1, 10.0)
    initial.publish(corridor_initial_pose())
    assert spin_until(executor, lambda: localizer.handled["initialpose"] == 1, 5.0)
    # Latched with depth 1: the driver may get the start-up quality or only the latest.
    assert spin_until(executor, lambda: driver.count("localization_quality") >= 1
                      and driver.messages["localization_quality"][-1].data > 0.5, 5.0)
    client = driver.node.create_client(Trigger, "/grid_localizer/global_localization")
    assert client.wait_for_service(timeout_sec=5.0)
    future = client.call_async(Trigger.Request())
    assert spin_until(executor, future.done, 5.0) and future.result().success
    assert spin_until(executor, lambda: driver.messages["localization_quality"][-1].data < 0.01,
                      5.0)


def test_diagnostics_say_localized_or_lost_and_why_when_it_changes(nodes, executor,
                                                                  collector_factory):
    """The state goes out on /diagnostics with the estimate that changed it, not at the
    next period (an hour here): localized from an initial pose, lost once the belief is
    uniform again, with the reason and ERROR."""
    localizer = nodes(GridLocalizer, map_file=CORRIDOR, heading_bins=72,
                      diagnostics_period=3600.0)
    driver = collector_factory({"/diagnostics": (DiagnosticArray, 10)}, name="driver")
    initial = driver.node.create_publisher(PoseWithCovarianceStamped, "initialpose", 10)
    assert spin_until(executor, lambda: initial.get_subscription_count() == 1, 10.0)

    def said(state):
        for msg in driver.messages["/diagnostics"]:
            values = {v.key: v.value for v in msg.status[0].values}
            if values.get("localization_state") == state:
                return msg.status[0], values
        return None

    initial.publish(corridor_initial_pose())
    assert spin_until(executor, lambda: said("localized") is not None, 5.0)
    status, values = said("localized")
    assert status.level == DiagnosticStatus.OK and "of the belief within 0.3 m" \
        in values["localization_reason"]
    client = driver.node.create_client(Trigger, "/grid_localizer/global_localization")
    assert client.wait_for_service(timeout_sec=5.0)
    future = client.call_async(Trigger.Request())
    assert spin_until(executor, future.done, 5.0) and future.result().success
    assert spin_until(executor, lambda: said("lost") is not None
                      and driver.messages["/diagnostics"][-1] is not None, 5.0)
    status, values = said("lost")
    assert status.level == DiagnosticStatus.ERROR
    assert "uniform over the free cells" in values["localization_reason"]
    assert status.message.startswith("lost: no scan since")
    assert localizer.standing[0] is failure.Standing.LOST


def test_a_map_from_the_topic_and_a_bad_one(nodes, executor, collector_factory):
    localizer = nodes(GridLocalizer, heading_bins=4)
    driver = collector_factory({"pose": PoseWithCovarianceStamped}, name="driver")
    maps = driver.node.create_publisher(OccupancyGrid, "map", latched_qos(1))
    bad = OccupancyGrid()
    bad.info.width, bad.info.height, bad.info.resolution = 4, 4, 0.1
    bad.data = [0] * 15                                   # 15 cells for a 4 x 4 grid
    maps.publish(bad)
    assert spin_until(executor, lambda: localizer.rejected["bad_map"] == 1, 10.0)
    assert localizer.localization is None
    good = OccupancyGrid()
    good.info.width, good.info.height, good.info.resolution = 6, 5, 0.1
    good.info.origin.orientation.w = 1.0
    good.data = [100] * 6 + [100, 0, 0, 0, 0, 100] * 3 + [100] * 6
    maps.publish(good)
    assert spin_until(executor, lambda: localizer.localization is not None, 10.0)
    assert localizer.localization.model.free.sum() == 12


@pytest.mark.parametrize("values, message", [
    ({"map_file": "/nonexistent/map.yaml"}, "map_file"),
    ({"map_file": CORRIDOR, "resolution": 0.07}, "whole multiple"),
    ({"map_file": CORRIDOR, "max_states": 1000}, "max_states"),
    ({"global_frame_id": " "}, "global_frame_id"),
    ({"odometry_source": "wheels"}, "odometry_source"),
    ({"odom_frame_id": "map"}, "three different frames"),
    ({"laser_pose": [0.1, 0.2]}, "laser_pose"),
    ({"laser_pose": [0.25, 0.0]}, "laser_pose"),
    ({"laser_pose": [0.25, 0.0, float("inf")]}, "laser_pose"),
])
def test_bad_localizer_parameters_are_one_clear_error(context, values, message):
    with pytest.raises(ConfigurationError, match=message):
        GridLocalizer(context=context, parameter_overrides=params(**{**STANDALONE, **values}))


def test_the_robot_starts_only_once_the_named_nodes_hear_it(nodes, executor, context,
                                                          collector_factory):
    """A recorder named in hold_for_nodes gets the robot's first odom and scan."""
    nodes(PlanarRobot, map_file=CORRIDOR, seed=3, rate_hz=20.0,
          hold_for_nodes=["grid_localizer", "recorder"])
    early = collector_factory({"odom": (Odometry, 10), "scan": (LaserScan, 10)},
                              name="grid_localizer")
    assert spin_until(executor, lambda: not early.unmatched(), 10.0)
    # The localizer alone hears it: the robot still waits for the recorder.
    assert not spin_until(executor, lambda: early.count("odom") > 0, 1.0)
    recorder = collector_factory({"odom": (Odometry, 10), "scan": (LaserScan, 10)},
                                 name="recorder")
    assert spin_until(executor, lambda: all(c.count("odom") and c.count("scan")
                                            for c in (early, recorder)), 10.0)
    # Both heard the run from its first step (odometry starts at the origin).
    for heard in (early, recorder):
        first = heard.messages["odom"][0].pose.pose.position
        assert math.hypot(first.x, first.y) < 0.1
    assert early.messages["odom"][0].header.stamp == recorder.messages["odom"][0].header.stamp


def test_the_robot_needs_a_map_and_a_free_start(context):
    with pytest.raises(ConfigurationError, match="map_file"):
        PlanarRobot(context=context)
    with pytest.raises(ConfigurationError, match="initial_pose"):
        PlanarRobot(context=context, parameter_overrides=params(
            map_file=CORRIDOR, initial_pose=[0.0, 0.0, 0.0]))
