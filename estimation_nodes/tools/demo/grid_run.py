"""The demo's localization runs on a map or among landmarks: a localizer and a simulated
robot (grid_localizer and planar_robot, or ekf_localizer and landmark_robot), watched and
summarized.

Started by estimation_demo for a scenario of kind ``grid`` or ``landmarks``
(msgs_config/grid_localization.yaml, landmarks.yaml). The localizer starts first; the
simulated robot, once the localizer has published its first estimate (its map
and kernels are loaded: several seconds on a first run), and it ends itself
after its ``duration``; a monitor here
prints each update (the estimate's error to the truth at the scan's time,
the localization quality, the belief's entropy from /diagnostics) and a
summary, and records every topic with ``--record``.
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
from rclpy.node import Node
from std_msgs.msg import Float64

from estimation_nodes.nodes.grid_messages import planar_pose
from estimation_nodes.nodes.qos import INPUT_QOS, latched_qos
from estimation_nodes.nodes.stamps import published_ns
from estimation_nodes.params import topics
from estimation_nodes.tools.demo.graph_runtime import NodeStart, run_graph
from estimation_nodes.tools.demo.overrides import GRID_MONITOR, node_overrides

#: Within this of the truth an update counts as localized (the issue's 0.3 m and 10 deg).
NEAR_M, NEAR_DEG = 0.3, 10.0


@dataclass
class GridRecord:
    """Each update: (seconds since start, error m, error deg, quality, entropy bits)."""

    updates: list[tuple[float, float, float, float, float]] = field(default_factory=list)

    def summary(self) -> str:
        lines = ["", "summary:", f"  localizer updates {len(self.updates)}"]
        if not self.updates:
            return "\n".join(lines)
        near = [e <= NEAR_M and a <= NEAR_DEG for _, e, a, _, _ in self.updates]
        first = next((t for (t, *_), ok in zip(self.updates, near) if ok), None)
        _, error, angle, quality, _ = self.updates[-1]
        lines.append(f"  within {NEAR_M} m and {NEAR_DEG:g} deg of the truth in {sum(near)} "
                     f"of {len(near)} updates" + (f", first at {first:.1f} s" if first else ""))
        if not math.isnan(quality):     # a landmark localizer publishes no quality
            lines.append(f"  quality at the first update {self.updates[0][3]:.3f}, at the "
                         f"last {quality:.3f}")
        lines.append(f"  final error {error:.3f} m, {angle:.1f} deg")
        return "\n".join(lines)


class QualityOfPose:
    """Each pose with the localization_quality published for it, by the publisher's source
    timestamps: grid_localizer publishes an update's quality just before its pose, while a
    subscriber's callbacks for two topics run in no set order (an executor that finds both
    ready may take the pose first, and the latest quality it holds is then the previous
    update's). A pose's quality is the latest published after the pose before it and not
    after it; a pose waits until that quality has come, or is shown without one (NaN)
    once a later quality says its own is lost."""

    def __init__(self) -> None:
        self._qualities: deque[tuple[int, float]] = deque(maxlen=1000)
        #: (published ns, the pose before's published ns or None, what to pair).
        self._waiting: deque[tuple[int, int | None, Any]] = deque()
        self._previous: int | None = None

    def quality(self, published_ns: int, value: float) -> list[tuple[Any, float]]:
        self._qualities.append((published_ns, value))
        return self._paired()

    def pose(self, published_ns: int, item: Any) -> list[tuple[Any, float]]:
        """``item`` (what to keep of the pose) and each pose now paired, in order."""
        self._waiting.append((published_ns, self._previous, item))
        self._previous = published_ns
        return self._paired()

    def rest(self) -> list[tuple[Any, float]]:
        """The poses still waiting, without a quality."""
        rest = [(item, math.nan) for _, _, item in self._waiting]
        self._waiting.clear()
        return rest

    def _paired(self) -> list[tuple[Any, float]]:
        paired = []
        while self._waiting:
            published, before, item = self._waiting[0]
            own = [value for at, value in self._qualities
                   if at <= published and (before is None or at > before)]
            if own:
                paired.append((item, own[-1]))
            elif any(at > published for at, _ in self._qualities):
                paired.append((item, math.nan))
            else:
                break
            self._waiting.popleft()
        return paired


def topic_types(kind: str) -> dict[str, str]:
    """The run's topics as the nodes resolve them in the root namespace."""
    types = topics.GRID_TOPIC_TYPES if kind == "grid" else topics.LANDMARK_TOPIC_TYPES
    return {f"/{t}" if not t.startswith("/") else t: n for t, n in types.items()}


