"""ekf_node / ukf_node as a process: reading published -> odometry/filtered received.

    python bench/fusion/fusion_node.py latency [--bag test1.bag|test2.bag] [--filter ekf|ukf]
        [--seconds 30] [--rounds 2]

The peer's bag's odometry and IMU messages (../shared/data/robot_localization; test1.bag:
the IMU at 30 Hz and the wheel odometry at 10 Hz, test2.bag: both at 50 Hz) are published
from this process at their recorded spacing, stamped with the time they are sent, to
``ekf_node`` (or ``ukf_node``) started with the peer's parameter file for that bag (its
``frequency``: 30 Hz for test1, 50 Hz for test2), on the wall clock, the IMU's mount of
test1 given by ``sensor_mounts``. The node queues each reading and its timer takes the
queue and publishes the estimate, stamped with the newest reading it took: a reading
is answered by the first output stamped at or after it, and its latency is that
output's arrival here less the reading's publication (DDS both ways included; the wait
for the node's next periodic update too, up to 1 / frequency, by the peer's design).

The reference, in alternating rounds with the node: bench/relay_node.py ``fusion``, a
bare rclpy node that answers every reading at once with an empty Odometry of the same
header, the node's QoS on both sides: the least any rclpy node in the filter's place
could do. Printed: p50, p99 and the largest latency of each, and the ratio of the
node's p99 to the relay's. Nothing is asserted.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

sys.path.insert(1, str(Path(__file__).resolve().parents[2]))  # the repository: bench
from bench.common import RELAY_NODE, confine_ros, executable, table  # noqa: E402
from bench.fusion.fusion_offline import BAGS, FILES, HUSKY_IMU_MOUNT, SHARED  # noqa: E402

from estimation_nodes.params.fusion import fusion_config, parameters_of_file  # noqa: E402
from estimation_nodes.tools.demo.graph_runtime import spin_until, stop_process  # noqa: E402
from estimation_nodes.tools.recording import bags  # noqa: E402

#: This bench's ROS domain (bench/common.py).
DOMAIN = 92


def node_name(params: Path) -> str:
    """The node's name in the peer's file (its parameters are under it)."""
    return next(iter(yaml.safe_load(params.read_text())))


def readings(bag: str, topics: set[str], seconds: float) -> list[tuple[float, str, object]]:
    """(seconds after the first, topic, rclpy message) for the bag's first ``seconds``."""
    chosen, first = [], None
    for stamp, topic, _, msg in bags.bag_messages(SHARED / bag, topics):
        first = stamp if first is None else first
        if (stamp - first) * 1e-9 > seconds:
            break
        chosen.append(((stamp - first) * 1e-9, topic, msg))
    return chosen


class Listener:
    """The bench's node: publishes the readings, keeps every output's stamp and arrival."""

    def __init__(self, inputs: dict[str, str]) -> None:
        from nav_msgs.msg import Odometry
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node
        from sensor_msgs.msg import Imu

        self.node = Node("fusion_node_bench")
        self.publishers = {topic: self.node.create_publisher(
            Odometry if kind == "odom" else Imu, topic, 100) for topic, kind in inputs.items()}
        self.outputs: list[tuple[int, float]] = []
        self.node.create_subscription(Odometry, "odometry/filtered", self._on_output, 100)
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)

    def _on_output(self, msg) -> None:
        arrived = time.perf_counter()
        self.outputs.append((msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec, arrived))

    def connected(self) -> bool:
        return all(p.get_subscription_count() > 0 for p in self.publishers.values()) and \
            self.node.count_publishers("odometry/filtered") > 0

    def play(self, chosen: list[tuple[float, str, object]]) -> list[tuple[int, float]]:
        """Publish each reading at its offset, stamped now; (stamp ns, publication time)."""
        sent, last_ns = [], 0
        start = time.perf_counter()
        for offset, topic, msg in chosen:
            while (wait := start + offset - time.perf_counter()) > 0:
                self.executor.spin_once(timeout_sec=min(wait, 0.005))
            stamp_ns = max(time.time_ns(), last_ns + 1)   # one stamp per reading
            last_ns = stamp_ns
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 10**9)
            sent.append((stamp_ns, time.perf_counter()))
            self.publishers[topic].publish(msg)
        spin_until(self.executor, lambda: False, 1.0)
        return sent


