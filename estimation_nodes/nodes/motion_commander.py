"""Publishes a sequence of motion commands (or Kalman input vectors) at a fixed rate.

No command is lost at start-up: the first one goes out only once
``required_subscribers`` subscriptions are matched on ``motion_cmd``, the
``required_nodes`` (the estimator and the tile sensor by default) among them
(subscribers.py: a recorder beside the graph never stands in for one), and
``start_delay`` has passed after that, so the rest of the graph has time to
discover itself. Later, while they are not all matched (a node restarting),
the commander pauses and resumes ``start_delay`` after they are back. A node
that crashes is noticed only when DDS drops it (its lease, 20 s by default), so
commands sent before then are lost to it; one that stops cleanly is noticed
when its goodbye reaches the commander's graph, and a command sent in between
(one in three restarts under load, measured by tests/graph/test_faults.py) is
lost to it too.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray, Int32

from estimation_nodes.nodes import wire
from estimation_nodes.nodes.parameters import (
    declare_and_build,
)
from estimation_nodes.nodes.process import main_for
from estimation_nodes.nodes.qos import INPUT_QOS
from estimation_nodes.nodes.subscribers import missing_subscribers
from estimation_nodes.params import topics
from estimation_nodes.params.simulators import build_commander_settings
from estimation_nodes.params.specs import COMMANDER_SPECS
from estimation_nodes.params.wording import plural

#: How often the commander checks for subscribers while it waits.
POLL_PERIOD_S = 0.05


class MotionCommander(Node):
    """Drives the robot with a configured command sequence."""

    node_name = "motion_commander"

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(self.node_name, **kwargs)
        values, settings = declare_and_build(self, COMMANDER_SPECS, build_commander_settings)
        # Each command as the message it goes out as: Int32 on motion_cmd, or a vector
        # on kalman_input when input_vectors is set.
        if settings.vectors:
            self._messages: list[Any] = [wire.vector(np.array(v), "input")
                                         for v in settings.vectors]
            self._publisher = self.create_publisher(
                Float64MultiArray, topics.KALMAN_INPUT, INPUT_QOS)
        else:
            self._messages = [Int32(data=command) for command in settings.commands]
            self._publisher = self.create_publisher(Int32, topics.MOTION_CMD, INPUT_QOS)
        self._limit = settings.limit
        self._required_nodes = settings.required_nodes
        self._values = values
        self._sent = 0
        self._ready_since: float | None = None
        self._timer = self.create_timer(POLL_PERIOD_S, self._wait_for_graph)
        required = values["required_subscribers"]
        named = f" ({', '.join(self._required_nodes)} among them)" if self._required_nodes \
            else ""
        self.get_logger().info(
            f"waiting for {plural(required, 'subscriber')}{named} on "
            f"{self._publisher.topic_name}"
            if required else f"sending on {self._publisher.topic_name} without waiting for "
            f"subscribers")

    @property
    def command_limit(self) -> int | None:
        """How many commands this run sends in all; None when it repeats without end."""
        return self._limit

    @property
    def sent(self) -> int:
        """Commands published so far."""
        return self._sent

    def _subscribers_ready(self) -> bool:
        if self._publisher.get_subscription_count() < self._values["required_subscribers"]:
            return False
        return not self._required_nodes or not missing_subscribers(
            self, self._publisher, self._required_nodes)

    def _wait_for_graph(self) -> None:
        if not self._subscribers_ready():
            self._ready_since = None
            return
        now = time.monotonic()
        if self._ready_since is None:
            self._ready_since = now
        if now - self._ready_since < self._values["start_delay"]:
            return
        self._timer.cancel()
        self.destroy_timer(self._timer)
        self.get_logger().info(f"subscribers matched: sending at {self._values['rate_hz']} Hz")
        self._timer = self.create_timer(1.0 / self._values["rate_hz"], self._send_next)
        self._send_next()

    def _send_next(self) -> None:
        if self._limit is not None and self._sent >= self._limit:
            self._finish()
            return
        if not self._subscribers_ready():
            self.get_logger().warning(f"a subscriber left {self._publisher.topic_name}: paused "
                                      "until it is back")
            self._timer.cancel()
            self.destroy_timer(self._timer)
            self._ready_since = None
            self._timer = self.create_timer(POLL_PERIOD_S, self._wait_for_graph)
            return
        self._publisher.publish(self._messages[self._sent % len(self._messages)])
        self._sent += 1

    def _finish(self) -> None:
        self._timer.cancel()
        self.get_logger().info(f"done: {plural(self._sent, 'command')} sent")
        if self._values["exit_when_done"]:
            raise SystemExit(0)


main = main_for(MotionCommander)

if __name__ == "__main__":
    main()
