"""A real log through the running grid_localizer, played at a laser's rate.

    python bench/grid/real_log_node.py [--log intel|aces|PATH] [--scan-rate 10]
        [--resolution 0.1] [--heading-bins 72] [--max-odom-jump 5] [--seconds S]
        [--picture FILE.png] [--keep DIR] [--record FILE.mcap] [--tf] [--global-start]

What a user does with a CARMEN log, through the real executables: ``estimation_import
carmen`` makes a recording, ``estimation_map`` a map from its corrected poses (0.05 m),
``grid_localizer`` runs on that map as its own process (given the first corrected pose
on ``initialpose``, 0.3 m and 10 degrees), and ``estimation_play`` plays the recording's
``/scan`` and ``/odom`` into it. The corrected logs hold a scan every 3 s or so (Intel:
910 in 44 minutes); the play's rate is set so that the scans come at ``--scan-rate``
(default 10 Hz, a laser's), the odometry with them.

Printed: the scans played and their rate, what the node did with them from its
/diagnostics (updated, not due for lack of motion, missed, rejected), its update time
(median and maximum, its own measure), its peak resident memory (VmHWM), and the
published poses against the corrected pose of their scan (paired by stamp). With
``--global-start`` the localizer is given no pose and starts uniform over the free cells;
its longest update is then the first.

With ``--tf`` the run is a robot's as nav2_amcl sees it: the log imported with its tf tree
and the laser mounted ``TF_LASER_AHEAD`` m forward (``--laser-ahead``: base_link, its
odometry and its truth that far behind the laser), played with ``--clock`` without
/odom (/scan, /tf, /tf_static), the localizer with ``odometry_source: tf`` and
``use_sim_time``, configured and activated through its lifecycle services as Nav2's
lifecycle manager does; besides the pose topic, map -> base_link through the /tf it
publishes (its map -> odom for the scan, with the tree's odom -> base_link at the scan's
time) is scored against the truth.

With ``--record`` the bench also records the run as ``estimation_demo --record`` does
(the scans and odometry as the bench's node heard them, the initial pose it sent, the
localizer's poses and qualities, its parameters in the metadata) and runs
``estimation_replay`` on the file: the localizer offline over the same inputs must
publish the same poses (EQUAL).
"""

from __future__ import annotations

import argparse
import math
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(1, str(Path(__file__).resolve().parents[2]))  # the repository: bench
from bench.common import (  # noqa: E402
    RunRecorder,
    confine_ros,
    end_run,
    executable,
    table,
    wait_for_line,
)
from bench.grid.real_buildings import (  # noqa: E402
    LOGS,
    NEAR_M,
    NEAR_RAD,
    PRIOR_SIGMA_M,
    PRIOR_SIGMA_RAD,
    RANGE_MAX,
)

from estimation_nodes.tools.demo.graph_runtime import spin_until, stop_process  # noqa: E402
from estimation_nodes.tools.importers import carmen  # noqa: E402


#: --tf: the laser this far (m) ahead of base_link in the imported tree.
TF_LASER_AHEAD = 0.25


def prepare(log_path: Path, work: Path, laser_ahead: float,
            map_from: Path | None = None, map_yaml: Path | None = None) -> tuple[Path, Path]:
    """The recording and the map, made by the package's own tools; the map from the log
    ``map_from`` where given (a log with faults injected is mapped from its clean one),
    or ``map_yaml`` as it is, one made before."""
    recording, stem = work / "run.mcap", work / "map"
    if map_yaml is not None:
        map_from = None
    for source, target in ((log_path, recording), (map_from, work / "mapped.mcap")):
        if source is not None:
            subprocess.run([executable("estimation_import"), "carmen", str(source), "-o",
                            str(target), "--range-max", str(RANGE_MAX),
                            "--laser-ahead", str(laser_ahead)], check=True,
                           stdout=subprocess.DEVNULL)
    if map_yaml is not None:
        return recording, map_yaml
    # The truth is base_link's: the map is made from the laser's poses, laser_ahead before.
    subprocess.run([executable("estimation_map"),
                    str(recording if map_from is None else work / "mapped.mcap"),
                    "-o", str(stem), "--laser-pose", str(laser_ahead), "0", "0"],
                   check=True, stdout=subprocess.DEVNULL)
    return recording, stem.with_suffix(".yaml")


