"""grid_localizer as nav2_amcl is used: a lifecycle driven through lifecycle_msgs services as
Nav2's lifecycle manager drives it, odometry and the laser's mount from tf, map -> odom on
/tf such that the tree's map -> base_link is the published pose, AMCL's services, and a
scan whose transform never comes dropped and counted."""

from __future__ import annotations

import contextlib
import math

import numpy as np
import pytest
from geometry_msgs.msg import PoseArray, PoseWithCovarianceStamped
from lifecycle_msgs.msg import State, Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import LaserScan
from std_srvs.srv import Empty
from tf2_msgs.msg import TFMessage

from estimation_nodes.core.grid.likelihood_field import SensorField, grid_model
from estimation_nodes.core.sim import planar
from estimation_nodes.core.transforms.buffer import TransformBuffer, TransformRejected
from estimation_nodes.core.transforms.rigid import Transform
from estimation_nodes.nodes.grid_localizer import GridLocalizer
from estimation_nodes.nodes.grid_messages import planar_pose
from estimation_nodes.nodes.qos import latched_qos
from estimation_nodes.nodes.tf import (TF_QOS, StaticTransformBroadcaster, TransformBroadcaster,
                                       from_message, to_message)
from estimation_nodes.params.map_files import read_map_file
from tests.conftest import REPO, spin_until

CORRIDOR = REPO / "maps" / "corridor.yaml"
SECOND = 10**9
T0 = 1000 * SECOND
#: The laser 0.25 m ahead of base_link, as the acceptance's moved mount.
MOUNT = (0.25, 0.0, 0.0)
BEAMS = 120


def true_pose(step: int) -> tuple[float, float, float]:
    return (3.0 + 0.2 * step, 2.0, 0.01 * step)


def odometry(step: int) -> tuple[float, float, float]:
    """The wheels' idea: the true path seen from an odom frame 1 m and 0.3 rad off."""
    return (Transform.planar(1.0, -0.5, 0.3) * Transform.planar(*true_pose(step))).as_planar()


def stamp(step: int) -> int:
    return T0 + step * SECOND // 10


class Robot:
    """Sends /tf, /tf_static and scans as a robot's drivers would, and keeps what the
    localizer sends on /tf."""

    def __init__(self, context, executor) -> None:
        self.node = Node("robot", context=context)
        executor.add_node(self.node)
        self.executor = executor
        self.tf = TransformBroadcaster(self.node)
        self.static = StaticTransformBroadcaster(self.node)
        self.scans = self.node.create_publisher(LaserScan, "scan", 10)
        self.clock = self.node.create_publisher(Clock, "/clock", 10)
        self.heard = TransformBuffer(cache_time_ns=3600 * SECOND)
        self.poses: list[PoseWithCovarianceStamped] = []
        self.clouds: list[PoseArray] = []
        self.node.create_subscription(TFMessage, "/tf", self._on_tf, TF_QOS)
        self.node.create_subscription(PoseWithCovarianceStamped, "pose", self.poses.append,
                                      latched_qos(100))
        self.node.create_subscription(PoseArray, "particle_cloud", self.clouds.append,
                                      latched_qos(1))
        self.world = planar.planar_world(read_map_file(CORRIDOR))
        self.angles = -math.pi + 2 * math.pi * np.arange(BEAMS) / BEAMS

    def _on_tf(self, msg: TFMessage) -> None:
        for transform in msg.transforms:
            if transform.header.frame_id == "map":
                with contextlib.suppress(TransformRejected):   # a second pass's repeats
                    self.heard.set_transform(*from_message(transform))

    def mount(self) -> None:
        self.static.send([to_message("base_link", "laser", 0, Transform.planar(*MOUNT))])

    def tick(self, stamp_ns: int) -> None:
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = divmod(stamp_ns, SECOND)
        self.clock.publish(msg)

    def move(self, step: int) -> None:
        self.tick(stamp(step))
        self.tf.send([to_message("odom", "base_link", stamp(step),
                                 Transform.planar(*odometry(step)))])

    def scan(self, step: int) -> None:
        msg = LaserScan()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp(step), SECOND)
        msg.header.frame_id = "laser"
        msg.angle_min, msg.angle_increment = float(self.angles[0]), 2 * math.pi / BEAMS
        msg.range_min, msg.range_max = 0.05, 12.0
        laser = planar.sensor_at(true_pose(step), MOUNT)
        msg.ranges = planar.ray_cast(self.world, laser, self.angles, 12.0).tolist()
        self.scans.publish(msg)


