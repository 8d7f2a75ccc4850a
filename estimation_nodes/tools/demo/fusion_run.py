"""The demo's fusion run: ``ekf_node`` on a robot's bag, as a user runs it next to a bag.

Started by estimation_demo for a scenario of kind ``fusion`` (msgs_config/fusion.yaml):
``ekf_node`` with the scenario's robot_localization parameters under ``use_sim_time``,
then ``estimation_play BAG --clock`` once the node listens; the node's
``odometry/filtered`` is printed as it comes (one line a second of the bag's time). At the
end the same bag goes through the same filter in-process (estimation_fuse's loop), and the
two final estimates are printed side by side: they differ only by when the periodic update
ran against the messages' arrival over DDS.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

import yaml

from estimation_nodes.params.installed import package_file
from estimation_nodes.params.param_files import node_parameters
from estimation_nodes.params.scenarios import DEMO
from estimation_nodes.tools.demo.graph_runtime import NodeStart, run_graph

#: ekf_node's name (robot_localization's launch files name it so), its scenario section's.
NODE = "ekf_filter_node"
#: Seconds of the bag's time between two printed estimates.
PRINT_EVERY_S = 1.0


def _monitor_class():
    from rclpy.node import Node

    class FusionMonitor(Node):
        """The demo's node: keeps every odometry/filtered, prints one a second of bag time."""

        def __init__(self, quiet: bool) -> None:
            from nav_msgs.msg import Odometry

            super().__init__("estimation_demo_fusion_monitor")
            self.outputs: list[Any] = []
            self._quiet = quiet
            self._printed_s = -math.inf
            self.create_subscription(Odometry, "odometry/filtered", self._on_output, 1000)

        def listening(self) -> bool:
            """Whether ekf_node is there (its output matched this monitor)."""
            return self.count_publishers("odometry/filtered") > 0

        def _on_output(self, msg) -> None:
            self.outputs.append(msg)
            t = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
            if self._quiet or t - self._printed_s < PRINT_EVERY_S:
                return
            self._printed_s = t
            p = msg.pose.pose.position
            print(f"t {t:9.3f} s  x {p.x:8.4f}  y {p.y:8.4f}  z {p.z:8.4f} m  "
                  f"vx {msg.twist.twist.linear.x:7.4f} m/s  "
                  f"std x {math.sqrt(max(msg.pose.covariance[0], 0.0)):.4f} m", flush=True)

    return FusionMonitor


def run(params: Path, args: argparse.Namespace) -> int:
    """The run; its exit code (2: the scenario's bag cannot be found)."""
    document = yaml.safe_load(params.read_text(encoding="utf-8")) or {}
    demo = node_parameters(document, f"/{DEMO}")
    bag = package_file(str(demo.get("bag", "")), "msgs_config/bags") \
        if demo.get("bag") else None
    if bag is None:
        print(f"estimation_demo: {params}: no bag {demo.get('bag')!r} (the {DEMO} section's "
              f"bag: a file in msgs_config/bags/ or a path)", file=sys.stderr)
        return 2
    rate = float(demo.get("rate", 1.0))
    # Through tools/start.py, as the console script: it takes the Ctrl-C that run_graph's
    # start leaves blocked until the program can end quietly on it.
    play = (sys.executable, "-c",
            "from estimation_nodes.tools.start import estimation_play; estimation_play()",
            str(bag), "--clock", "--rate", f"{rate:g}", "--wait-for-subscribers", "30",
            "--delay", "1")
    print(f"estimation_demo: ekf_node on {bag.name}, played with --clock at {rate:g}x")
    # rclpy is imported by run_graph under its Ctrl-C hold: the monitor's class with it.
    code, monitor = run_graph(params, lambda: _monitor_class()(args.quiet), [
        NodeStart("ekf_node"),
        NodeStart("estimation_play", ready=lambda m: m.listening(), command=play),
    ], "estimation_play", args.timeout, args.linger)
    if monitor is not None and code == 0:
        print(summary(monitor.outputs, params, bag))
    return code


def summary(outputs: list, params: Path, bag: Path) -> str:
    """The node's last estimate beside the in-process filter's over the same bag."""
    if not outputs:
        return "summary: no odometry/filtered heard"
    from estimation_nodes.params.fusion import fusion_config
    from estimation_nodes.tools.fusion.offline import run as run_in_process
    from estimation_nodes.tools.recording.play import read_raw

    document = yaml.safe_load(params.read_text(encoding="utf-8")) or {}
    config = fusion_config(node_parameters(document, f"/{NODE}"))
    result = run_in_process(config, _decoded(read_raw(bag)))
    last = outputs[-1].pose.pose.position
    x = result.fusion.x
    gap = math.dist((last.x, last.y, last.z), tuple(float(v) for v in x[:3]))
    return "\n".join([
        "summary:",
        f"  odometry/filtered messages: {len(outputs)}",
        f"  final estimate through DDS: x {last.x:.4f} y {last.y:.4f} z {last.z:.4f} m",
        f"  the same bag in-process:    x {x[0]:.4f} y {x[1]:.4f} z {x[2]:.4f} m "
        f"({gap:.4f} m apart: when the periodic updates ran against the messages' arrival)",
        "  the whole bag and the peer's own tests: docs/nodes/ekf_node.md"])


def _decoded(recorded):
    from rclpy.serialization import deserialize_message

    from estimation_nodes.tools.demo.monitor import message_class

    for message in recorded:
        yield message.log_time_ns, message.topic, deserialize_message(
            message.data, message_class(message.type_name))