def peak_mib(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return float("nan")


class Watcher:
    """The bench's node: gives the initial pose, keeps the poses and the latest
    diagnostics."""

    def __init__(self) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from geometry_msgs.msg import PoseWithCovarianceStamped
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node
        from std_msgs.msg import Float64

        from estimation_nodes.nodes.qos import latched_qos

        from estimation_nodes.core.transforms.buffer import TransformBuffer
        from estimation_nodes.nodes.tf import TransformListener

        self.node = Node("real_log_bench")
        self.poses: dict[int, tuple[float, float, float]] = {}
        #: Each pose's covariance in (x, y, yaw) and publish time, by its stamp; the
        #: (publish time, value) of each localization_quality, which the node publishes
        #: just before its pose.
        self.covariances: dict[int, np.ndarray] = {}
        self.published: dict[int, int] = {}
        self.qualities: list[tuple[int, float]] = []
        #: Everything heard on /tf and /tf_static, kept for the whole run.
        self.tree = TransformBuffer(cache_time_ns=1 << 62)
        TransformListener(self.node, self.tree)
        self.diagnostics: dict[str, str] = {}
        self.node.create_subscription(PoseWithCovarianceStamped, "pose", self._on_pose,
                                      latched_qos(1000))
        self.node.create_subscription(Float64, "localization_quality", self._on_quality,
                                      latched_qos(1000))
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics,
                                      10)
        self.initial = self.node.create_publisher(PoseWithCovarianceStamped, "initialpose",
                                                  10)
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self.recorder: RunRecorder | None = None

    def record(self, tf: bool) -> None:
        """Keep every input the localizer hears and every pose and quality it publishes."""
        from rclpy.qos import QoSProfile, ReliabilityPolicy

        from estimation_nodes.nodes.qos import latched_qos
        from estimation_nodes.nodes.tf import TF_QOS, TF_STATIC_QOS

        best_effort = QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT)
        pose_type = "geometry_msgs/msg/PoseWithCovarianceStamped"
        inputs = {"/tf": ("tf2_msgs/msg/TFMessage", TF_QOS),
                  "/tf_static": ("tf2_msgs/msg/TFMessage", TF_STATIC_QOS)} if tf \
            else {"/odom": ("nav_msgs/msg/Odometry", 1000)}
        self.recorder = RunRecorder(self.node, {
            "/scan": ("sensor_msgs/msg/LaserScan", best_effort), **inputs,
            "/pose": (pose_type, latched_qos(1000)),
            "/localization_quality": ("std_msgs/msg/Float64", latched_qos(1000))})

    def activate(self, node_name: str) -> None:
        """Configure and activate the localizer as Nav2's lifecycle manager does."""
        from lifecycle_msgs.msg import Transition
        from lifecycle_msgs.srv import ChangeState

        client = self.node.create_client(ChangeState, f"/{node_name}/change_state")
        if not self.spin(client.service_is_ready, 60):
            sys.exit("real_log_node: the localizer's lifecycle services never came")
        for transition in (Transition.TRANSITION_CONFIGURE, Transition.TRANSITION_ACTIVATE):
            future = client.call_async(ChangeState.Request(
                transition=Transition(id=transition)))
            if not self.spin(future.done, 300) or not future.result().success:
                sys.exit(f"real_log_node: lifecycle transition {transition} failed")

    def through_tf(self, tolerance_s: float) -> dict[int, tuple[float, float, float]]:
        """map -> base_link at each pose's scan time through the heard tree: the map -> odom
        sent for that scan (stamped tolerance_s after it) and odom -> base_link then."""
        from estimation_nodes.core.transforms.buffer import LookupFailed

        found = {}
        for stamp in self.poses:
            try:
                map_odom = self.tree.lookup("map", "odom", stamp + round(tolerance_s * 1e9))
                odom_base = self.tree.lookup("odom", "base_link", stamp)
            except LookupFailed:
                continue
            found[stamp] = (map_odom * odom_base).as_planar()
        return found

    def _on_pose(self, msg, info) -> None:
        from estimation_nodes.nodes.grid_messages import covariance_3x3, planar_pose
        from estimation_nodes.nodes.stamps import published_ns

        stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        self.poses[stamp] = planar_pose(msg.pose.pose)
        self.covariances[stamp] = covariance_3x3(msg.pose.covariance)
        self.published[stamp] = published_ns(info)

    def _on_quality(self, msg, info) -> None:
        from estimation_nodes.nodes.stamps import published_ns

        self.qualities.append((published_ns(info), msg.data))

    def quality_of(self, stamp: int) -> float:
        """The quality published last before the pose of ``stamp`` (by the publisher's
        clock: a subscriber's callbacks for the two topics run in no set order)."""
        sent = self.published[stamp]
        before = [value for published, value in self.qualities if published <= sent]
        return before[-1] if before else math.nan

    def _on_diagnostics(self, msg) -> None:
        if msg.status and msg.status[0].name.startswith("grid_localizer"):
            self.diagnostics = {v.key: v.value for v in msg.status[0].values}

    def give_initial_pose(self, pose: tuple[float, float, float]) -> None:
        from geometry_msgs.msg import PoseWithCovarianceStamped

        from estimation_nodes.nodes.grid_messages import fill_pose

        msg = PoseWithCovarianceStamped()
        msg.header.frame_id = "map"
        fill_pose(msg.pose.pose, *pose)
        covariance = np.zeros((6, 6))
        covariance[0, 0] = covariance[1, 1] = PRIOR_SIGMA_M ** 2
        covariance[5, 5] = PRIOR_SIGMA_RAD ** 2
        msg.pose.covariance = covariance.ravel().tolist()
        sent_ns = time.time_ns()
        self.initial.publish(msg)
        if self.recorder is not None:
            self.recorder.sent("/initialpose", "geometry_msgs/msg/PoseWithCovarianceStamped",
                               msg, sent_ns)

    def spin(self, condition, timeout: float) -> bool:
        return spin_until(self.executor, condition, timeout)

    def start_localizer_at(self, localizer, log_path: Path, pose: tuple[float, float, float],
                           bench: str) -> None:
        """Once the localizer (its output in ``log_path``) is ready and publishing, give it
        ``pose`` as the initial pose and wait for its answer; exit naming ``bench`` if it
        never gets ready."""
        if not wait_for_line(localizer, log_path, "ready:", 300):
            sys.exit(f"{bench}: the localizer never said ready:\n" + log_path.read_text())
        self.spin(lambda: self.initial.get_subscription_count() > 0 and self.poses, 60)
        count = len(self.poses)
        self.give_initial_pose(pose)
        self.spin(lambda: len(self.poses) > count, 30)

    def start_localizer_anywhere(self, localizer, log_path: Path, bench: str) -> None:
        """Once the localizer is ready and publishing, give it no pose: it starts from
        the uniform belief over the free cells (a global start)."""
        if not wait_for_line(localizer, log_path, "ready:", 300):
            sys.exit(f"{bench}: the localizer never said ready:\n" + log_path.read_text())
        self.spin(lambda: self.initial.get_subscription_count() > 0 and self.poses, 60)


