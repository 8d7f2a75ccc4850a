"""A reading publisher that loses nothing published before the nodes that need it listen."""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

from rclpy.event_handler import PublisherEventCallbacks
from rclpy.node import Node

from estimation_nodes.nodes.qos import INPUT_QOS
from estimation_nodes.nodes.subscribers import missing_subscribers

#: Readings kept per topic while the required subscribers are not there; the oldest go
#: first beyond that.
HOLD_LIMIT = 1000
#: Seconds between checks of the graph while something is held (never while idle).
HOLD_CHECK_PERIOD_S = 0.02


class HeldPublisher:
    """A publisher that keeps its messages until the nodes in ``hold_for`` are matched.

    With ``hold_for`` empty, any matched subscription will do. What it held goes
    out, in order, on DDS's matched event or at the next check of the graph
    (every HOLD_CHECK_PERIOD_S while something is held; nothing polls while
    the sensor is idle).
    """

    def __init__(self, node: Node, msg_type: type, topic: str, hold: bool,
                 hold_for: Sequence[str] = ()) -> None:
        self._node = node
        self._publisher = node.create_publisher(
            msg_type, topic, INPUT_QOS,
            event_callbacks=PublisherEventCallbacks(matched=lambda _info: self.flush()))
        self._hold = hold
        self._hold_for = tuple(name for name in hold_for if name)
        self._held: deque = deque(maxlen=HOLD_LIMIT)
        self._timer = None
        #: Matched subscriptions when the required nodes were last seen matched.
        self._ready_at: int | None = None

    @property
    def held(self) -> int:
        return len(self._held)

    @property
    def hold_for(self) -> tuple[str, ...]:
        """The nodes this publisher waits for (empty: any subscriber)."""
        return self._hold_for

    def ready(self) -> bool:
        """Whether a message published now reaches every node it must.

        The graph is asked again only when fewer subscriptions are matched than when it
        last said yes: a query costs more than a publish.
        """
        count = self._publisher.get_subscription_count()
        if count == 0:
            return False
        if self._ready_at is not None and count >= self._ready_at:
            return True
        self._ready_at = None
        if self._hold_for and missing_subscribers(self._node, self._publisher, self._hold_for):
            return False
        self._ready_at = count
        return True

    def publish(self, msg) -> None:
        if self._hold and (self._held or not self.ready()):
            self._held.append(msg)
            self._check_until_flushed()
            return
        self._publisher.publish(msg)

    def _check_until_flushed(self) -> None:
        if self._timer is None:
            self._timer = self._node.create_timer(HOLD_CHECK_PERIOD_S, self.flush)

    def flush(self) -> None:
        """Send what was held, in order, once the required subscribers are matched."""
        if self._held and self.ready():
            while self._held:
                self._publisher.publish(self._held.popleft())
        if not self._held and self._timer is not None:
            self._node.destroy_timer(self._timer)
            self._timer = None


def subscribe_when_ready(node: Node, publishers: list[HeldPublisher], hold: bool,
                         subscribe) -> None:
    """Call ``subscribe`` (which takes the simulator's commands) once every one of
    ``publishers`` reaches the nodes it must, or at once without ``hold``.

    A reading held and sent later carries the later time: ordered by source
    timestamps (core/causal_order.py) it would land after moves that came after it.
    So a simulator takes no command before its readings can go out at once; the
    commander, which waits for it as a subscriber, starts only then. Holding remains
    for an estimator that leaves mid-run.
    """
    if not hold or all(publisher.ready() for publisher in publishers):
        subscribe()
        return
    names = ", ".join(dict.fromkeys(name for p in publishers for name in p.hold_for)) \
        or "a subscriber"
    node.get_logger().info(f"waiting for {names} to hear the readings before taking "
                           f"commands")

    def check() -> None:
        if all(publisher.ready() for publisher in publishers):
            node.destroy_timer(timer)
            node.get_logger().info(f"the readings reach {names}: taking commands")
            subscribe()

    timer = node.create_timer(HOLD_CHECK_PERIOD_S, check)
