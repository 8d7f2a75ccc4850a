"""The landmark filters through the running ekf_localizer: a UTIAS robot played into it,
and its event -> pose latency at a camera's and an odometry's rates.

    python bench/landmarks/ekf_node.py run [--robot 1] [--filter ekf|ukf] [--rate 1] [--seconds S]
        [--record FILE.mcap]
    python bench/landmarks/ekf_node.py latency [--filter ekf|ukf] [--seconds 30]

``run``: what a user does with the dataset, through the real executables.
``estimation_import utias`` makes the recording and the landmarks file,
``ekf_localizer`` runs as its own process with msgs_config/robots/utias_mrclam.yaml
(started at Vicon's pose at the first odometry message), and ``estimation_play``
plays ``/odom`` and ``/landmark_observations`` into it at ``--rate`` times real time.
Printed: the published poses scored against Vicon as bench/landmarks/ekf_real.py scores the
core's, and the largest difference from the core filter run offline on the same
events, their observations read as the node reads them (float32 coordinates). With
``--record`` the run is also recorded (the odometry and frames the node heard, its poses,
its parameters) and ``estimation_replay`` checks the poses against the filter offline.

``latency``: a publisher in this process sends odometry at 100 Hz and camera frames
at 30 Hz (a simulated unicycle among the UTIAS landmarks) to ekf_localizer with the
package's default models (those of the simulation); each
published pose is paired by its stamp with the event that made it, and the time from
the event's publication to the pose's arrival here is measured (DDS both ways
included). The same events go first to bench/relay_node.py, which answers each with an
empty pose at once: the least any rclpy node in the localizer's place could do, the
baseline of the p99 ratio printed.
"""

from __future__ import annotations

import argparse
import math
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(1, str(Path(__file__).resolve().parents[2]))  # the repository: bench
from bench.common import (  # noqa: E402
    RELAY_NODE,
    RunRecorder,
    confine_ros,
    end_run,
    executable,
    table,
    wait_for_line,
)
from bench.landmarks.ekf_real import DATASET, PARAMS, file_figures, run_filter, score  # noqa: E402

from estimation_nodes.params.landmarks import landmark_model  # noqa: E402
from estimation_nodes.nodes.qos import latched_qos  # noqa: E402
from estimation_nodes.params.specs import LANDMARK_MODEL_SPECS, spec_defaults  # noqa: E402
from estimation_nodes.tools.demo.graph_runtime import spin_until, stop_process  # noqa: E402
from estimation_nodes.tools.importers.cli import seconds_to_ns  # noqa: E402
from estimation_nodes.tools.importers.utias import read_run  # noqa: E402

#: Rates of the latency run (Hz): odometry, camera frames.
ODOM_HZ, FRAME_HZ = 100.0, 30.0


class PoseWatcher:
    """The bench's node: keeps every pose by stamp, with its arrival time."""

    def __init__(self) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from geometry_msgs.msg import PoseWithCovarianceStamped
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node

        from estimation_nodes.nodes.qos import latched_qos

        self.node = Node("ekf_node_bench")
        self.poses: dict[int, tuple[np.ndarray, np.ndarray, float]] = {}
        self.diagnostics: dict[str, str] = {}
        self.node.create_subscription(PoseWithCovarianceStamped, "pose", self._on_pose,
                                      latched_qos(1000))
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics,
                                      10)
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)

    def _on_pose(self, msg) -> None:
        from estimation_nodes.nodes.grid_messages import planar_pose

        arrived = time.perf_counter()
        stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        c = np.array(msg.pose.covariance).reshape(6, 6)
        covariance = c[np.ix_([0, 1, 5], [0, 1, 5])]
        self.poses[stamp] = (np.array(planar_pose(msg.pose.pose)), covariance, arrived)

    def _on_diagnostics(self, msg) -> None:
        if msg.status and msg.status[0].name.startswith("ekf_localizer"):
            self.diagnostics = {v.key: v.value for v in msg.status[0].values}

    def spin(self, condition, timeout: float) -> bool:
        return spin_until(self.executor, condition, timeout)

    def counts(self) -> str:
        """What the node says it did with the events and observations."""
        return ", ".join(f"{k} {v}" for k, v in self.diagnostics.items()
                         if k.startswith(("handled.", "rejected.", "observations."))) or "-"