@dataclass
class Played:
    """A run of a log through the node: the log, the bench's node with what it heard,
    the play's rate over the log's and how long it played, the localizer's peak memory,
    where the laser sat, and the localizer's parameters and map."""

    log: carmen.CarmenLog
    watcher: Watcher
    rate: float
    played_s: float
    peak: float
    laser_ahead: float
    parameters_yaml: str
    map_yaml: Path


def run(args: argparse.Namespace, log_path: Path, work: Path) -> list[list[str]]:
    played = play(args, log_path, work)
    log, watcher = played.log, played.watcher
    if args.picture:
        draw(log, watcher, played.map_yaml, args.picture, log_path.name)
    rows = summary(log, watcher, played.rate, played.played_s, played.peak,
                   played.laser_ahead)
    if watcher.recorder is not None:
        rows += watcher.recorder.write_and_replay(
            args.record, {"parameters_yaml": played.parameters_yaml, "kind": "grid"},
            executable("estimation_replay"))
    return rows


def play(args: argparse.Namespace, log_path: Path, work: Path,
         map_from: Path | None = None, map_yaml: Path | None = None) -> Played:
    """The log through the running localizer (``prepare``'s map: ``map_from``'s, or
    ``map_yaml`` where given), as the module's docstring says."""
    import rclpy

    log = carmen.read_log(log_path)
    laser_ahead = TF_LASER_AHEAD if args.tf else 0.0
    recording, map_yaml = prepare(log_path, work, laser_ahead, map_from, map_yaml)
    if args.record:
        map_yaml = beside(args.record, map_yaml)
    period = float(np.median(np.diff([scan.t for scan in log.scans])))
    rate = period * args.scan_rate
    env = confine_ros(87)
    parameters_yaml = localizer_parameters(args, map_yaml)
    (work / "localizer.yaml").write_text(parameters_yaml)
    localizer = subprocess.Popen(
        [executable("grid_localizer"), "--ros-args", "--params-file",
         str(work / "localizer.yaml")],
        env=env, stdout=(work / "localizer.log").open("w"), stderr=subprocess.STDOUT)
    rclpy.init()
    watcher = Watcher()
    if args.record:
        watcher.record(args.tf)
    player = None
    try:
        if args.tf:
            watcher.activate("grid_localizer")
        if getattr(args, "global_start", False):
            watcher.start_localizer_anywhere(localizer, work / "localizer.log",
                                             "real_log_node")
        else:
            watcher.start_localizer_at(localizer, work / "localizer.log",
                                       behind(log.scans[0].pose, laser_ahead),
                                       "real_log_node")
        inputs = ["/scan", "/tf", "/tf_static", "--clock"] if args.tf else ["/scan", "/odom"]
        play_command = [executable("estimation_play"), str(recording), "--rate", f"{rate:g}",
                        "--topics", *inputs, "--wait-for-subscribers", "30", "--delay", "2"]
        player = subprocess.Popen(play_command, env=env,
                                  stdout=(work / "play.log").open("w"),
                                  stderr=subprocess.STDOUT)
        limit = args.seconds or (log.scans[-1].t - log.scans[0].t) / rate + 60
        started = time.monotonic()
        watcher.spin(lambda: player.poll() is not None, limit)
        played_s = time.monotonic() - started
        if player.poll() is None:
            stop_process(player)      # --seconds: the first part of the log only
        watcher.spin(lambda: False, 3.0)     # the last update and diagnostics
        peak = peak_mib(localizer.pid)
    finally:
        end_run(player, localizer, watcher.node)
    return Played(log, watcher, rate, played_s, peak, laser_ahead, parameters_yaml, map_yaml)


