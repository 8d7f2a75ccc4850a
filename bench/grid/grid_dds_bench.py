"""Grid localization through DDS: scan -> pose, one update after another, on the benchmark's grid.

    python bench/grid/grid_dds_bench.py [--updates 40]

grid_localizer runs as its own process on the office map (0.1 m, 72 headings:
2.88 million states). A driver here moves a simulated robot (core/planar.py)
0.3 m per step, publishes its odometry and, 20 ms later, its scan (so every
scan is due for an update), and waits for the pose stamped with that scan before the
next step: scan published -> pose received, the rate that gives, and the
localizer's own update time from /diagnostics. The localizer's resident
memory is compared with the belief tensor.
"""

from __future__ import annotations

import argparse
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(1, str(Path(__file__).resolve().parents[2]))  # the repository: bench, tests
from bench.common import REPO, confine_ros, table  # noqa: E402

from estimation_nodes.tools.demo.graph_runtime import spin_until, stop_process  # noqa: E402
from tests.support import resident_mib  # noqa: E402

MAP = REPO / "maps" / "office.yaml"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--updates", type=int, default=40)
    args = parser.parse_args()
    env = confine_ros(86)
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PoseWithCovarianceStamped
    from nav_msgs.msg import Odometry
    from rclpy.node import Node
    from sensor_msgs.msg import LaserScan

    from estimation_nodes.core.sim import planar
    from estimation_nodes.nodes.grid_messages import fill_pose
    from estimation_nodes.nodes.qos import latched_qos
    from estimation_nodes.params import map_files as maps

    localizer = subprocess.Popen(
        [sys.executable, "-m", "estimation_nodes.nodes.grid_localizer", "--ros-args", "-p",
         f"map_file:={MAP}", "-p", "diagnostics_period:=0.2", "-p", "autostart:=true",
         "-p", "odometry_source:=topic", "--log-level", "warn"],
        env=env, cwd=REPO)
    rclpy.init()
    node = Node("grid_bench_driver")
    poses: list = []
    update_ms: list[float] = []

    def on_diagnostics(msg) -> None:
        for pair in msg.status[0].values:
            if pair.key == "last_update_ms":
                update_ms.append(float(pair.value))

    node.create_subscription(PoseWithCovarianceStamped, "pose",
                             lambda m: poses.append((time.perf_counter(), m)), latched_qos(10))
    node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 10)
    odom_pub = node.create_publisher(Odometry, "odom", 50)
    scan_pub = node.create_publisher(LaserScan, "scan", 10)
    occupancy = maps.read_map_file(MAP)
    world = planar.planar_world(occupancy)
    rng = np.random.default_rng(0)
    pose = (-8.0, -8.0, 0.0)
    angles = -math.pi + 2 * math.pi * np.arange(180) / 180
    try:
        assert spin_until(node_executor(node), lambda: odom_pub.get_subscription_count() > 0
                          and scan_pub.get_subscription_count() > 0 and poses, 60.0)
        latencies = []
        for step in range(args.updates + 1):
            pose = (pose[0] + 0.3 if pose[0] < 8 else -8.0, pose[1], 0.0)
            odom = Odometry()
            # Stamped with the scan's time: the localizer takes a scan with the odometry of
            # its time (a scan without it waits, then is dropped).
            odom.header.stamp.sec = step + 1
            fill_pose(odom.pose.pose, 0.3 * (step + 1), 0.0, 0.0)
            odom_pub.publish(odom)
            # The odometry first: the localizer follows the latest, and a scan that comes
            # before the motion it follows is not due for an update yet.
            spin_until(node_executor(node), lambda: False, 0.02)
            ranges = planar.noisy_ranges(planar.ray_cast(world, pose, angles, 12.0), rng,
                                         0.05, 0.05, 12.0)
            scan = LaserScan()
            scan.header.stamp.sec, scan.header.stamp.nanosec = step + 1, 0
            scan.angle_min, scan.angle_increment = -math.pi, 2 * math.pi / 180
            scan.range_min, scan.range_max = 0.05, 12.0
            scan.ranges = ranges.astype(np.float32).tolist()
            count = len(poses)
            sent = time.perf_counter()
            scan_pub.publish(scan)
            assert spin_until(node_executor(node), lambda c=count, s=step + 1: len(poses) > c
                              and poses[-1][1].header.stamp.sec == s, 30.0)
            if step:                          # the first update also loads the kernels
                latencies.append(poses[-1][0] - sent)
        spin_until(node_executor(node), lambda: False, 0.5)
        rss = resident_mib(localizer.pid)
    finally:
        stop_process(localizer)
        node.destroy_node()
        rclpy.try_shutdown()
    belief_mib = 2_880_000 * 8 / 2**20
    lat = np.array(latencies) * 1e3
    print(f"grid_localizer, office map, 2.88 million states, {args.updates} updates "
          f"(ROS_DOMAIN_ID={env['ROS_DOMAIN_ID']})")
    print(table(["figure", "value"], [
        ["scan -> pose, median (p10..p90)", f"{np.median(lat):.1f} ms "
         f"({np.percentile(lat, 10):.1f}..{np.percentile(lat, 90):.1f})"],
        ["updates per second, back to back", f"{1e3 / np.median(lat):.1f} /s"],
        ["localizer's update (prediction + correction), median",
         f"{np.median(update_ms):.1f} ms" if update_ms else "-"],
        ["localizer RSS", f"{rss:.0f} MiB"],
        ["belief tensor", f"{belief_mib:.0f} MiB"],
    ]))


def node_executor(node):
    from rclpy.executors import SingleThreadedExecutor

    executor = getattr(node_executor, "executor", None)
    if executor is None:
        executor = node_executor.executor = SingleThreadedExecutor()
        executor.add_node(node)
    return executor


if __name__ == "__main__":
    main()
