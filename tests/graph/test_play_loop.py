"""A robot's bag played in a loop into grid_localizer, as `ros2 bag play --loop --clock`
does: at each pass the clock jumps back, the localizer starts over with one log line, and
the second pass localizes as the first."""

from __future__ import annotations

import math

import numpy as np
import pytest
from geometry_msgs.msg import PoseWithCovarianceStamped
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import LaserScan
from tf2_msgs.msg import TFMessage

from estimation_nodes.core.sim import planar
from estimation_nodes.core.transforms.buffer import TransformBuffer
from estimation_nodes.core.transforms.rigid import Transform
from estimation_nodes.nodes.grid_messages import planar_pose, scan_beams
from estimation_nodes.nodes.qos import latched_qos
from estimation_nodes.nodes.tf import from_message, to_message
from estimation_nodes.params.grid import build_grid_localizer_settings
from estimation_nodes.params.map_files import read_map_file
from estimation_nodes.params.specs import GRID_LOCALIZER_SPECS, spec_defaults
from estimation_nodes.tools.demo.graph_runtime import stop_process
from estimation_nodes.tools.recording.mcap import McapRunWriter
from tests.conftest import spin_until
from tests.graph.graph_tools import executable
from tests.node.test_grid_dropin import BEAMS, CORRIDOR, MOUNT, odometry, true_pose

SECOND = 10**9
#: Odometry every 0.1 s, a scan every third step: 0.3 s for the localizer to answer one.
STEP_NS, SCAN_EVERY, STEPS = SECOND // 10, 3, 75
T0 = 1000 * SECOND


def scan_of(step: int, world, angles) -> LaserScan:
    """The laser's scan of the corridor from the true pose at ``step``."""
    scan = LaserScan()
    scan.header.stamp.sec, scan.header.stamp.nanosec = divmod(T0 + step * STEP_NS, SECOND)
    scan.header.frame_id = "laser"
    scan.angle_min, scan.angle_increment = float(angles[0]), 2 * math.pi / BEAMS
    scan.range_min, scan.range_max = 0.05, 12.0
    laser = planar.sensor_at(true_pose(step), MOUNT)
    scan.ranges = planar.ray_cast(world, laser, angles, 12.0).tolist()
    return scan


def robots_scans() -> dict[int, LaserScan]:
    """Scan stamp -> scan: one every SCAN_EVERY steps, between two odometry samples."""
    world = planar.planar_world(read_map_file(CORRIDOR))
    angles = -math.pi + 2 * math.pi * np.arange(BEAMS) / BEAMS
    # As the localizer gets them: through CDR (its float32 angles rounded).
    return {T0 + step * STEP_NS: deserialize_message(
                serialize_message(scan_of(step, world, angles)), LaserScan)
            for step in range(1, STEPS, SCAN_EVERY)}


def mount_message() -> TFMessage:
    return TFMessage(transforms=[to_message("base_link", "laser", T0,
                                            Transform.planar(*MOUNT))])


def odometry_message(step: int) -> TFMessage:
    return TFMessage(transforms=[to_message("odom", "base_link", T0 + step * STEP_NS,
                                            Transform.planar(*odometry(step)))])


def write_bag(path, scans: dict[int, LaserScan]) -> None:
    """A robot's recording: the laser's mount on /tf_static, odom -> base_link on /tf, the
    scans (the bag's log times are its stamps)."""
    writer = McapRunWriter(path, {"/tf_static": "tf2_msgs/msg/TFMessage",
                                  "/tf": "tf2_msgs/msg/TFMessage",
                                  "/scan": "sensor_msgs/msg/LaserScan"}, {"source": "test"})
    writer.write("/tf_static", serialize_message(mount_message()), T0, T0)
    for step in range(STEPS):
        stamp = T0 + step * STEP_NS
        writer.write("/tf", serialize_message(odometry_message(step)), stamp, stamp)
        if stamp in scans:
            writer.write("/scan", serialize_message(scans[stamp]), stamp, stamp)
    writer.close()