class GridMonitor(Node):
    """Subscribes to the run's grid topics; prints and keeps each update; feeds raw sinks."""

    def __init__(self, quiet: bool, sinks: list, kind: str = "grid", **kwargs: Any) -> None:
        super().__init__(GRID_MONITOR, **kwargs)
        self.record = GridRecord()
        #: Whether the localizer has published an estimate: it is ready for the robot.
        self.localizer_ready = False
        self._quiet, self._sinks, self._kind = quiet, sinks, kind
        self._truth: dict[tuple[int, int], tuple[float, float, float]] = {}
        self._qualities = QualityOfPose()
        self._entropy = float("nan")
        self._started = time.monotonic()
        self.create_subscription(PoseStamped, topics.TRUE_POSE, self._on_truth,
                                 latched_qos(1000))
        self.create_subscription(PoseWithCovarianceStamped, topics.POSE, self._on_pose,
                                 latched_qos(1000))
        self.create_subscription(Float64, topics.LOCALIZATION_QUALITY, self._on_quality,
                                 latched_qos(1000))
        self.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, self._on_diagnostics, 10)
        if sinks:
            self._raw_subscriptions()

    def _raw_subscriptions(self) -> None:
        from estimation_nodes.tools.demo.monitor import message_class, observer_qos

        inputs = ("/scan", "/odom", "/landmark_observations")
        # The robot's inputs last: it starts once it has matched this node on them
        # (overrides.py), and DDS announces a node's subscriptions in the order they
        # were made, so by then it has matched the truth's too.
        ordered = sorted(topic_types(self._kind).items(), key=lambda item: item[0] in inputs)
        for topic, type_name in ordered:
            # The inputs 1000 deep, not 10: a monitor kept from its queue for a second
            # (a busy machine) lost the oldest, and a recording without a scan the
            # localizer took does not replay. observer_qos says why for the others.
            qos = INPUT_QOS if topic in inputs else observer_qos(topic)
            self.create_subscription(message_class(type_name), topic, self._forward(topic),
                                     qos, raw=True)

    def _forward(self, topic: str):
        def on_raw(data: bytes, info: dict) -> None:
            received = time.time_ns()
            for sink in self._sinks:
                sink.write(topic, data, received, info.get("source_timestamp") or received,
                           info.get("publication_sequence_number"))
        return on_raw

    def _on_truth(self, msg) -> None:
        self._truth[(msg.header.stamp.sec, msg.header.stamp.nanosec)] = planar_pose(msg.pose)

    def _on_diagnostics(self, msg) -> None:
        for status in msg.status:
            for pair in status.values:
                if pair.key == "belief_entropy_bits":
                    self._entropy = float(pair.value)

    def _on_quality(self, msg: Float64, info: dict) -> None:
        self._show(self._qualities.quality(published_ns(info), msg.data))

    def _on_pose(self, msg, info: dict) -> None:
        self.localizer_ready = True
        truth = self._truth.get((msg.header.stamp.sec, msg.header.stamp.nanosec))
        if truth is None:
            # Before the robot moved: no truth for that time. Its quality is still its own.
            self._show(self._qualities.pose(published_ns(info), None))
            return
        x, y, yaw = planar_pose(msg.pose.pose)
        error = math.hypot(x - truth[0], y - truth[1])
        angle = abs(math.degrees(math.remainder(yaw - truth[2], 2 * math.pi)))
        update = (time.monotonic() - self._started, (x, y, yaw), error, angle, self._entropy)
        if self._kind == "grid":
            self._show(self._qualities.pose(published_ns(info), update))
        else:                           # a landmark localizer publishes no quality
            self._show([(update, math.nan)])

    def finish(self) -> None:
        """Keep the poses whose quality never came, without one."""
        self._show(self._qualities.rest())

    def _show(self, paired: list) -> None:
        for update, quality in paired:
            if update is None:
                continue
            elapsed, (x, y, yaw), error, angle, entropy = update
            self.record.updates.append((elapsed, error, angle, quality, entropy))
            if not self._quiet:
                # A landmark localizer has neither quality nor a belief's entropy: no "nan".
                grid_figures = (f"  quality {quality:.3f}  entropy {entropy:.1f} bits"
                                if self._kind == "grid" else "")
                print(f"t {elapsed:5.1f} s  update {len(self.record.updates):3d}  pose "
                      f"({x:6.2f}, {y:6.2f}, {math.degrees(yaw):6.1f} deg)  error "
                      f"{error:5.2f} m {angle:5.1f} deg{grid_figures}", flush=True)


#: Each kind's localizer and simulated robot.
NODES = {"grid": ("grid_localizer", "planar_robot"),
         "landmarks": ("ekf_localizer", "landmark_robot")}


def run(params: Path, args, sinks: list, kind: str = "grid") -> tuple[int, GridRecord]:
    """Start the localizer, then the robot once the localizer is ready (a grid localizer
    has published its first estimate; a landmark localizer listens to odometry); watch
    until the robot's duration is over."""
    localizer, robot = NODES[kind]
    # The monitor hears the robot's odometry and readings only to record or serve them.
    overrides = node_overrides(params.read_text(encoding="utf-8"), kind,
                               monitor_hears_inputs=bool(sinks))

    def ready(monitor: GridMonitor) -> bool:
        return monitor.localizer_ready if kind == "grid" \
            else monitor.count_publishers(topics.POSE) > 0
    code, monitor = run_graph(params, lambda: GridMonitor(args.quiet, sinks, kind), [
        NodeStart(localizer, overrides.get(localizer, ())),
        NodeStart(robot, ("-p", "exit_when_done:=true", *overrides.get(robot, ())),
                  ready=ready),
    ], robot, args.timeout, args.linger)
    if monitor is None:
        return code, GridRecord()
    monitor.finish()
    return code, monitor.record