def latencies(sent: list[tuple[int, float]], outputs: list[tuple[int, float]]) -> np.ndarray:
    """Per reading answered, ms from its publication to the first output arriving after it
    stamped at or after it."""
    found = []
    for stamp, published in sent:
        answer = next((arrived for output_stamp, arrived in outputs
                       if output_stamp >= stamp and arrived >= published), None)
        if answer is not None:
            found.append(1e3 * (answer - published))
    return np.array(found)


def start(target: str, bag: str, kind: str, inputs: dict[str, str], work: Path,
          env: dict) -> subprocess.Popen:
    log = work / f"{target}.log"
    if target == "relay":
        command = [sys.executable, str(RELAY_NODE), "fusion",
                   *(f"{topic}:{k}" for topic, k in inputs.items())]
    else:
        params = FILES / f"test_{kind}_localization_node_bag{BAGS[bag]}.yaml"
        # (an empty list on the command line has no type rclpy can declare: none given)
        mounts = ["-p", f'sensor_mounts:=["{HUSKY_IMU_MOUNT}"]'] if bag == "test1.bag" else []
        command = [executable(f"{kind}_node"), "--ros-args", "-r",
                   f"__node:={node_name(params)}", "--params-file", str(params),
                   "-p", "use_sim_time:=false", *mounts, "--log-level", "warn"]
    return subprocess.Popen(command, env=env, stdout=log.open("w"), stderr=subprocess.STDOUT)


def run_latency(args: argparse.Namespace, work: Path) -> None:
    import rclpy

    params = FILES / f"test_{args.filter}_localization_node_bag{BAGS[args.bag]}.yaml"
    config = fusion_config(parameters_of_file(str(params)))
    inputs = {sensor.topic: sensor.kind for sensor in config.sensors.values()}
    chosen = readings(args.bag, set(inputs), args.seconds)
    env = confine_ros(DOMAIN)
    target_name = f"{args.filter}_node"
    results: dict[str, list[np.ndarray]] = {"relay": [], target_name: []}
    counts: dict[str, list[tuple[int, int]]] = {"relay": [], target_name: []}
    rclpy.init()
    try:
        for _ in range(args.rounds):
            for target in ("relay", target_name):
                listener = Listener(inputs)
                process = start(target, args.bag, args.filter, inputs, work, env)
                try:
                    if not spin_until(listener.executor, listener.connected, 60):
                        sys.exit(f"fusion_node: {target} never connected:\n"
                                 + (work / f"{target}.log").read_text())
                    spin_until(listener.executor, lambda: False, 1.0)
                    sent = listener.play(chosen)
                finally:
                    stop_process(process)
                    listener.node.destroy_node()
                found = latencies(sent, listener.outputs)
                results[target].append(found)
                counts[target].append((len(sent), found.size))
    finally:
        rclpy.try_shutdown()
    rows, relay_p99 = [], None
    for target in ("relay", target_name):
        values = np.concatenate(results[target])
        p50, p99 = np.percentile(values, [50, 99])
        relay_p99 = p99 if target == "relay" else relay_p99
        sent = sum(s for s, _ in counts[target])
        answered = sum(a for _, a in counts[target])
        rows.append([target, str(sent), str(answered), f"{p50:.2f}", f"{p99:.2f}",
                     f"{values.max():.2f}",
                     "-" if target == "relay" else f"{p99 / relay_p99:.1f}"])
    print(f"{args.bag} ({', '.join(f'{t} {k}' for t, k in inputs.items())}) for "
          f"{args.seconds:g} s at the recorded spacing, {args.rounds} alternating rounds; "
          f"{target_name} at {config.frequency:g} Hz; reading published -> "
          "odometry/filtered received")
    print(table(["answered by", "readings sent", "answered", "p50 ms", "p99 ms", "max ms",
                 "p99 / relay's"], rows))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("mode", choices=("latency",))
    parser.add_argument("--bag", choices=tuple(BAGS), default="test1.bag")
    parser.add_argument("--filter", choices=("ekf", "ukf"), default="ekf")
    parser.add_argument("--seconds", type=float, default=30.0,
                        help="how much of the bag to play, per round (30)")
    parser.add_argument("--rounds", type=int, default=2, help="alternating rounds (2)")
    args = parser.parse_args()
    if not SHARED.is_dir():
        sys.exit(f"fusion_node: no bags at {SHARED} (see ../shared/data/README.md)")
    with tempfile.TemporaryDirectory() as work:
        run_latency(args, Path(work))


if __name__ == "__main__":
    main()