def start_localizer(work: Path, kind: str, initial: np.ndarray, landmarks_file: Path,
                    env: dict, params: Path | None = PARAMS) -> subprocess.Popen:
    """ekf_localizer as its own process, with the robots' file unless ``params`` is None
    (the package's defaults)."""
    from_file = ["--params-file", str(params)] if params is not None else []
    localizer = subprocess.Popen(
        [executable("ekf_localizer"), "--ros-args", *from_file,
         "-p", f"landmarks_file:={landmarks_file}", "-p", f"filter:={kind}",
         "-p", "autostart:=true",
         "-p", "initial_pose:=[" + ", ".join(repr(float(v)) for v in initial) + "]"],
        env=env, stdout=(work / "localizer.log").open("w"), stderr=subprocess.STDOUT)
    if not wait_for_line(localizer, work / "localizer.log", "ready:", 120):
        stop_process(localizer)
        sys.exit("ekf_node: the localizer never said ready:\n"
                 + (work / "localizer.log").read_text())
    return localizer


def run_robot(args: argparse.Namespace, work: Path) -> None:
    import rclpy

    run = read_run(args.dataset, args.robot)
    recording = work / "robot.mcap"
    subprocess.run([executable("estimation_import"), "utias", str(args.dataset), "--robot",
                    str(args.robot), "-o", str(recording)], check=True,
                   stdout=subprocess.DEVNULL)
    first_odometry = run.odometry[0, 0]
    initial = np.array([np.interp(first_odometry, run.truth[:, 0], run.truth[:, i])
                        for i in (1, 2)] + [_heading_at(run, first_odometry)])
    env = confine_ros(88)
    landmarks_file = recording.with_suffix(".landmarks.yaml")
    if args.record:
        # beside the recording, for a replay of it later
        landmarks_file = Path(shutil.copy(landmarks_file,
                                          args.record.with_suffix(".landmarks.yaml")))
    parameters_yaml = localizer_parameters(args.filter, initial, landmarks_file)
    (work / "localizer.yaml").write_text(parameters_yaml)
    localizer = start_localizer(work, args.filter, initial, landmarks_file, env,
                                params=work / "localizer.yaml")
    rclpy.init()
    watcher = PoseWatcher()
    recorder = RunRecorder(watcher.node, {
        "/odom": ("nav_msgs/msg/Odometry", 1000),
        "/landmark_observations": ("sensor_msgs/msg/PointCloud2", 1000),
        "/pose": ("geometry_msgs/msg/PoseWithCovarianceStamped", latched_qos(1000))}) \
        if args.record else None
    play = None
    try:
        play = subprocess.Popen(
            [executable("estimation_play"), str(recording), "--rate", f"{args.rate:g}",
             "--topics", "/odom", "/landmark_observations", "--wait-for-subscribers", "30",
             "--delay", "2"], env=env, stdout=(work / "play.log").open("w"),
            stderr=subprocess.STDOUT)
        span = run.odometry[-1, 0] - first_odometry
        limit = args.seconds or span / args.rate + 60
        watcher.spin(lambda: play.poll() is not None, limit)
        if play.poll() is None:
            stop_process(play)
        watcher.spin(lambda: False, 3.0)
    finally:
        end_run(play, localizer, watcher.node)
    rows = report_robot(args, run, initial, watcher)
    if recorder is not None:
        rows += recorder.write_and_replay(
            args.record, {"parameters_yaml": parameters_yaml, "kind": "landmarks"},
            executable("estimation_replay"))
    print(f"ekf_localizer ({args.filter.upper()}) on robot {args.robot}, played at "
          f"{args.rate:g}x, through DDS")
    print(table(["figure", "value"], rows))


def localizer_parameters(kind: str, initial: np.ndarray, landmarks_file: Path) -> str:
    """The robots' file with this run's filter, start and landmarks, as YAML: given to the
    node and kept in a recording."""
    import yaml

    document = yaml.safe_load(PARAMS.read_text(encoding="utf-8"))
    section = document["/**/ekf_localizer"]["ros__parameters"]
    section.update(filter=kind, landmarks_file=str(landmarks_file),
                   initial_pose=[float(v) for v in initial])
    return yaml.safe_dump(document)


def _heading_at(run, t: float) -> float:
    heading = np.unwrap(run.truth[:, 3])
    return math.remainder(float(np.interp(t, run.truth[:, 0], heading)), 2 * math.pi)


