"""A large world end to end: full steps per second and the estimator's memory.

    python bench/dds/large_world_bench.py [--cells 1000000] [--steps 30]

The estimator runs as its own process on a world of N cells read from a
world_file (seeded random dark and bright). A driver here sends a
``motion_cmd`` and then a ``tile_observation`` and waits for the corrected
``belief`` (N doubles) to arrive: one full step, including both published
belief messages. The estimator's resident memory (VmRSS) is compared with
that of a bare rclpy node (bench/relay_node.py, idle) plus 3 x N x 8 bytes.
Both histogram code paths are measured: numpy's (the node's default) and
the compiled kernels (numba, compiled_kernels:=true).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(1, str(Path(__file__).resolve().parents[2]))  # the repository: bench, tests
from bench.common import confine_ros, table  # noqa: E402
from bench.dds.dds_bench import start  # noqa: E402

from estimation_nodes.tools.demo import graph_runtime  # noqa: E402
from estimation_nodes.tools.demo.graph_runtime import stop_process  # noqa: E402
from tests.support import resident_mib, write_world  # noqa: E402



def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cells", type=int, default=1_000_000)
    parser.add_argument("--steps", type=int, default=30)
    args = parser.parse_args()
    env = confine_ros(83)

    import rclpy

    rclpy.init()
    try:
        with tempfile.TemporaryDirectory() as tmp:
            world = write_world(args.cells, Path(tmp))
            runs = {compiled: measure(world, env, compiled, args)
                    for compiled in (False, True)}
    finally:
        rclpy.try_shutdown()
    arrays_mib = 3 * args.cells * 8 / 2**20
    print(f"Large world: N = {args.cells:,} cells, {args.steps} full steps "
          f"(predict + correct + both beliefs published and received), "
          f"with compiled_kernels true and false")

    def row(name, figure):
        return [name] + [figure(runs[compiled]) for compiled in (False, True)]

    print(table(
        ["figure", "numpy path (default)", "compiled_kernels:=true"],
        [row("up and answering after", lambda r: f"{r['ready']:.1f} s"),
         row("full step, median", lambda r: f"{np.median(r['durations']) * 1e3:.1f} ms "
             f"({1 / np.median(r['durations']):.1f} steps/s)"),
         row("full step, p10..p90", lambda r: f"{np.percentile(r['durations'], 10) * 1e3:.1f}.."
             f"{np.percentile(r['durations'], 90) * 1e3:.1f} ms"),
         row("estimator RSS", lambda r: f"{r['estimator_rss']:.0f} MiB"),
         row("bare rclpy node RSS + 3 x N x 8 B", lambda r: f"{r['bare_rss']:.0f} + "
             f"{arrays_mib:.0f} = {r['bare_rss'] + arrays_mib:.0f} MiB"),
         row("ratio", lambda r: f"{r['estimator_rss'] / (r['bare_rss'] + arrays_mib):.2f}")]))


def measure(world: Path, env: dict, compiled: bool, args: argparse.Namespace) -> dict:
    """One estimator process on the world: time to answer, full steps, memory."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from std_msgs.msg import Float64MultiArray, Int32, String

    from estimation_nodes.nodes.qos import INPUT_QOS, latched_qos

    bare = start("relay", env)
    started = time.perf_counter()
    estimator = subprocess_estimator(world, env, compiled)
    node = Node("large_world_driver")
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    beliefs: list[float] = []
    predicted: list[float] = []
    sizes: set[int] = set()

    def on_belief(msg) -> None:
        beliefs.append(time.perf_counter())
        sizes.add(len(msg.data))

    node.create_subscription(Float64MultiArray, "belief", on_belief, latched_qos(1))
    node.create_subscription(Float64MultiArray, "belief_predicted",
                             lambda m: predicted.append(time.perf_counter()), latched_qos(1))
    cmd = node.create_publisher(Int32, "motion_cmd", INPUT_QOS)
    tile = node.create_publisher(String, "tile_observation", INPUT_QOS)

    def spin_until(predicate, timeout=120.0):
        if not graph_runtime.spin_until(executor, predicate, timeout):
            raise RuntimeError("timed out")

    try:
        spin_until(lambda: cmd.get_subscription_count() >= 1
                   and tile.get_subscription_count() >= 1)
        cmd.publish(Int32(data=1))
        spin_until(lambda: len(predicted) >= 1)
        ready = time.perf_counter() - started
        durations = []
        rng = np.random.default_rng(1)
        for _ in range(args.steps + 3):
            target = len(beliefs) + 1
            begin = time.perf_counter()
            cmd.publish(Int32(data=int(rng.integers(-2, 3))))
            tile.publish(String(data=("dark", "bright")[int(rng.integers(0, 2))]))
            spin_until(lambda t=target: len(beliefs) >= t)
            durations.append(beliefs[-1] - begin)
        if sizes != {args.cells}:
            raise RuntimeError(f"beliefs of {sizes} values, expected {args.cells}")
        return dict(ready=ready, durations=np.array(durations[3:]),
                    estimator_rss=resident_mib(estimator.pid), bare_rss=resident_mib(bare.pid))
    finally:
        executor.shutdown()
        node.destroy_node()
        stop_process(estimator)
        stop_process(bare)


def subprocess_estimator(world: Path, env: dict, compiled: bool):
    import subprocess

    return subprocess.Popen(
        [sys.executable, "-m", "estimation_nodes.nodes.estimator", "--ros-args",
         "-p", f"world_file:={world}", "-p", "history_depth:=1",
         "-p", f"compiled_kernels:={str(compiled).lower()}", "--log-level", "warn"],
        env=env)


if __name__ == "__main__":
    main()
