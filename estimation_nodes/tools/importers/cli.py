"""estimation_import: a real robot's log as a ROS 2 recording (MCAP), in the layout --record
writes, so that estimation_play, estimation_replay, ros2 bag and Foxglove read it.

    estimation_import carmen LOG -o run.mcap [--range-max M] [--scan-rate HZ]
                             [--laser-ahead M]
    estimation_import utias DATASET_DIR --robot N -o run.mcap [--landmarks-file FILE]
    estimation_import rosbag BAG -o run.mcap [--topics /imu/data /odom ...]

CARMEN (FLASER or ROBOTLASER1 scans): /scan (sensor_msgs/LaserScan with the log's
angles, range_max and remissions as intensities, frame ``laser``), /odom
(nav_msgs/Odometry at every odometry line: the raw odometry pose and twist, ``odom`` ->
``base_link``; from the scan lines' odometry fields in a log without ODOM lines),
the tf tree a robot records (/tf: ``odom`` -> ``base_link`` at every odometry line;
/tf_static: ``base_link`` -> ``laser``, ``--laser-ahead`` m forward), /ground_truth
(geometry_msgs/PoseStamped in ``map``: the log's corrected pose at each scan; none for a
raw log, see ``carmen``). UTIAS: /odom (the twist, and the pose it dead-reckons),
/landmark_observations (sensor_msgs/PointCloud2, one per camera frame: x = range
cos(bearing), y = range sin(bearing), z = 0, id = the landmark's subject number),
/ground_truth (Vicon), and a landmarks file (YAML). rosbag (a ROS 1 ``.bag`` or a rosbag2
folder, MCAP or sqlite3, read through ``rosbags``): every message as this ROS 2's type at
its receive time, a topic whose type is not installed here left out and said.
Every message is stamped with the log's time (CARMEN: with ``--scan-rate``, the scans at
that rate in the log's order and the odometry evenly between them, for a log whose times
do not advance). What was left out is counted and reported; a log that cannot be read is
one line and exit code 2.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections import Counter
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from estimation_nodes.nodes.grid_messages import fill_pose
from estimation_nodes.nodes.landmark_messages import landmark_cloud
from estimation_nodes.nodes.stamps import set_stamp
from estimation_nodes.tools.importers import carmen, utias
from estimation_nodes.tools.recording.mcap import McapRunWriter, RecordingError

LASER_SCAN = "sensor_msgs/msg/LaserScan"
ODOMETRY = "nav_msgs/msg/Odometry"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
POINT_CLOUD = "sensor_msgs/msg/PointCloud2"


def seconds_to_ns(t: float) -> int:
    """A log's time in seconds as the importers stamp it: rounded to the nanosecond."""
    return int(round(t * 1e9))


def _stamp(header, t: float, frame_id: str) -> None:
    set_stamp(header, seconds_to_ns(t), frame_id)


class _Writer:
    """Messages to MCAP in time order, counted by topic."""

    def __init__(self, path: Path, topics: dict[str, str], source: str) -> None:
        self._file = McapRunWriter(path, topics, {"source": source,
                                                  "importer": "estimation_import"})
        self._pending: list[tuple[int, int, str, bytes]] = []
        self.counts: Counter[str] = Counter()

    def add(self, topic: str, t: float, msg) -> None:
        from rclpy.serialization import serialize_message

        self._pending.append((seconds_to_ns(t), len(self._pending), topic, serialize_message(msg)))
        self.counts[topic] += 1

    def close(self) -> None:
        for ns, _, topic, data in sorted(self._pending):
            self._file.write(topic, data, ns, ns)
        self._file.close()


