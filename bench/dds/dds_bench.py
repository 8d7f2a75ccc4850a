"""Latency and throughput through DDS: the estimator against a bare rclpy relay.

    python bench/dds/dds_bench.py [--events 3000] [--rounds 5] [--pause-ms 2] [--pin]

A driver node (this process) publishes ``tile_observation`` and waits for
the answer: the estimator's corrected ``belief`` (N = 5, the book's world),
or the same String back from bench/relay_node.py on ``relay_out``. The
matrix filter's path is measured the same way (latency only): a 2-value
``kalman_measurement`` to the estimator in the tracking_2d scenario (4
states, 2 inputs, 2 outputs) answered on ``kalman_state``, against the relay's
``relay_vector_out``, back to back and again with a pause (``--pause-ms``)
before each measurement, so that it finds the node idle as a sensor's
readings do; back to back, a node's whole work per event (after its answer
too) delays the next answer. The
estimator and the relay run as separate processes, one at a time, in
alternating rounds, so both see the same machine. Latency: one message in
flight, publish to receipt, p50 and p99. Throughput: a window of 100 in
flight (inside the subscriptions' depth of 1000, so nothing may be lost),
events per second until every answer is back; a lost message fails the run.
The node's CPU time per event during the throughput run is printed too: on
a shared machine it moves less than the rate, and the rate a node sustains
is bounded by it.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(1, str(Path(__file__).resolve().parents[2]))  # the repository: bench
from bench.common import RELAY_NODE, REPO, confine_ros, table  # noqa: E402

from estimation_nodes.tools.demo.graph_runtime import stop_process  # noqa: E402

WINDOW = 100


TRACKING = REPO / "msgs_config" / "tracking_2d.yaml"


#: The CPUs of the node under test and of this driver, when the machine has two or more:
#: each process then keeps a core of its own, whichever node runs, instead of the
#: scheduler placing them together in some rounds and apart in others.
NODE_CPUS: set[int] | None = None


def pin_cores() -> str:
    """Keep this process on one CPU and leave the others to the node under test."""
    global NODE_CPUS
    cpus = sorted(os.sched_getaffinity(0))
    if len(cpus) < 2:
        return "not pinned (one CPU)"
    os.sched_setaffinity(0, {cpus[0]})
    NODE_CPUS = set(cpus[1:])
    return f"driver pinned to CPU {cpus[0]}, node to CPU {','.join(map(str, cpus[1:]))}"


def start(kind: str, env: dict, params: tuple[str, ...] = ()) -> subprocess.Popen:
    if kind == "estimator":
        command = [sys.executable, "-m", "estimation_nodes.nodes.estimator", "--ros-args",
                   *params, "-p", "history_depth:=1000", "--log-level", "warn"]
    else:
        command = [sys.executable, str(RELAY_NODE)]
    cpus = NODE_CPUS
    return subprocess.Popen(command, env=env, preexec_fn=(
        (lambda: os.sched_setaffinity(0, cpus)) if cpus else None))


class Driver:
    """Publishes observations and counts answers on one topic."""

    def __init__(self, answer_topic: str, answer_type, qos, vectors: bool = False) -> None:
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node
        from std_msgs.msg import Float64MultiArray, String

        from estimation_nodes.nodes import wire
        from estimation_nodes.nodes.qos import INPUT_QOS

        self.node = Node(f"bench_driver_{answer_topic}")
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self.received = 0
        self.arrivals: list[int] = []
        self.node.create_subscription(answer_type, answer_topic, self._on_answer, qos)
        if vectors:   # position measurements of the tracking scenario
            self.pub = self.node.create_publisher(
                Float64MultiArray, "kalman_measurement", INPUT_QOS)
            self.messages = [wire.vector(np.array(z), "z") for z in ([0.1, 0.2], [0.3, 0.1])]
        else:
            self.pub = self.node.create_publisher(String, "tile_observation", INPUT_QOS)
            self.messages = [String(data=name) for name in ("dark", "bright")]

    def _on_answer(self, _msg) -> None:
        self.arrivals.append(time.perf_counter_ns())
        self.received += 1

    def wait_until(self, predicate, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if predicate():
                return True
            self.executor.spin_once(timeout_sec=0.05)
        return predicate()

    def connect(self, timeout: float = 30.0) -> None:
        """Matched both ways, and one answer received (the whole path is up)."""
        if not self.wait_until(lambda: self.pub.get_subscription_count() >= 1, timeout):
            raise RuntimeError(f"no subscriber on {self.pub.topic_name}")
        self.pub.publish(self.messages[0])
        if not self.wait_until(lambda: self.received >= 1, timeout):
            raise RuntimeError("no answer")
        # The transient_local history of a late match can add one more: let it arrive.
        self.wait_until(lambda: False, 0.5)

    def latency(self, events: int, pause_s: float = 0.0) -> np.ndarray:
        """One message in flight: publish, wait for the answer, and send the next at once
        or, with ``pause_s``, that long after the answer (the node is idle when it comes,
        as between the readings of a sensor)."""
        samples = np.empty(events)
        for index in range(events):
            target = self.received + 1
            start = time.perf_counter_ns()
            self.pub.publish(self.messages[index % 2])
            while self.received < target:
                self.executor.spin_once(timeout_sec=1.0)
            samples[index] = (self.arrivals[-1] - start) / 1e3
            if pause_s:
                time.sleep(pause_s)
        return samples

    def throughput(self, events: int) -> float:
        base = self.received
        sent = 0
        start = time.perf_counter()
        while sent < events:
            if sent - (self.received - base) < WINDOW:
                self.pub.publish(self.messages[sent % 2])
                sent += 1
                self.executor.spin_once(timeout_sec=0.0)
            else:
                self.executor.spin_once(timeout_sec=0.01)
        if not self.wait_until(lambda: self.received - base >= events, 30.0):
            raise RuntimeError(f"lost: {events - (self.received - base)} of {events}")
        return events / (time.perf_counter() - start)

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()


def cpu_seconds(pid: int) -> float:
    """User + system CPU time a process has used so far (/proc/PID/stat)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def measure(kind: str, env: dict, events: int) -> tuple[np.ndarray, float, float]:
    from std_msgs.msg import Float64MultiArray, String

    from estimation_nodes.nodes.qos import latched_qos

    process = start(kind, env)
    if kind == "estimator":
        driver = Driver("belief", Float64MultiArray, latched_qos(1000))
    else:
        driver = Driver("relay_out", String, latched_qos(1000))
    try:
        driver.connect()
        driver.latency(200)   # warm-up
        latencies = driver.latency(events)
        cpu_before = cpu_seconds(process.pid)
        rate = driver.throughput(events)
        cpu_per_event = (cpu_seconds(process.pid) - cpu_before) / events
        return latencies, rate, cpu_per_event
    finally:
        driver.close()
        stop_process(process)