@pytest.fixture
def localizer(make_node):
    return lambda **values: make_node(GridLocalizer, map_file=str(CORRIDOR), heading_bins=36,
                                      **values)


def drive(robot: Robot, localizer: GridLocalizer, steps: range) -> None:
    """Odometry at each step, then its scan, each scan answered before the next."""
    for step in steps:
        robot.move(step)
        robot.move(step + 1)     # the tree holds the scan's time on both sides
        before = answered(localizer)
        robot.scan(step)
        assert spin_until(robot.executor, lambda b=before: answered(localizer) > b, 10.0), \
            (dict(localizer.handled), dict(localizer.rejected))


def answered(localizer: GridLocalizer) -> int:
    return localizer.handled["scan"] + localizer.handled["scan_without_motion"]


@pytest.mark.timeout(120)
def test_odometry_and_mount_from_tf_and_map_to_odom_that_gives_the_pose(
        context, executor, localizer):
    node = localizer(autostart=True, set_initial_pose=True, **{
        "initial_pose.x": 3.0, "initial_pose.y": 2.0, "initial_pose.yaw": 0.0})
    robot = Robot(context, executor)
    robot.mount()
    assert spin_until(executor, lambda: robot.scans.get_subscription_count() > 0, 10.0)
    drive(robot, node, range(0, 30, 2))
    assert node.handled["scan"] >= 8
    assert node.localization is not None and node.localization.model.laser_pose == MOUNT
    # Every update's pose (the prior's, published at activation, may have come before the
    # robot's subscription matched).
    assert spin_until(executor, lambda: len(robot.poses) >= node.handled["scan"], 10.0), \
        (len(robot.poses), dict(node.handled), dict(node.rejected))
    last = robot.poses[-1]
    t = last.header.stamp.sec * SECOND + last.header.stamp.nanosec
    published = planar_pose(last.pose.pose)
    step = (t - T0) * 10 // SECOND
    # Found: within a state cell and a heading bin of the truth.
    assert math.dist(published[:2], true_pose(step)[:2]) < 0.15
    # map -> odom on /tf, stamped transform_tolerance (1 s) after the scan; with the
    # odometry of the scan's time it gives the published pose.
    assert spin_until(executor, lambda: robot.heard.can_transform("map", "odom", t + SECOND),
                      10.0)
    map_odom = robot.heard.lookup("map", "odom", t + SECOND)
    through_tree = (map_odom * Transform.planar(*odometry(step))).as_planar()
    np.testing.assert_allclose(through_tree[:2], published[:2], atol=1e-9)
    assert abs(math.remainder(through_tree[2] - published[2], 2 * math.pi)) < 1e-9
    assert spin_until(executor, lambda: bool(robot.clouds), 10.0)
    assert 0 < len(robot.clouds[-1].poses) <= 500


@pytest.mark.timeout(60)
def test_a_scan_whose_transform_never_comes_is_dropped_and_counted(context, executor,
                                                                   localizer):
    node = localizer(autostart=True, transform_tolerance=0.2)
    robot = Robot(context, executor)
    assert spin_until(executor, lambda: robot.scans.get_subscription_count() > 0, 10.0)
    robot.scan(0)            # no odom -> base_link, no mount at all
    assert spin_until(executor, lambda: node.rejected["scan_without_transform"] == 1, 10.0)
    assert not node._waiting_scans and node.localization.updates == 0


def call(client_node: Node, executor, service_type, name: str, request):
    client = client_node.create_client(service_type, name)
    assert spin_until(executor, client.service_is_ready, 10.0), f"no service {name}"
    future = client.call_async(request)
    assert spin_until(executor, future.done, 10.0), f"{name} did not answer"
    return future.result()


