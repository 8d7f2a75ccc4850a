"""Start-up and discovery of the estimator, with and without the shipped Fast DDS profile.

    python bench/startup/startup_bench.py [--runs 10]

For each run a fresh estimator process is started while this process is
already running a driver node. Measured from the moment the process is
spawned: when the driver's ``motion_cmd`` publisher sees the estimator's
subscription (discovery, driver side), when the driver's ``belief_predicted``
subscription sees the estimator's publisher (the "already running
subscriber discovers it"), and when the first output arrives (the driver
publishes a command every 10 ms until one is answered). Alternating runs use
the default Fast DDS settings and bench/startup/fastdds_discovery.xml (faster initial
announcements, set through FASTRTPS_DEFAULT_PROFILES_FILE for both sides),
so both see the same machine.
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
from bench.common import table  # noqa: E402

from estimation_nodes.tools.demo.graph_runtime import stop_process  # noqa: E402

PROFILE = Path(__file__).resolve().parent / "fastdds_discovery.xml"


def one_run() -> dict[str, float]:
    """Runs in a child process of its own, so each profile applies to both sides."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from std_msgs.msg import Float64MultiArray, Int32

    from estimation_nodes.nodes.qos import INPUT_QOS, latched_qos

    rclpy.init()
    node = Node("startup_driver")
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    outputs: list[float] = []
    pub = node.create_publisher(Int32, "motion_cmd", INPUT_QOS)
    sub = node.create_subscription(Float64MultiArray, "belief_predicted",
                                   lambda m: outputs.append(time.perf_counter()),
                                   latched_qos(10))
    executor.spin_once(timeout_sec=0.1)
    spawned = time.perf_counter()
    estimator = subprocess.Popen([sys.executable, "-m", "estimation_nodes.nodes.estimator",
                                  "--ros-args", "--log-level", "warn"], env=os.environ)
    marks: dict[str, float] = {}
    last_command = 0.0
    try:
        deadline = spawned + 30.0
        while not outputs and time.perf_counter() < deadline:
            now = time.perf_counter()
            if "subscription matched" not in marks and pub.get_subscription_count() >= 1:
                marks["subscription matched"] = now - spawned
            if "publisher discovered" not in marks and sub.get_publisher_count() >= 1:
                marks["publisher discovered"] = now - spawned
            if "subscription matched" in marks and now - last_command > 0.01:
                pub.publish(Int32(data=1))
                last_command = now
            executor.spin_once(timeout_sec=0.002)
        if not outputs:
            raise RuntimeError("no output within 30 s")
        marks["first output"] = outputs[0] - spawned
    finally:
        stop_process(estimator)
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return marks


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--child", choices=["default", "profile"], help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(repr(one_run()))
        return
    results: dict[str, list[dict[str, float]]] = {"default": [], "profile": []}
    for _ in range(args.runs):
        for setting in ("default", "profile"):
            env = dict(os.environ)
            env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
            env.setdefault("ROS_DOMAIN_ID", "85")   # outside the tests' 1..80 (bench/common.py)
            env.pop("FASTRTPS_DEFAULT_PROFILES_FILE", None)
            if setting == "profile":
                env["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(PROFILE)
            out = subprocess.run([sys.executable, __file__, "--child", setting], env=env,
                                 capture_output=True, text=True, timeout=120, check=True)
            results[setting].append(eval_marks(out.stdout))
    rows = []
    for mark in ("subscription matched", "publisher discovered", "first output"):
        cells = [mark]
        for setting in ("default", "profile"):
            values = np.array([r[mark] for r in results[setting]])
            cells.append(f"{np.median(values):.3f} s ({values.min():.3f}..{values.max():.3f})")
        rows.append(cells)
    print(f"Estimator start-up, seconds from spawn, median (min..max) of {args.runs} runs")
    print(table(["event", "default Fast DDS", "with fastdds_discovery.xml"], rows))


def eval_marks(text: str) -> dict[str, float]:
    """Parse the child's one-line dict of floats (no eval: split it by hand)."""
    line = text.strip().splitlines()[-1].strip("{}")
    marks = {}
    for item in line.split(", "):
        key, value = item.split(": ")
        marks[key.strip("'")] = float(value)
    return marks


if __name__ == "__main__":
    main()