def import_carmen(log_path: Path, out: Path, range_max: float | None,
                  scan_rate: float | None = None, laser_ahead: float = 0.0) -> list[str]:
    """The log as a recording: /scan, /odom, the tf tree (/tf: odom -> base_link at every
    odometry line, /tf_static: base_link -> laser) and, for a corrected log,
    /ground_truth. With ``laser_ahead`` the robot's frame is put that far (m) behind the
    laser, as on a robot whose laser is mounted forward: the odometry and the truth are
    then base_link's, the scans stay the laser's."""
    from geometry_msgs.msg import PoseStamped
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import LaserScan
    from tf2_msgs.msg import TFMessage

    from estimation_nodes.core.geometry import compose
    from estimation_nodes.core.transforms.rigid import Transform
    from estimation_nodes.nodes.tf import to_message

    def base_of(pose):
        """base_link's pose, given the laser's (the log's poses are the laser's)."""
        return compose(pose, (-laser_ahead, 0.0, 0.0))

    log = carmen.read_log(log_path, scan_rate)
    limit, origin = log.max_reading, "the log's largest reading"
    if range_max is not None:
        limit, origin = range_max, "given"
    elif log.laser_range_max is not None and log.laser_range_max <= limit:
        limit, origin = log.laser_range_max, "the laser's maximum_range"
    topics = {"/scan": LASER_SCAN, "/odom": ODOMETRY, "/tf": TF_MESSAGE,
              "/tf_static": TF_MESSAGE}
    if log.corrected:
        topics["/ground_truth"] = POSE_STAMPED
    writer = _Writer(out, topics, str(log_path))
    first = min([scan.t for scan in log.scans] + [sample.t for sample in log.odometry])
    mount = to_message("base_link", "laser", seconds_to_ns(first),
                       Transform.planar(laser_ahead, 0.0, 0.0))
    writer.add("/tf_static", first, TFMessage(transforms=[mount]))
    for scan in log.scans:
        n = scan.ranges.size
        msg = LaserScan()
        _stamp(msg.header, scan.t, "laser")
        msg.angle_min, msg.angle_increment = scan.angle_min, scan.angle_increment
        msg.angle_max = msg.angle_min + (n - 1) * msg.angle_increment
        msg.range_min, msg.range_max = 0.0, float(limit)
        msg.ranges = scan.ranges.tolist()
        msg.intensities = scan.remissions.tolist()
        writer.add("/scan", scan.t, msg)
        if not log.corrected:
            continue
        truth = PoseStamped()
        _stamp(truth.header, scan.t, "map")
        fill_pose(truth.pose, *base_of(scan.pose))
        writer.add("/ground_truth", scan.t, truth)
    for sample in log.odometry:
        pose = base_of(sample.pose)
        odom = Odometry()
        _stamp(odom.header, sample.t, "odom")
        odom.child_frame_id = "base_link"
        fill_pose(odom.pose.pose, *pose)
        odom.twist.twist.linear.x, odom.twist.twist.angular.z = sample.tv, sample.rv
        writer.add("/odom", sample.t, odom)
        writer.add("/tf", sample.t, TFMessage(transforms=[to_message(
            "odom", "base_link", seconds_to_ns(sample.t), Transform.planar(*pose))]))
    writer.close()
    notes = [f"range_max {limit:g} m ({origin})"]
    if laser_ahead:
        notes.append(f"base_link {laser_ahead:g} m behind the laser (--laser-ahead): "
                     f"/odom, /tf and /ground_truth are base_link's, the scans the laser's")
    if scan_rate is not None:
        notes.append(f"times placed at {scan_rate:g} Hz from {log.scans[0].t:.3f} s "
                     f"(--scan-rate): the scans in the log's order, the odometry evenly "
                     f"between them")
    if log.odometry_from_scans:
        notes.append("/odom from the scan lines' odometry fields (the log has no ODOM "
                     "line)")
    if log.mount is not None:
        x, y, yaw = log.mount
        how = "equals the odometry pose" if log.mount == (0.0, 0.0, 0.0) else (
            f"is the odometry pose moved by one fixed mount (x {x:.3f} m, y {y:.3f} m, "
            f"yaw {yaw:.4f} rad)")
        notes.append(f"no /ground_truth: the laser pose {how} on every scan line and the "
                     f"odometry never restarts at a scan (a raw log, not corrected)")
    if log.odometry_reordered:
        notes.append(f"{log.odometry_reordered} odometry lines reordered by time (the "
                     f"log's time ran back; every line kept, sorted stably by time)")
    return _report(writer.counts, log.left_out, notes)


def import_utias(directory: Path, robot: int, out: Path,
                 landmarks_file: Path | None) -> list[str]:
    from geometry_msgs.msg import PoseStamped
    from nav_msgs.msg import Odometry

    run = utias.read_run(directory, robot)
    writer = _Writer(out, {"/odom": ODOMETRY, "/landmark_observations": POINT_CLOUD,
                           "/ground_truth": POSE_STAMPED}, f"{directory} robot {robot}")
    pose = tuple(run.truth[0, 1:])
    previous_t, twist = run.odometry[0, 0], (0.0, 0.0)
    for t, v, w in run.odometry:
        pose = _dead_reckoned(pose, twist, t - previous_t)
        previous_t, twist = t, (v, w)
        odom = Odometry()
        _stamp(odom.header, t, "odom")
        odom.child_frame_id = "base_link"
        fill_pose(odom.pose.pose, *pose)
        odom.twist.twist.linear.x, odom.twist.twist.angular.z = float(v), float(w)
        writer.add("/odom", t, odom)
    for t, rows in run.frames():
        seen = [(int(key), float(r), float(b)) for _, key, r, b in rows]
        writer.add("/landmark_observations", t, landmark_cloud(seconds_to_ns(t), "camera", seen))
    for t, x, y, theta in run.truth:
        truth = PoseStamped()
        _stamp(truth.header, t, "map")
        fill_pose(truth.pose, x, y, theta)
        writer.add("/ground_truth", t, truth)
    writer.close()
    target = landmarks_file or out.with_suffix(".landmarks.yaml")
    _write_landmarks(target, run.landmarks, directory)
    return _report(writer.counts, run.left_out, [f"landmarks written to {target}"])


