"""estimation_map: a map_server map (YAML + PGM, trinary) from a recording's scans at its
/ground_truth poses, by occupancy grid mapping with known poses (core/grid/mapping.py),
cropped to what the scans saw.

    estimation_map run.mcap -o STEM [--resolution 0.05]

Each /scan is placed at the /ground_truth pose of its stamp (the nearest one within
``--max-pose-gap`` seconds; a scan without one is counted and left out); the laser's
mounting pose on the robot is ``--laser-pose X Y YAW`` (default 0 0 0).
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from estimation_nodes.core.grid.mapping import MappingModel, OccupancyGridMapper
from estimation_nodes.nodes.grid_messages import planar_pose
from estimation_nodes.nodes.stamps import stamp_ns
from estimation_nodes.params.map_files import write_map_file
from estimation_nodes.tools.recording.mcap import RecordingError


def _stamp_ns(msg) -> int:
    return stamp_ns(msg.header.stamp)


def recorded(path: Path) -> tuple[list, list]:
    """The recording's scans and ground-truth poses, each decoded, in stamp order."""
    try:
        from mcap.exceptions import McapError
        from mcap.reader import make_reader
        from mcap_ros2.decoder import DecoderFactory
    except ImportError:
        raise RecordingError("reading recordings needs the 'record' extra: "
                             "pip install 'estimation_nodes[record]'") from None
    if not path.is_file():
        raise RecordingError(f"{path} is not a file")
    scans, poses = [], []
    try:
        with path.open("rb") as stream:
            reader = make_reader(stream, decoder_factories=[DecoderFactory()])
            for _s, channel, _m, msg in reader.iter_decoded_messages(
                    topics=["/scan", "/ground_truth"]):
                (scans if channel.topic == "/scan" else poses).append(msg)
    except (McapError, ValueError, EOFError) as error:
        raise RecordingError(f"{path} is not a readable MCAP recording: {error}") from None
    if not scans or not poses:
        raise RecordingError(f"{path}: expected /scan and /ground_truth messages, got "
                             f"{len(scans)} and {len(poses)}")
    return sorted(scans, key=_stamp_ns), sorted(poses, key=_stamp_ns)


def build_map(scans: list, poses: list, resolution: float, laser: tuple[float, float, float],
              max_gap_s: float) -> tuple[OccupancyGridMapper, int]:
    """The mapper after every scan that has a pose; and how many had none."""
    mapper = OccupancyGridMapper(MappingModel(resolution))
    times = np.array([_stamp_ns(p) for p in poses])
    left_out = 0
    for scan in scans:
        t = _stamp_ns(scan)
        k = int(np.argmin(np.abs(times - t)))
        if abs(times[k] - t) > max_gap_s * 1e9:
            left_out += 1
            continue
        x, y, yaw = planar_pose(poses[k].pose)
        c, s = math.cos(yaw), math.sin(yaw)
        sensor = (x + c * laser[0] - s * laser[1], y + s * laser[0] + c * laser[1],
                  yaw + laser[2])
        ranges = np.asarray(scan.ranges, dtype=np.float64)
        angles = scan.angle_min + scan.angle_increment * np.arange(ranges.size)
        usable = ranges >= scan.range_min
        mapper.add_scan(sensor, np.where(usable, ranges, np.inf), angles, scan.range_max)
    return mapper, left_out


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="estimation_map", description=__doc__.split("\n")[0])
    parser.add_argument("recording", type=Path)
    parser.add_argument("-o", "--output", type=Path, required=True, metavar="STEM",
                        help="writes STEM.yaml and STEM.pgm")
    parser.add_argument("--resolution", type=float, default=0.05, help="m per cell "
                        "(default: %(default)s)")
    parser.add_argument("--laser-pose", type=float, nargs=3, default=(0.0, 0.0, 0.0),
                        metavar=("X", "Y", "YAW"))
    parser.add_argument("--max-pose-gap", type=float, default=0.05, metavar="SECONDS",
                        help="a scan more than this from every pose is left out "
                             "(default: %(default)s)")
    args = parser.parse_args(argv)
    if not (math.isfinite(args.resolution) and args.resolution > 0):
        parser.error("--resolution must be a finite number > 0")
    if not all(math.isfinite(v) for v in args.laser_pose):
        parser.error("--laser-pose must be three finite numbers")
    if not args.output.parent.is_dir():
        parser.error(f"-o: folder {args.output.parent} does not exist")
    return args


def main(argv: Sequence[str] | None = None) -> None:
    args = parse_args(argv)
    try:
        scans, poses = recorded(args.recording)
    except RecordingError as error:
        print(f"estimation_map: {error}", file=sys.stderr)
        sys.exit(2)
    mapper, left_out = build_map(scans, poses, args.resolution, tuple(args.laser_pose),
                                 args.max_pose_gap)
    try:
        occupancy = mapper.occupancy()
    except ValueError as error:
        print(f"estimation_map: {error}", file=sys.stderr)
        sys.exit(2)
    path = write_map_file(args.output, occupancy)
    rows, cols = occupancy.cells.shape
    print(f"estimation_map: {len(scans) - left_out} scans mapped"
          + (f", {left_out} left out (no pose within {args.max_pose_gap} s)" if left_out else "")
          + f"; {cols} x {rows} cells of {args.resolution} m "
          f"({cols * args.resolution:.1f} m x {rows * args.resolution:.1f} m)")
    print(f"estimation_map: wrote {path}")


if __name__ == "__main__":
    main()
