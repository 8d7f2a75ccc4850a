"""A real building's map, a laser at a steady 10 Hz, the running grid_localizer: how many
scans it answers.

    python bench/grid/laser_rate_node.py [--log intel|aces|PATH] [--rate-hz 10] [--seconds 60]
                                    [--every-scan]

The corrected CARMEN logs keep a scan every 3 s or so; played faster they come in
bursts (bench/grid/real_log_node.py). Here the scans are a laser's: ``planar_robot`` drives
a simulated robot through the map ``estimation_map`` makes from the log (0.05 m), from
the log's first corrected pose, and casts a scan at every step, ``--rate-hz`` steps a
second, each stamped with its ``scan_time``, so the localizer counts exactly the scans
it never saw. ``grid_localizer`` (0.1 m, 72 headings) tracks it from that pose.

Printed: the scans sent, and what the node says it did with them (received, missed,
updates, busy share, update time), the scans answered per second, its peak memory, and
the published poses against the simulator's true poses (paired by stamp).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(1, str(Path(__file__).resolve().parents[2]))  # the repository: bench
from bench.common import confine_ros, end_run, executable, table  # noqa: E402
from bench.grid.real_buildings import LOGS, RANGE_MAX  # noqa: E402
from bench.grid.real_log_node import Watcher, peak_mib, pose_rows, prepare  # noqa: E402

from estimation_nodes.tools.demo.graph_runtime import stop_process  # noqa: E402
from estimation_nodes.tools.importers import carmen  # noqa: E402

#: The simulated laser's beams over a full turn (the localizer scores laser_beams of them).
BEAMS = 360


def run(args: argparse.Namespace, log_path: Path, work: Path) -> list[list[str]]:
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PoseStamped

    from estimation_nodes.nodes.grid_messages import planar_pose
    from estimation_nodes.nodes.qos import latched_qos

    start = carmen.read_log(log_path).scans[0].pose
    _, map_yaml = prepare(log_path, work, laser_ahead=0.0)
    env = confine_ros(90)
    grid = ["-p", f"map_file:={map_yaml}", "-p", "resolution:=0.1", "-p", "heading_bins:=72",
            "-p", f"laser_max_range:={RANGE_MAX}"]
    # --every-scan: no motion threshold, every scan is an update (the default waits for
    # update_min_d or update_min_a of motion, as AMCL does)
    every = ["-p", "update_min_d:=0.0", "-p", "update_min_a:=0.0"] if args.every_scan else []
    every += ["-p", "scan_fit:=false"] if args.no_scan_fit else []
    localizer = subprocess.Popen(
        [executable("grid_localizer"), "--ros-args", *grid, "-p", "max_states:=200000000",
         "-p", "diagnostics_period:=0.5", "-p", "autostart:=true",
         "-p", "odometry_source:=topic", *every],
        env=env, stdout=(work / "localizer.log").open("w"), stderr=subprocess.STDOUT)
    rclpy.init()
    watcher = Watcher()
    truths: dict[int, tuple[float, float, float]] = {}
    watcher.node.create_subscription(
        PoseStamped, "true_pose",
        lambda m: truths.__setitem__(m.header.stamp.sec * 10**9 + m.header.stamp.nanosec,
                                     planar_pose(m.pose)), latched_qos(1000))
    busy: list[float] = []
    watcher.node.create_subscription(
        DiagnosticArray, "/diagnostics",
        lambda m: busy.extend(float(v.value) for s in m.status for v in s.values
                              if s.name.startswith("grid_localizer") and
                              v.key == "busy_percent"), 10)
    robot = None
    try:
        watcher.start_localizer_at(localizer, work / "localizer.log", start,
                                   "laser_rate_node")
        robot = subprocess.Popen(
            [executable("planar_robot"), "--ros-args", *grid, "-p", "seed:=3",
             "-p", f"rate_hz:={args.rate_hz}", "-p", f"beams:={BEAMS}",
             "-p", "initial_pose:=[" + ", ".join(repr(float(v)) for v in start) + "]",
             "-p", f"duration:={args.seconds}", "-p", "exit_when_done:=true"],
            env=env, stdout=(work / "robot.log").open("w"), stderr=subprocess.STDOUT)
        started = time.monotonic()
        watcher.spin(lambda: robot.poll() is not None, args.seconds + 120)
        driven_s = time.monotonic() - started
        watcher.spin(lambda: False, 3.0)     # the last update and diagnostics
        peak = peak_mib(localizer.pid)
    finally:
        if robot is not None and robot.poll() is None:
            stop_process(robot)
        end_run(None, localizer, watcher.node)
    return summary(args, watcher, truths, driven_s, peak, busy)


def summary(args, watcher: Watcher, truths: dict, driven_s: float, peak: float,
            busy: list[float]) -> list[list[str]]:
    d = watcher.diagnostics
    updates = int(d.get("handled.scan", 0))
    sent = int(round(args.seconds * args.rate_hz))
    return [
        ["scans sent (steps of the simulated robot)", f"{sent} at {args.rate_hz:g} Hz"],
        ["received / missed (from scan_time)", f"{d.get('scans_received', '?')} / "
         f"{d.get('scans_missed', '?')}"],
        ["updates / not due (no motion)", f"{updates} / "
         f"{d.get('handled.scan_without_motion', 0)}"],
        ["scans answered per second", f"{updates / args.seconds:.1f}"],
        ["scans not answered, in the first 5 s / after", unanswered(watcher.poses, truths)],
        ["busy (share of the time updating), median / max of its reports",
         f"{np.median(busy):.0f} / {max(busy):.0f} %" if busy else "-"],
        ["update, median / max (node's own)", f"{d.get('update_ms_median', '?')} / "
         f"{d.get('update_ms_max', '?')} ms"],
        ["localizer peak RSS (VmHWM)", f"{peak:.0f} MiB"],
        ["wall time of the drive", f"{driven_s:.1f} s"],
        *pose_rows(watcher.poses, truths, "true pose"),
    ]


def unanswered(poses: dict[int, tuple], truths: dict[int, tuple],
               settling_s: float = 5.0) -> str:
    """The simulator's scans (one true pose each, same stamp) with no published pose: in
    the first ``settling_s`` (the given pose's spread narrowing) and after."""
    if not truths:
        return "-"
    first = min(truths)
    missed = [stamp for stamp in truths if stamp not in poses]
    early = sum(stamp - first < settling_s * 1e9 for stamp in missed)
    return f"{early} / {len(missed) - early}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--log", default="intel", help="intel, aces or a CARMEN log's path")
    parser.add_argument("--rate-hz", type=float, default=10.0)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--every-scan", action="store_true",
                        help="update_min_d and update_min_a 0: every scan an update")
    parser.add_argument("--no-scan-fit", action="store_true",
                        help="scan_fit false: the pose is the belief's, not refined by the scan")
    args = parser.parse_args()
    log_path = LOGS.get(args.log, Path(args.log))
    if not log_path.exists():
        sys.exit(f"laser_rate_node: no log at {log_path} (see ../shared/data/README.md)")
    with tempfile.TemporaryDirectory() as work:
        rows = run(args, log_path, Path(work))
    print(f"grid_localizer on the map of {log_path.name}, a simulated laser at "
          f"{args.rate_hz:g} Hz for {args.seconds:g} s, through DDS"
          + (", every scan an update" if args.every_scan else ""))
    print(table(["figure", "value"], rows))


if __name__ == "__main__":
    main()