def import_rosbag(bag: Path, out: Path, topics: set[str] | None) -> list[str]:
    """A robot's bag (ROS 1, or a rosbag2 folder) as one of the package's recordings: each
    message as this ROS 2's type (tools/recording/bags.py), at its receive time; topics of
    types not installed here left out and said."""
    from rclpy.serialization import serialize_message

    from estimation_nodes.tools.recording.bags import bag_messages, is_bag, left_out_notes

    if not is_bag(bag):
        raise RecordingError(f"{bag}: not a ROS 1 bag (.bag) or a rosbag2 folder "
                             f"(metadata.yaml)")
    left_out: dict[str, str] = {}
    messages = list(bag_messages(bag, topics, left_out=left_out))
    if not messages:
        raise RecordingError(f"{bag}: no message on the topics asked for")
    writer = McapRunWriter(out, {topic: type_name for _, topic, type_name, _ in messages},
                           {"source": str(bag)})
    counts: Counter[str] = Counter()
    for stamp, topic, _, msg in messages:
        writer.write(topic, serialize_message(msg), stamp, stamp)
        counts[topic] += 1
    writer.close()
    return _report(counts, Counter(), left_out_notes(left_out))


def _dead_reckoned(pose, twist, dt: float):
    from estimation_nodes.core.kalman.unicycle import move

    return tuple(move(np.array(pose), twist[0], twist[1], max(dt, 0.0)).tolist())


def _write_landmarks(path: Path, landmarks: dict[int, tuple[float, float]],
                     source: Path) -> None:
    lines = [f"# Landmarks of {source} (subject number, x and y in m, map frame)",
             "landmarks:"]
    lines += [f"  - {{id: {key}, x: {x!r}, y: {y!r}}}" for key, (x, y) in
              sorted(landmarks.items())]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def _report(counts: Counter[str], left_out: Counter[str], notes: list[str]) -> list[str]:
    lines = [f"{topic}: {count} messages" for topic, count in sorted(counts.items())]
    lines += [f"left out: {count} {what}" for what, count in sorted(left_out.items())
              if count]
    return lines + notes


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="estimation_import",
                                     description=__doc__.split("\n")[0])
    kinds = parser.add_subparsers(dest="kind", required=True)
    c = kinds.add_parser("carmen", help="a CARMEN laser log (plain or .gz)")
    c.add_argument("log", type=Path)
    c.add_argument("--range-max", type=float,
                   help="readings at or above this are no return (default: the log's "
                        "largest reading, or the laser's own maximum range where every "
                        "ROBOTLASER1 line gives one not above it)")
    c.add_argument("--scan-rate", type=float, metavar="HZ",
                   help="place the scans at this rate in the log's order, from the first "
                        "scan's time, and the odometry evenly between them: for a log "
                        "whose times do not advance (printed with too few digits)")
    c.add_argument("--laser-ahead", type=float, default=0.0, metavar="M",
                   help="the laser this far ahead of base_link (/tf_static base_link -> "
                        "laser): the robot's frame, its odometry and its truth are put that "
                        "far behind the laser's poses the log gives (default: 0)")
    u = kinds.add_parser("utias", help="one robot of a UTIAS MRCLAM dataset folder")
    u.add_argument("dataset", type=Path)
    u.add_argument("--robot", type=int, required=True)
    u.add_argument("--landmarks-file", type=Path,
                   help="where to write the landmarks (default: OUT.landmarks.yaml)")
    r = kinds.add_parser("rosbag", help="a robot's bag: ROS 1 (.bag) or a rosbag2 folder "
                                        "(MCAP or sqlite3)")
    r.add_argument("bag", type=Path)
    r.add_argument("--topics", nargs="+", metavar="TOPIC",
                   help="only these topics (default: every topic of an installed type)")
    for sub in (c, u, r):
        sub.add_argument("-o", "--output", type=Path, required=True, metavar="FILE.mcap")
    args = parser.parse_args(argv)
    if args.kind == "carmen" and args.range_max is not None \
            and not (math.isfinite(args.range_max) and args.range_max > 0):
        parser.error("--range-max must be a finite number > 0")
    if args.kind == "carmen" and not math.isfinite(args.laser_ahead):
        parser.error("--laser-ahead must be a finite number")
    if args.kind == "carmen" and args.scan_rate is not None \
            and not (math.isfinite(args.scan_rate) and args.scan_rate > 0):
        parser.error("--scan-rate must be a finite number > 0")
    return args


def main(argv: Sequence[str] | None = None) -> None:
    args = parse_args(argv)
    try:
        if args.kind == "carmen":
            lines = import_carmen(args.log, args.output, args.range_max, args.scan_rate,
                                  args.laser_ahead)
        elif args.kind == "rosbag":
            topics = {t if t.startswith("/") else f"/{t}" for t in args.topics} \
                if args.topics else None
            lines = import_rosbag(args.bag, args.output, topics)
        else:
            lines = import_utias(args.dataset, args.robot, args.output, args.landmarks_file)
    except (carmen.LogError, utias.DatasetError, RecordingError) as error:
        print(f"estimation_import: {error}", file=sys.stderr)
        sys.exit(2)
    for line in lines:
        print(f"estimation_import: {line}")
    print(f"estimation_import: wrote {args.output}")


if __name__ == "__main__":
    main()