def offline_poses(scans: dict[int, LaserScan], taken: list[int]) -> dict[int, tuple]:
    """What the localizer with these parameters computes from a uniform belief with the
    scans ``taken`` (stamps), each with the odometry of its time: stamp -> pose."""
    values = spec_defaults(GRID_LOCALIZER_SPECS)
    values.update(PARAMETERS)
    settings = build_grid_localizer_settings(values)
    localization = settings.localization(settings.model)
    # The tree the localizer builds from the bag's /tf and /tf_static, looked up as it does.
    tree = TransformBuffer(cache_time_ns=3600 * SECOND)
    tree.set_transform(*from_message(mount_message().transforms[0]), static=True)
    for step in range(STEPS):
        tree.set_transform(*from_message(odometry_message(step).transforms[0]))
    localization.set_laser_pose(tree.lookup("base_link", "laser", T0).as_planar())
    poses = {}
    for stamp in taken:
        ranges, angles, _ = scan_beams(scans[stamp], settings.sensor.max_range,
                                       settings.max_beams)
        localization.update(ranges, angles, stamp,
                            tree.lookup("odom", "base_link", stamp).as_planar())
        poses[stamp] = localization.estimate(settings.quality_radius,
                                             settings.quality_angle).pose
    return poses


def passes_of(poses: list[PoseWithCovarianceStamped]) -> list[dict[int, tuple]]:
    """The poses split where their stamps go back (a new pass), each as stamp -> pose."""
    passes: list[dict[int, tuple]] = []
    last = None
    for pose in poses:
        stamp = pose.header.stamp.sec * SECOND + pose.header.stamp.nanosec
        if last is None or stamp < last:
            passes.append({})
        passes[-1][stamp] = planar_pose(pose.pose.pose)
        last = stamp
    return passes


#: The localizer's parameters in the test (the rest its defaults). history_depth: the
#: pose publisher keeps every pose of a pass until the test's subscriber has it (with the
#: default 1, a pose not yet acknowledged is replaced by the next, and the test would take
#: its scan for one the localizer left out).
PARAMETERS = {"map_file": str(CORRIDOR), "heading_bins": 36, "autostart": True,
              "use_sim_time": True, "history_depth": 100}


@pytest.mark.timeout(180)
def test_a_bag_played_in_a_loop_resets_the_localizer_and_the_second_pass_localizes_as_the_first(
        tmp_path, collector_factory, executor, processes):
    scans = robots_scans()
    bag = tmp_path / "robot.mcap"
    write_bag(bag, scans)
    seen = collector_factory({"/pose": (PoseWithCovarianceStamped, latched_qos(1000))})
    localizer = processes([executable("grid_localizer"), "--ros-args", *[
        arg for name, value in PARAMETERS.items()
        for arg in ("-p", f"{name}:={str(value).lower() if isinstance(value, bool) else value}")]])
    player = processes([executable("estimation_play"), str(bag), "--clock", "--loop",
                        "--wait-for-subscribers", "60", "--delay", "2"])
    # Two whole passes and the start of a third: its first answer ends the second pass.
    assert spin_until(executor, lambda: len(passes_of(seen.messages["/pose"])) >= 3, 120), \
        f"{len(seen.messages['/pose'])} poses heard"
    stop_process(player)
    stop_process(localizer)
    logged = localizer.stdout.read()
    assert logged.count("time jumped back: the belief is uniform again") >= 2, logged

    # Each pass is what the filter computes from a uniform belief with the scans that pass
    # took (on a loaded machine a best-effort scan may be lost in one pass, not the other):
    # the belief was reset at the jump, and a pass then localizes as the first did. Where
    # both passes took the same scans, their poses are the same.
    for one in passes_of(seen.messages["/pose"])[:2]:
        taken = sorted(stamp for stamp in one if stamp in scans)
        assert len(taken) >= len(scans) // 2, (taken, logged)
        expected = offline_poses(scans, taken)
        for stamp in taken:
            np.testing.assert_allclose(one[stamp], expected[stamp], atol=1e-9)