def beside(recording: Path, map_yaml: Path) -> Path:
    """The map copied to a folder beside the recording (the node is given that copy): a
    replay of the recording later finds the map it names."""
    import shutil

    folder = recording.parent / f"{recording.stem}_map"
    folder.mkdir(parents=True, exist_ok=True)
    for path in map_yaml.parent.glob(f"{map_yaml.stem}.*"):
        shutil.copy(path, folder / path.name)
    return folder / map_yaml.name


#: The localizer's transform_tolerance under --tf (AMCL's default).
TF_TOLERANCE_S = 1.0


def localizer_parameters(args: argparse.Namespace, map_yaml: Path) -> str:
    """The localizer's parameter file, as YAML: given to the node and kept in a recording."""
    import yaml

    how = {"odometry_source": "tf", "use_sim_time": True, "autostart": False,
           "transform_tolerance": TF_TOLERANCE_S} if args.tf else \
        {"odometry_source": "topic", "autostart": True}
    return yaml.safe_dump({"/grid_localizer": {"ros__parameters": {
        "map_file": str(map_yaml), "resolution": args.resolution,
        "heading_bins": args.heading_bins, "max_states": 200_000_000,
        "laser_max_range": RANGE_MAX, "diagnostics_period": 0.5,
        "max_odom_jump": args.max_odom_jump, **how}}})


