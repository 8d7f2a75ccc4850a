"""``estimation_fuse``: a bag through ekf_node's / ukf_node's filter in-process, in seconds.

Reads a ROS 1 bag or a rosbag2 recording (MCAP or sqlite3) with the ``rosbags`` library,
takes the inputs a robot_localization parameter file names, and runs the same filter
loop the node runs under ``use_sim_time``: messages reach the filter at their recorded
time, the periodic update runs at ``frequency`` on the bag's clock. It prints the final
filtered pose (and writes every periodic output with ``--csv``).
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from estimation_nodes.core.fusion.control import DroppedCommand, command_message
from estimation_nodes.core.fusion.filter import FusionFilter
from estimation_nodes.core.fusion.inputs import Mount
from estimation_nodes.core.fusion.sensors import SensorInputs, gyro_biases
from estimation_nodes.params.fusion import FusionConfig, FusionConfigError, fusion_config, \
    parameters_of_file
from estimation_nodes.tools.recording import bags

#: The velocity command's topic (the peer's, under use_control).
CONTROL_TOPIC = "cmd_vel"


@dataclass
class FusionRun:
    """What a run left: the filter, its inputs' counters, the periodic outputs."""

    fusion: FusionFilter
    inputs: SensorInputs
    #: (stamp ns, the 15-entry state) of each periodic output.
    outputs: list[tuple[int, np.ndarray]]
    #: The 15 x 15 covariance of each periodic output, when the run was asked to keep them.
    covariances: list[np.ndarray]


def bag_messages(path: Path, topics: set[str]):
    """(receive time ns, topic, message) in recorded order, from any bag ``rosbags`` reads
    (the one bag reader: tools/recording/bags.py), as ``rosbags`` decoded them: the inputs
    read fields by name, as of an rclpy message."""
    for timestamp, topic, _, msg in bags.bag_messages(path, topics, as_rclpy=False):
        yield timestamp, topic, msg


def run(config: FusionConfig, messages, mounts: dict[str, Mount] | None = None,
        keep_covariances: bool = False) -> FusionRun:
    """The node's loop over recorded messages: callbacks between periodic updates."""
    fusion = FusionFilter(config.settings)
    sensor_inputs = config.sensor_inputs(mounts)
    by_topic = {}
    for sensor in config.sensors.values():
        by_topic.setdefault(sensor.topic.lstrip("/"), []).append(sensor)
    period_ns = round(1e9 / config.frequency)
    next_tick: int | None = None
    outputs: list[tuple[int, np.ndarray]] = []
    covariances: list[np.ndarray] = []

    def tick(now_ns: int) -> None:
        fusion.update(now_ns)
        fusion.differentiate(now_ns)
        if fusion.initialized:
            outputs.append((fusion.last_time_ns, fusion.x.copy()))
            if keep_covariances:
                covariances.append(fusion.p.copy())

    for received_ns, topic, msg in messages:
        if next_tick is None:
            next_tick = received_ns + period_ns
        while next_tick <= received_ns:
            tick(next_tick)
            next_tick += period_ns
        if fusion.control is not None and topic.lstrip("/") == CONTROL_TOPIC:
            take_command(fusion, msg, received_ns, config)
        for sensor in by_topic.get(topic.lstrip("/"), []):
            sensor_inputs.add(sensor, msg, fusion)
    if next_tick is not None:
        tick(next_tick)
    return FusionRun(fusion, sensor_inputs, outputs, covariances)


def take_command(fusion: FusionFilter, msg, received_ns: int, config: FusionConfig) -> None:
    """A recorded velocity command into the filter, as the node takes it
    (``control.command_message``; one the node drops is left out)."""
    try:
        command, stamp_ns = command_message(msg, config.stamped_control, received_ns,
                                            config.base_link_frame)
    except DroppedCommand:
        return
    fusion.command(command, stamp_ns)


def parse_mount(text: str) -> tuple[str, Mount]:
    """``FRAME=x,y,z,roll,pitch,yaw`` (m, rad): a sensor frame's pose on the robot."""
    frame, _, numbers = text.partition("=")
    values = [float(v) for v in numbers.split(",")]
    if not frame or len(values) != 6 or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(
            f"--mount {text!r}: expected FRAME=x,y,z,roll,pitch,yaw (m, rad)")
    return frame, Mount.from_rpy(tuple(values[:3]), tuple(values[3:]))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="estimation_fuse", description=__doc__.split("\n")[0])
    parser.add_argument("bag", type=Path, help="a ROS 1 .bag, or a rosbag2 folder or .mcap")
    parser.add_argument("--params-file", required=True,
                        help="robot_localization parameter file (unchanged)")
    parser.add_argument("--node", help="the node's name in the file (default: the first)")
    parser.add_argument("--filter", choices=("ekf", "ukf"),
                        help="override the file's filter_type")
    parser.add_argument("--mount", action="append", type=parse_mount, default=[],
                        help="FRAME=x,y,z,roll,pitch,yaw: a sensor's mount on base_link "
                             "(the bag has no /tf_static); repeat per frame")
    args = parser.parse_args(argv)
    try:
        config = fusion_config(parameters_of_file(args.params_file, args.node), args.filter)
    except (FusionConfigError, OSError) as error:
        print(f"estimation_fuse: {error}", file=sys.stderr)
        return 2
    for name in config.unsupported:
        print(f"estimation_fuse: parameter {name} is not supported yet: ignored")
    for note in config.notes:
        print(f"estimation_fuse: {note}")
    if not args.bag.exists():
        print(f"estimation_fuse: {args.bag}: no such bag", file=sys.stderr)
        return 2
    names = [s.topic for s in config.sensors.values()] + \
        ([CONTROL_TOPIC] if config.settings.control else [])
    topics = {t for name in names for t in (name, name.lstrip("/"), "/" + name.lstrip("/"))}
    result = run(config, bag_messages(args.bag, topics), dict(args.mount))
    x = result.fusion.x
    print(f"{config.settings.kind}: final position x {x[0]:.4f} y {x[1]:.4f} z {x[2]:.4f} m, "
          f"roll {x[3]:.4f} pitch {x[4]:.4f} yaw {x[5]:.4f} rad "
          f"({len(result.outputs)} periodic outputs)")
    print(f"measurements applied {result.fusion.counts.applied}, "
          f"rejected {result.fusion.counts.rejected}, dropped {result.inputs.dropped}")
    for name, bias in gyro_biases(config.sensors, x).items():
        print(f"{name} gyro bias {' '.join(f'{v:.6f}' for v in bias)} rad/s (roll, pitch, "
              f"yaw rates)")
    if config.settings.history_ns is not None:
        print(f"late, put in their place {result.fusion.counts.smoothed}, "
              f"older than history_length {result.fusion.counts.beyond_history}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