def report_robot(args, run, initial: np.ndarray, watcher: PoseWatcher) -> list[list[str]]:
    stamps = sorted(watcher.poses)
    if not stamps:
        sys.exit("ekf_node: no pose was published")
    times = np.array(stamps) / 1e9
    poses = np.array([watcher.poses[s][0] for s in stamps])
    covariances = np.array([watcher.poses[s][1] for s in stamps])
    # scored over what was played (--seconds may play the first part only)
    played = replace(run, truth=run.truth[run.truth[:, 0] <= times[-1]])
    node = score(played, times, poses, covariances)
    # the core on the same events as the node received them, from the same start,
    # compared at the node's stamps
    model = landmark_model({**spec_defaults(LANDMARK_MODEL_SPECS), **file_figures(PARAMS),
                            "filter": args.filter}, run.landmarks)
    started = as_received(replace_truth_start(run, initial))
    core_times, core_poses, _, _, _ = run_filter(started, model, np.diag([0.01] * 3))
    # by the stamps the node saw: the import rounds each time to the nanosecond, and a
    # float comparison could pair a corrected pose with the one before its correction
    core_ns = np.array([seconds_to_ns(t) for t in core_times])
    index = np.searchsorted(core_ns, np.array(stamps), side="right") - 1
    difference = np.hypot(*(core_poses[index, :2] - poses[:, :2]).T)
    rows = [["poses published", str(len(stamps))],
            ["position RMSE", f"{node['position_rmse']:.3f} m"],
            ["heading RMSE", f"{node['heading_rmse_deg']:.1f} deg"],
            ["truth in 95% ellipse", f"{node['in_ellipse']:.0%}"],
            ["longest > 0.5 m", f"{node['longest_off_s']:.1f} s"],
            ["largest difference from the core", f"{difference.max():.2e} m"],
            ["the node's counts", watcher.counts()]]
    return rows


def as_received(run):
    """The run with each detection's range and bearing as the node reads them from a
    landmark cloud: x = range cos(bearing), y = range sin(bearing) in float32, and back."""
    detections = run.detections.copy()
    r, b = detections[:, 2], detections[:, 3]
    x = (r * np.cos(b)).astype(np.float32).astype(np.float64)
    y = (r * np.sin(b)).astype(np.float32).astype(np.float64)
    detections[:, 2], detections[:, 3] = np.hypot(x, y), np.arctan2(y, x)
    return replace(run, detections=detections)


def replace_truth_start(run, initial: np.ndarray):
    """The run as run_filter reads it, starting at ``initial`` at the first odometry."""
    first = np.array([[run.odometry[0, 0], *initial]])
    return replace(run, truth=np.vstack([first, run.truth[run.truth[:, 0] > first[0, 0]]]))


def run_latency(args: argparse.Namespace, work: Path) -> None:
    """The same events to a bare relay (bench/relay_node.py: the least any rclpy node in
    the localizer's place could do) and then to ekf_localizer, side by side."""
    run = read_run(args.dataset, 1)
    landmarks_file = work / "landmarks.yaml"
    landmarks_file.write_text("landmarks:\n" + "".join(
        f"  - {{id: {key}, x: {x!r}, y: {y!r}}}\n" for key, (x, y) in run.landmarks.items()))
    start = np.array([1.0, 0.0, 0.0])
    env = confine_ros(89)
    rows, p99 = [], {}
    for target in ("relay", "ekf_localizer"):
        if target == "relay":
            process = subprocess.Popen([sys.executable, str(RELAY_NODE)],
                                       env=env, stdout=(work / "relay.log").open("w"),
                                       stderr=subprocess.STDOUT)
        else:
            # the simulated frames are euclidean ranges of commands driven at once: the
            # package's defaults
            process = start_localizer(work, args.filter, start, landmarks_file, env,
                                      params=None)
        for kind, count, latencies in _latencies(args, run, start, process):
            p50, p99[target, kind] = np.percentile(latencies, [50, 99])
            ratio = f"{p99[target, kind] / p99['relay', kind]:.2f}" \
                if target != "relay" and ("relay", kind) in p99 else "-"
            rows.append([target, kind, f"{count}", f"{latencies.size}", f"{p50:.2f}",
                         f"{p99[target, kind]:.2f}", f"{latencies.max():.2f}", ratio])
    print(f"ekf_localizer ({args.filter.upper()}): odometry at {ODOM_HZ:g} Hz, frames at "
          f"{FRAME_HZ:g} Hz for {args.seconds:g} s each; event published -> pose received")
    print(table(["answered by", "event", "sent", "poses paired", "p50 ms", "p99 ms",
                 "max ms", "p99 / relay's"], rows))