@pytest.mark.timeout(120)
def test_the_lifecycle_as_navs_lifecycle_manager_drives_it(context, executor, localizer):
    node = localizer(odometry_source="topic")
    manager = Node("lifecycle_manager", context=context)
    executor.add_node(manager)
    poses: list = []
    manager.create_subscription(PoseWithCovarianceStamped, "pose", poses.append,
                                latched_qos(10))

    def state() -> int:
        return call(manager, executor, GetState, "/grid_localizer/get_state",
                    GetState.Request()).current_state.id

    def change(transition: int) -> bool:
        return call(manager, executor, ChangeState, "/grid_localizer/change_state",
                    ChangeState.Request(transition=Transition(id=transition))).success

    assert state() == State.PRIMARY_STATE_UNCONFIGURED and node.localization is None
    assert change(Transition.TRANSITION_CONFIGURE)
    assert state() == State.PRIMARY_STATE_INACTIVE and node.localization is not None
    spin_until(executor, lambda: bool(poses), 1.0)
    assert not poses, "published while inactive"
    assert change(Transition.TRANSITION_ACTIVATE)
    assert state() == State.PRIMARY_STATE_ACTIVE
    assert spin_until(executor, lambda: bool(poses), 10.0)
    # AMCL's services, by its names: global localization, a forced update on the next scan.
    call(manager, executor, Empty, "/reinitialize_global_localization", Empty.Request())
    call(manager, executor, Empty, "/request_nomotion_update", Empty.Request())
    assert node._force_update and node.handled["initialpose"] == 0
    assert change(Transition.TRANSITION_DEACTIVATE)
    assert state() == State.PRIMARY_STATE_INACTIVE and not node.active
    assert change(Transition.TRANSITION_CLEANUP)
    assert state() == State.PRIMARY_STATE_UNCONFIGURED and node.localization is None
    assert change(Transition.TRANSITION_CONFIGURE) and change(Transition.TRANSITION_ACTIVATE)
    assert state() == State.PRIMARY_STATE_ACTIVE and node.localization is not None
    assert change(Transition.TRANSITION_ACTIVE_SHUTDOWN)
    assert state() == State.PRIMARY_STATE_FINALIZED


