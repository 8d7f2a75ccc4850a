"""A reading publisher that loses nothing published before anyone listens."""

from __future__ import annotations

from collections import deque

from rclpy.event_handler import PublisherEventCallbacks
from rclpy.node import Node

from estimation_nodes.nodes.qos import INPUT_QOS

#: Readings kept per topic while nobody listens; the oldest go first beyond that.
HOLD_LIMIT = 1000


class HeldPublisher:
    """A publisher that keeps its messages while no subscription is matched.

    What it held goes out, in order, on DDS's matched event: nothing polls
    while the sensor is idle.
    """

    def __init__(self, node: Node, msg_type: type, topic: str, hold: bool) -> None:
        self._publisher = node.create_publisher(
            msg_type, topic, INPUT_QOS,
            event_callbacks=PublisherEventCallbacks(matched=lambda _info: self.flush()))
        self._hold = hold
        self._held: deque = deque(maxlen=HOLD_LIMIT)

    @property
    def held(self) -> int:
        return len(self._held)

    def publish(self, msg) -> None:
        if self._hold and (self._held or self._publisher.get_subscription_count() == 0):
            self._held.append(msg)
            return
        self._publisher.publish(msg)

    def flush(self) -> None:
        """Send what was held, in order, once a subscription is matched."""
        if self._held and self._publisher.get_subscription_count() > 0:
            while self._held:
                self._publisher.publish(self._held.popleft())