def measure_matrix_latency(kind: str, env: dict, events: int,
                           pause_s: float) -> tuple[np.ndarray, np.ndarray, float]:
    """kalman_measurement -> kalman_state of the tracking filter, or the relay's echo:
    back to back, and with ``pause_s`` between an answer and the next measurement; and
    the node's CPU time per measurement back to back (less noisy than the latency)."""
    from std_msgs.msg import Float64MultiArray

    from estimation_nodes.nodes.qos import latched_qos

    process = start(kind, env, ("--params-file", str(TRACKING)))
    answer = "kalman_state" if kind == "estimator" else "relay_vector_out"
    driver = Driver(answer, Float64MultiArray, latched_qos(1000), vectors=True)
    try:
        driver.connect()
        driver.latency(200)   # warm-up
        cpu_before = cpu_seconds(process.pid)
        back_to_back = driver.latency(events)
        cpu_per_event = (cpu_seconds(process.pid) - cpu_before) / events
        return back_to_back, driver.latency(events // 5, pause_s), cpu_per_event
    finally:
        driver.close()
        stop_process(process)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--events", type=int, default=3000)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--pause-ms", type=float, default=2.0,
                        help="pause between an answer and the next measurement, for the "
                             "matrix filter's latency with the node idle")
    parser.add_argument("--pin", action="store_true",
                        help="keep the driver on one CPU and the node on the others")
    args = parser.parse_args()
    placement = pin_cores() if args.pin else "not pinned"
    env = confine_ros(81)
    import rclpy

    rclpy.init()
    results: dict[str, dict[str, list]] = {k: {"lat": [], "rate": [], "cpu": []}
                                           for k in ("estimator", "relay")}
    matrix: dict[str, list] = {"estimator": [], "relay": []}
    paced: dict[str, list] = {"estimator": [], "relay": []}
    matrix_cpu: dict[str, list] = {"estimator": [], "relay": []}
    try:
        for _ in range(args.rounds):
            for kind in ("relay", "estimator"):
                latencies, rate, cpu = measure(kind, env, args.events)
                results[kind]["lat"].append(latencies)
                results[kind]["rate"].append(rate)
                results[kind]["cpu"].append(cpu)
                back_to_back, idle, cpu = measure_matrix_latency(
                    kind, env, args.events // 3, args.pause_ms / 1e3)
                matrix[kind].append(back_to_back)
                paced[kind].append(idle)
                matrix_cpu[kind].append(cpu)
    finally:
        rclpy.try_shutdown()
    rows = []
    for kind in ("estimator", "relay"):
        lat = np.concatenate(results[kind]["lat"])
        rates = results[kind]["rate"]
        rows.append([kind, f"{np.percentile(lat, 50):.0f}", f"{np.percentile(lat, 99):.0f}",
                     f"{np.median(rates):.0f}", f"{min(rates):.0f}..{max(rates):.0f}",
                     f"{np.median(results[kind]['cpu']) * 1e6:.0f}"])
    est = np.concatenate(results["estimator"]["lat"])
    rel = np.concatenate(results["relay"]["lat"])
    ratio_rate = np.median(results["estimator"]["rate"]) / np.median(results["relay"]["rate"])
    print(f"DDS: {args.rounds} rounds x {args.events} events each, N = 5, "
          f"ROS_DOMAIN_ID={env['ROS_DOMAIN_ID']}, {placement}")
    ratio_cpu = np.median(results["relay"]["cpu"]) / np.median(results["estimator"]["cpu"])
    print(table(["node", "latency p50 (us)", "latency p99 (us)", "throughput (events/s, median)",
                 "throughput range", "node CPU per event under load (us)"], rows))
    print(f"estimator / relay: p50 {np.percentile(est, 50) / np.percentile(rel, 50):.2f}, "
          f"p99 {np.percentile(est, 99) / np.percentile(rel, 99):.2f}, "
          f"throughput {ratio_rate:.2f} (by CPU per event: {ratio_cpu:.2f})")
    print("Matrix filter (tracking_2d: 4 states, 2 inputs, 2 outputs), latency "
          "kalman_measurement -> kalman_state against the relay's echo")
    for label, samples in (("back to back", matrix),
                           (f"{args.pause_ms:g} ms pause before each measurement", paced)):
        est, rel = np.concatenate(samples["estimator"]), np.concatenate(samples["relay"])
        print(f"{label}:")
        print(table(["node", "latency p50 (us)", "latency p99 (us)"],
                    [[kind, f"{np.percentile(lat, 50):.0f}", f"{np.percentile(lat, 99):.0f}"]
                     for kind, lat in (("estimator", est), ("relay", rel))]))
        print(f"estimator / relay: p50 {np.percentile(est, 50) / np.percentile(rel, 50):.2f}, "
              f"p99 {np.percentile(est, 99) / np.percentile(rel, 99):.2f}")
    cpu = {kind: np.median(matrix_cpu[kind]) * 1e6 for kind in matrix_cpu}
    print(f"node CPU per measurement back to back (median of rounds): estimator "
          f"{cpu['estimator']:.0f} us, relay {cpu['relay']:.0f} us")


if __name__ == "__main__":
    main()