@pytest.mark.timeout(120)
def test_a_bag_played_again_resets_and_the_second_pass_localizes_as_the_first(
        context, executor, localizer):
    """Time going back (estimation_play --loop with --clock): the tf buffer cleared, the
    belief uniform again, one line; the same inputs then give the same poses."""
    node = localizer(autostart=True, use_sim_time=True)
    robot = Robot(context, executor)
    robot.mount()
    assert spin_until(executor, lambda: robot.scans.get_subscription_count() > 0
                      and robot.clock.get_subscription_count() > 0, 10.0)
    passes = []
    for _ in range(2):
        robot.tick(stamp(0))
        heard = len(robot.poses)
        drive(robot, node, range(0, 24, 2))
        last = divmod(stamp(22), SECOND)      # the last scan's update
        assert spin_until(executor, lambda h=heard, last=last: any(
            (p.header.stamp.sec, p.header.stamp.nanosec) == last for p in robot.poses[h:]),
            10.0)
        passes.append({(p.header.stamp.sec, p.header.stamp.nanosec): planar_pose(p.pose.pose)
                       for p in robot.poses[heard:]})
        robot.tick(stamp(0) - 5 * SECOND)      # the bag starts again
        jumps = len(passes)
        assert spin_until(executor, lambda n=jumps: node.handled["time_jumped_back"] == n,
                          10.0)
    first, second = passes
    updates = sorted(stamp_ for stamp_ in first if stamp_[0] >= T0 // SECOND)
    assert len(updates) >= 6 and updates == sorted(s for s in second if s[0] >= T0 // SECOND)
    for key in updates:
        np.testing.assert_allclose(second[key], first[key], atol=1e-12)


@pytest.mark.timeout(60)
def test_amcls_parameter_names_reach_the_filter(context, executor, localizer):
    """The rows of the nav2_amcl table that say "same": each of AMCL's names sets what the
    filter uses."""
    node = localizer(autostart=True, alpha1=0.11, alpha2=0.12, alpha3=0.13, alpha4=0.14,
                     laser_max_range=9.5, laser_likelihood_max_dist=1.5, max_beams=40,
                     laser_z_hit=0.7, laser_z_rand=0.3, laser_sigma_hit=0.15,
                     update_min_d=0.4, update_min_a=0.3, global_frame_id="world",
                     odom_frame_id="wheels", base_frame_id="base_footprint",
                     transform_tolerance=0.3)
    localization, settings = node.localization, node._settings
    noise = localization.noise
    assert (noise.alpha1, noise.alpha2, noise.alpha3, noise.alpha4) == (0.11, 0.12, 0.13, 0.14)
    # The likelihood field is the one these laser parameters make.
    sensor = SensorField(z_hit=0.7, z_rand=0.3, sigma_hit=0.15, max_range=9.5,
                         max_distance=1.5)
    expected = grid_model(read_map_file(CORRIDOR), settings.resolution, 36, sensor,
                          settings.max_states)
    np.testing.assert_array_equal(localization.model.log_field, expected.log_field)
    assert localization.model.log_outside == expected.log_outside
    assert settings.max_beams == 40
    assert (localization._min_d, localization._min_a) == (0.4, 0.3)
    frames = settings.frames
    assert (frames.global_frame_id, frames.odom_frame_id, frames.base_frame_id,
            frames.transform_tolerance) == ("world", "wheels", "base_footprint", 0.3)


@pytest.mark.timeout(60)
def test_update_min_d_and_update_min_a_decide_which_scans_update(context, executor,
                                                                 localizer):
    """AMCL's rule: a scan updates after update_min_d of travel or update_min_a of turn
    since the last update (the first at once); the others are answered without one."""
    node = localizer(autostart=True, update_min_d=0.5, update_min_a=1.0)
    robot = Robot(context, executor)
    robot.mount()
    assert spin_until(executor, lambda: robot.scans.get_subscription_count() > 0, 10.0)
    # A scan at every step (0.2 m, 0.01 rad): the first, then every third (0.6 m) updates.
    drive(robot, node, range(0, 10))
    assert (node.handled["scan"], node.handled["scan_without_motion"]) == (4, 6)


@pytest.mark.timeout(60)
def test_without_tf_broadcast_no_map_to_odom_is_sent(context, executor, localizer):
    node = localizer(autostart=True, tf_broadcast=False)
    robot = Robot(context, executor)
    robot.mount()
    assert spin_until(executor, lambda: robot.scans.get_subscription_count() > 0, 10.0)
    drive(robot, node, range(0, 6, 2))
    spin_until(executor, lambda: False, 0.5)      # what was sent is in by now
    assert node.handled["scan"] >= 1 and not robot.heard.frames()


@pytest.mark.timeout(60)
def test_an_initialpose_heard_while_inactive_is_taken_at_activation(context, executor,
                                                                    localizer, make_node):
    """As AMCL: the latest initial pose sent before activation is the prior once active."""
    node = localizer()
    assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
    sender = make_node("rviz")
    publisher = sender.create_publisher(PoseWithCovarianceStamped, "initialpose", 10)
    assert spin_until(executor, lambda: publisher.get_subscription_count() > 0, 10.0)
    msg = PoseWithCovarianceStamped()
    msg.header.frame_id = "map"
    msg.pose.pose.position.x, msg.pose.pose.position.y = 3.0, 2.0
    msg.pose.pose.orientation.w = 1.0
    msg.pose.covariance[0] = msg.pose.covariance[7] = 0.04
    msg.pose.covariance[35] = 0.01
    publisher.publish(msg)
    assert spin_until(executor, lambda: node._pending_initial_pose is not None, 10.0)
    assert node.handled["initialpose"] == 0
    assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
    assert node.handled["initialpose"] == 1
    assert math.dist(node.localization.estimate(0.5, 0.5).pose[:2], (3.0, 2.0)) < 0.1