def draw(log, watcher: Watcher, map_yaml: Path, output: Path, name: str) -> None:
    """The map, the log's corrected path and the node's published poses, one PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from estimation_nodes.params.map_files import read_map_file

    occupancy = read_map_file(map_yaml)
    rows, cols = occupancy.cells.shape
    x0, y0 = occupancy.origin
    extent = (x0, x0 + cols * occupancy.resolution, y0, y0 + rows * occupancy.resolution)
    cells = occupancy.cells
    shade = np.where(cells >= 50, 0.0, np.where(cells < 0, 0.75, 1.0))
    truth = np.array([scan.pose for scan in log.scans])
    estimates = np.array([watcher.poses[s] for s in sorted(watcher.poses)])
    figure, ax = plt.subplots(figsize=(10, 10 * rows / cols + 0.6), dpi=100)
    ax.imshow(shade, origin="lower", extent=extent, cmap="gray", vmin=0, vmax=1)
    ax.plot(truth[:, 0], truth[:, 1], color="#d62728", linewidth=1.0,
            label="corrected path (the log's SLAM)")
    ax.scatter(estimates[:, 0], estimates[:, 1], s=4, color="#1f77b4", zorder=3,
               label=f"grid_localizer's poses ({len(estimates)})")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(loc="upper right", fontsize=9)
    ax.set_title(f"{name}: the map made from the corrected poses, the corrected path, "
                 f"the node's estimates")
    figure.tight_layout()
    figure.savefig(output)
    plt.close(figure)
    print(f"real_log_node: picture written to {output}")


def pose_rows(poses: dict, truths: dict, truth_name: str) -> list[list[str]]:
    """The published poses against the truth of the same stamp: how many were paired, the
    share within 0.2 m and 5 degrees, the median errors."""
    paired = [(pose, truths[stamp]) for stamp, pose in poses.items() if stamp in truths]
    errors = np.array([math.hypot(p[0] - t[0], p[1] - t[1]) for p, t in paired])
    turns = np.array([abs(math.remainder(p[2] - t[2], 2 * math.pi)) for p, t in paired])
    return [
        [f"poses paired with a {truth_name}", str(len(paired))],
        ["within 0.2 m and 5 deg", f"{100 * np.mean((errors <= NEAR_M) & (turns <= NEAR_RAD)):.1f}"
         " %" if paired else "-"],
        ["median error", f"{100 * np.median(errors):.1f} cm, "
         f"{math.degrees(np.median(turns)):.1f} deg" if paired else "-"],
    ]


def behind(pose: tuple[float, float, float], laser_ahead: float) -> tuple[float, float, float]:
    """base_link's pose, ``laser_ahead`` m behind the laser's (as the import puts it)."""
    from estimation_nodes.core.geometry import compose

    return compose(pose, (-laser_ahead, 0.0, 0.0))


def summary(log, watcher: Watcher, rate: float, played_s: float, peak: float,
            laser_ahead: float) -> list[list[str]]:
    truth = {int(round(scan.t * 1e9)): behind(scan.pose, laser_ahead) for scan in log.scans}
    d = watcher.diagnostics
    handled = int(d.get("handled.scan", 0))
    not_due = int(d.get("handled.scan_without_motion", 0))
    rejected = {k: v for k, v in d.items() if k.startswith("rejected.")}
    scans = sum(1 for s in log.scans if s.t - log.scans[0].t <= played_s * rate)
    return [
        ["scans played (of the log's)", f"{scans} of {len(log.scans)}"],
        ["play rate (x the log's) -> scan rate", f"{rate:.1f} -> {scans / played_s:.1f} Hz"],
        ["received / updates / not due (no motion)", f"{d.get('scans_received', '?')} / "
         f"{handled} / {not_due}"],
        ["rejected", ", ".join(f"{k[9:]} {v}" for k, v in rejected.items()) or "none"],
        ["update, median / p99 / max (node's own)", f"{d.get('update_ms_median', '?')} / "
         f"{d.get('update_ms_p99', '?')} / {d.get('update_ms_max', '?')} ms"],
        ["localizer peak RSS (VmHWM)", f"{peak:.0f} MiB"],
        *pose_rows(watcher.poses, truth, "corrected pose"),
        *([] if not laser_ahead else [
            [f"map -> base_link through /tf: {name}", value] for name, value in
            pose_rows(watcher.through_tf(TF_TOLERANCE_S), truth, "corrected pose")]),
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--log", default="intel", help="intel, aces or a CARMEN log's path")
    parser.add_argument("--scan-rate", type=float, default=10.0,
                        help="scans per second the play makes (default: %(default)s)")
    parser.add_argument("--resolution", type=float, default=0.1)
    parser.add_argument("--heading-bins", type=int, default=72)
    # The corrected logs keep an odometry line per scan, seconds apart: a step of a metre
    # or more is the robot's motion there, not a jump of the odometry.
    parser.add_argument("--max-odom-jump", type=float, default=5.0,
                        help="the localizer's max_odom_jump (m; default: %(default)s)")
    parser.add_argument("--seconds", type=float, default=0.0,
                        help="play only this long (default: the whole log)")
    parser.add_argument("--picture", type=Path, metavar="FILE.png",
                        help="draw the map, the corrected path and the node's poses")
    parser.add_argument("--keep", type=Path, metavar="DIR",
                        help="make the recording, map and the processes' logs in DIR and "
                             "keep them (default: a temporary folder)")
    parser.add_argument("--record", type=Path, metavar="FILE.mcap",
                        help="record the run and check it with estimation_replay")
    parser.add_argument("--global-start", action="store_true",
                        help="give the localizer no initial pose: it starts uniform over "
                             "the free cells (its longest update is then the first)")
    parser.add_argument("--tf", action="store_true",
                        help="as a robot with nav2_amcl: odometry and mount from tf, played "
                             "with --clock, the lifecycle driven, map -> base_link scored")
    args = parser.parse_args()
    log_path = LOGS.get(args.log, Path(args.log))
    if not log_path.exists():
        sys.exit(f"real_log_node: no log at {log_path} (see ../shared/data/README.md)")
    if args.keep:
        args.keep.mkdir(parents=True, exist_ok=True)
        rows = run(args, log_path, args.keep)
    else:
        with tempfile.TemporaryDirectory() as work:
            rows = run(args, log_path, Path(work))
    print(f"grid_localizer on {log_path.name} at {args.resolution} m, {args.heading_bins} "
          f"headings, through DDS")
    print(table(["figure", "value"], rows))


if __name__ == "__main__":
    main()