def _latencies(args: argparse.Namespace, run, start: np.ndarray,
               process: subprocess.Popen) -> list[tuple[str, int, np.ndarray]]:
    """Odometry at ODOM_HZ and frames at FRAME_HZ to ``process`` for args.seconds: per
    kind of event, how many were sent and the latencies (ms) of the poses paired."""
    import rclpy
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import PointCloud2

    from estimation_nodes.core.kalman import range_bearing
    from estimation_nodes.core.kalman.range_bearing import SensorPose
    from estimation_nodes.core.kalman.unicycle import move
    from estimation_nodes.nodes.landmark_messages import landmark_cloud
    from estimation_nodes.nodes.stamps import set_stamp

    rclpy.init()
    watcher = PoseWatcher()
    odom_pub = watcher.node.create_publisher(Odometry, "odom", 100)
    frame_pub = watcher.node.create_publisher(PointCloud2, "landmark_observations", 100)
    sent: dict[int, tuple[str, float]] = {}
    pose, t0 = start.copy(), time.time()
    state = {"step": 0}
    sensor = SensorPose(0.0, 0.0, 0.0)

    def tick() -> None:
        # odometry at 100 Hz; a camera frame every third or fourth tick (30 Hz)
        nonlocal pose
        step = state["step"]
        state["step"] += 1
        t_ns = int((t0 + step / ODOM_HZ) * 1e9)
        v, w = 0.2, 0.3 * math.sin(step / 300)
        pose = move(pose, v, w, 1 / ODOM_HZ)
        msg = Odometry()
        set_stamp(msg.header, t_ns, "odom")
        msg.twist.twist.linear.x, msg.twist.twist.angular.z = v, w
        sent[t_ns] = ("odom", time.perf_counter())
        odom_pub.publish(msg)
        if int((step + 1) * FRAME_HZ / ODOM_HZ) > int(step * FRAME_HZ / ODOM_HZ):
            seen = []
            for key, landmark in run.landmarks.items():
                r, b = range_bearing.expected(pose, landmark, sensor)
                if abs(b) < 0.5:
                    seen.append((key, r, b))
            frame_ns = t_ns + 1000   # a stamp of its own, after the odometry's
            sent[frame_ns] = ("frame", time.perf_counter())
            frame_pub.publish(landmark_cloud(frame_ns, "camera", seen))

    try:
        watcher.spin(lambda: odom_pub.get_subscription_count() > 0
                     and frame_pub.get_subscription_count() > 0, 30)
        watcher.spin(lambda: False, 1.0)
        timer = watcher.node.create_timer(1 / ODOM_HZ, tick)
        watcher.spin(lambda: False, args.seconds)
        timer.cancel()
        watcher.spin(lambda: False, 2.0)
    finally:
        end_run(None, process, watcher.node)
    measured = []
    for kind in ("odom", "frame"):
        latencies = np.array([1e3 * (watcher.poses[s][2] - at) for s, (k, at) in sent.items()
                              if k == kind and s in watcher.poses])
        if latencies.size:
            measured.append((kind, sum(1 for k, _ in sent.values() if k == kind), latencies))
    return measured


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("mode", choices=("run", "latency"))
    parser.add_argument("--dataset", type=Path, default=DATASET)
    parser.add_argument("--robot", type=int, default=1)
    parser.add_argument("--filter", choices=("ekf", "ukf"), default="ekf")
    parser.add_argument("--rate", type=float, default=1.0,
                        help="play at this many times real time (run)")
    parser.add_argument("--record", type=Path, metavar="FILE.mcap",
                        help="run: record it and check it with estimation_replay")
    parser.add_argument("--seconds", type=float, default=0.0,
                        help="run: play only this long; latency: default 30")
    args = parser.parse_args()
    if not args.dataset.is_dir():
        sys.exit(f"ekf_node: no dataset at {args.dataset} (see ../shared/data/README.md)")
    with tempfile.TemporaryDirectory() as work:
        if args.mode == "run":
            run_robot(args, Path(work))
        else:
            args.seconds = args.seconds or 30.0
            run_latency(args, Path(work))


if __name__ == "__main__":
    main()
