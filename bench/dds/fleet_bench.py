"""How many robots one machine carries: K namespaces, each its estimator, sensor and commander.

    python bench/dds/fleet_bench.py [--robots 1 2 4 8 16] [--late-ms 250]

Each robot runs the default scenario (localization: 40 steps at 4 Hz) in a
namespace of its own, all on this machine. An observer in this process
takes every robot's tile_observation and belief with their DDS source
timestamps. Per fleet size it prints: readings sent, readings whose belief
never came (lost), and the reading -> belief latency (the belief's publish
time minus the reading's: the estimator's reaction, one clock), p50, p99 and
max over all robots; a belief later than --late-ms (the scenario's period
by default: the next reading is due) counts as late. Also how many
commanders finished their 40 commands in time, the run's length from
spawning the fleet, how far apart the robots' first readings were (start-up
and discovery of the whole fleet), and the machine's load.
The reference is the same figure for one robot: the table's ratio column.
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
from bench.common import REPO, confine_ros, table  # noqa: E402

from estimation_nodes.tools.demo.graph_runtime import stop_process  # noqa: E402

SCENARIO = REPO / "msgs_config" / "localization.yaml"
STEPS = 40
NODES = ("estimator", "tile_sensor", "motion_commander")


def start_fleet(robots: int, env: dict) -> dict[str, list[subprocess.Popen]]:
    fleet: dict[str, list[subprocess.Popen]] = {name: [] for name in NODES}
    for index in range(robots):
        for name in NODES:
            extra = ["-p", "history_depth:=1000"] if name == "estimator" else []
            if name == "tile_sensor":
                # The observer must hear every reading too: the sensor holds them for it.
                extra = ["-p", "hold_for_nodes:=[estimator, /fleet_observer]"]
            if name == "motion_commander":
                extra = ["-p", "exit_when_done:=true", "-p", "start_delay:=2.0"]
            command = [sys.executable, "-m", f"estimation_nodes.nodes.{name}", "--ros-args",
                       "-r", f"__ns:=/robot{index}", "--params-file", str(SCENARIO), *extra,
                       "--log-level", "warn"]
            fleet[name].append(subprocess.Popen(command, env=env, stdout=subprocess.DEVNULL,
                                                stderr=subprocess.STDOUT,
                                                cwd=REPO))
    return fleet


class Observer:
    """Every robot's readings and beliefs with their source timestamps (ns)."""

    def __init__(self, robots: int) -> None:
        from rclpy.node import Node
        from std_msgs.msg import Float64MultiArray, String

        from estimation_nodes.nodes.qos import INPUT_QOS, latched_qos

        self.node = Node("fleet_observer")
        self.readings: dict[int, list[int]] = {i: [] for i in range(robots)}
        self.beliefs: dict[int, list[int]] = {i: [] for i in range(robots)}
        for index in range(robots):
            self.node.create_subscription(
                String, f"/robot{index}/tile_observation",
                lambda _m, info, i=index: self.readings[i].append(info["source_timestamp"]),
                INPUT_QOS)
            self.node.create_subscription(
                Float64MultiArray, f"/robot{index}/belief",
                lambda _m, info, i=index: self.beliefs[i].append(info["source_timestamp"]),
                latched_qos(1000))


def measure(robots: int, env: dict, late_ms: float) -> dict:
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    rclpy.init()
    executor = SingleThreadedExecutor()
    observer = Observer(robots)
    executor.add_node(observer.node)
    load_before = os.getloadavg()[0]
    spawned = time.monotonic()
    fleet = start_fleet(robots, env)
    try:
        deadline = spawned + 60.0 + STEPS / 4.0 + 5.0 * robots
        while time.monotonic() < deadline and any(
                p.poll() is None for p in fleet["motion_commander"]):
            executor.spin_once(timeout_sec=0.05)
        finished = time.monotonic()
        end = finished + 3.0
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
        # Before they are stopped: a commander ended by SIGINT also exits 0.
        done = [p.poll() == 0 for p in fleet["motion_commander"]]
    finally:
        for processes in fleet.values():
            for process in processes:
                stop_process(process, grace=10.0)
        observer.node.destroy_node()
        executor.shutdown()
        rclpy.try_shutdown()
    latencies, lost, sent = [], 0, 0
    for index in range(robots):
        beliefs = np.array(sorted(observer.beliefs[index]))
        for reading in observer.readings[index]:
            sent += 1
            after = beliefs[np.searchsorted(beliefs, reading):]
            if after.size == 0:
                lost += 1
            else:
                latencies.append((after[0] - reading) / 1e6)
    lat = np.array(latencies) if latencies else np.array([np.nan])
    firsts = [min(r) for r in observer.readings.values() if r]
    started_s = (max(firsts) - min(firsts)) / 1e9 if firsts else float("nan")
    return {"robots": robots, "sent": sent, "expected": robots * STEPS, "lost": lost,
            "late": int(np.sum(lat > late_ms)), "p50": float(np.median(lat)),
            "p99": float(np.percentile(lat, 99)), "max": float(np.max(lat)),
            "commanders_done": sum(done), "run_s": finished - spawned,
            "start_spread_s": started_s,
            "load": f"{load_before:.1f} -> {os.getloadavg()[0]:.1f}"}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--robots", type=int, nargs="+", default=[1, 2, 4, 8, 16])
    parser.add_argument("--late-ms", type=float, default=250.0)
    args = parser.parse_args()
    env = confine_ros(84)
    print(f"fleet: localization scenario ({STEPS} steps at 4 Hz) per robot, "
          f"ROS_DOMAIN_ID={env['ROS_DOMAIN_ID']}; late = belief more than {args.late_ms:g} ms "
          f"after its reading")
    rows, reference = [], None
    for robots in args.robots:
        result = measure(robots, env, args.late_ms)
        reference = reference or result["p50"]
        rows.append([result["robots"], f"{result['sent']} / {result['expected']}",
                     result["lost"], result["late"], f"{result['p50']:.2f}",
                     f"{result['p99']:.2f}", f"{result['max']:.1f}",
                     f"{result['p50'] / reference:.2f}",
                     f"{result['commanders_done']} / {robots}", f"{result['run_s']:.1f}",
                     f"{result['start_spread_s']:.1f}",
                     result["load"]])
        print(f"  {robots} robots: done", flush=True)
    print(table(["robots", "readings sent / expected", "lost", "late", "p50 (ms)", "p99 (ms)",
                 "max (ms)", "p50 / 1 robot", "commanders done", "run (s)",
                 "first readings spread (s)", "load 1 min"],
                [[str(cell) for cell in row] for row in rows]))


if __name__ == "__main__":
    main()
