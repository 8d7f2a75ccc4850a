"""tf for the nodes, the one home of ``/tf`` and ``/tf_static`` (tf2_ros is not on PyPI):
a listener that fills a ``core.transforms`` buffer, and the broadcasters.

QoS as tf2_ros: ``/tf`` reliable and volatile, ``/tf_static`` reliable and
transient_local (a late listener still gets every static transform). Whatever the buffer
refuses (a loop, a second parent, NaN, a changed static transform, a stamp too far ahead)
is dropped, counted by reason and said in a throttled warning; the node goes on.
A clock that jumps back (a bag played again with ``--loop``) clears the dynamic
transforms, as tf2_ros does, and tells the node.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterable

from geometry_msgs.msg import TransformStamped
from rclpy.clock import ClockChange, JumpThreshold
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from tf2_msgs.msg import TFMessage

from estimation_nodes.core.errors import InvalidInputError
from estimation_nodes.core.transforms.buffer import TransformBuffer, TransformRejected
from estimation_nodes.core.transforms.rigid import Transform
from estimation_nodes.nodes.stamps import set_stamp, stamp_ns
from estimation_nodes.nodes.throttled import ThrottledWarnings

TF_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                    reliability=ReliabilityPolicy.RELIABLE,
                    durability=DurabilityPolicy.VOLATILE)
TF_STATIC_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                           reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: tf2_ros's static broadcaster keeps one message (all of its transforms) for late joiners.
TF_STATIC_PUBLISHER_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                                     reliability=ReliabilityPolicy.RELIABLE,
                                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


def to_message(parent: str, child: str, stamp: int, transform: Transform) -> TransformStamped:
    msg = TransformStamped()
    set_stamp(msg.header, stamp, parent)
    msg.child_frame_id = child
    t, q = msg.transform.translation, msg.transform.rotation
    t.x, t.y, t.z = (float(v) for v in transform.translation)
    q.x, q.y, q.z, q.w = (float(v) for v in transform.rotation)
    return msg


def from_message(msg: TransformStamped) -> tuple[str, str, int, Transform]:
    """(parent, child, stamp ns, transform); ``InvalidInputError`` for a broken one."""
    t, q = msg.transform.translation, msg.transform.rotation
    transform = Transform.checked((t.x, t.y, t.z), (q.x, q.y, q.z, q.w))
    return msg.header.frame_id, msg.child_frame_id, stamp_ns(msg.header.stamp), transform


class TransformListener:
    """Subscribes ``/tf`` and ``/tf_static`` into ``buffer``.

    ``future_tolerance_ns``: a dynamic transform stamped further than this ahead of the
    node's clock is refused (None: no such check). ``on_jump_back`` is called after the
    buffer was cleared for a clock that went back; ``depth``: /tf messages queued while the
    node is busy (tf2_ros's 100; more for a node that must see every sample);
    ``on_transforms`` after each message,
    with the (parent, child, stamp, transform) of each transform the buffer took (a node
    waiting for a transform looks again; one that follows an edge sees each sample).
    """

    def __init__(self, node: Node, buffer: TransformBuffer,
                 future_tolerance_ns: int | None = None,
                 on_jump_back: Callable[[], None] | None = None,
                 on_transforms: Callable[[list[tuple[str, str, int, Transform]]], None]
                 | None = None,
                 tf_topic: str = "/tf", tf_static_topic: str = "/tf_static",
                 depth: int = TF_QOS.depth) -> None:
        self._node = node
        self.buffer = buffer
        self._future_ns = future_tolerance_ns
        self._on_jump_back = on_jump_back
        self._on_transforms = on_transforms
        self.dropped: Counter[str] = Counter()
        self._warnings = ThrottledWarnings(node.get_logger())
        self._subscriptions = [
            node.create_subscription(TFMessage, tf_topic, lambda msg: self._take(msg, False),
                                     QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                                                reliability=ReliabilityPolicy.RELIABLE,
                                                durability=DurabilityPolicy.VOLATILE)),
            node.create_subscription(TFMessage, tf_static_topic,
                                     lambda msg: self._take(msg, True), TF_STATIC_QOS),
        ]
        self._jump = node.get_clock().create_jump_callback(
            JumpThreshold(min_forward=None, min_backward=Duration(nanoseconds=-1),
                          on_clock_change=True),
            post_callback=self._on_jump)

    def _take(self, msg: TFMessage, static: bool) -> None:
        now = None if self._future_ns is None else self._node.get_clock().now().nanoseconds
        taken = [t for t in (self.add(transform, static, now) for transform in msg.transforms)
                 if t is not None]
        if self._on_transforms is not None:
            self._on_transforms(taken)

    def add(self, msg: TransformStamped, static: bool, now_ns: int | None = None
            ) -> tuple[str, str, int, Transform] | None:
        """One transform into the buffer: what it took, or None (counted, warned) when it
        was refused."""
        try:
            parent, child, stamp, transform = from_message(msg)
            self.buffer.set_transform(parent, child, stamp, transform, static, now_ns,
                                      self._future_ns or 0)
        except TransformRejected as refused:
            return self._refused(refused.reason, str(refused))
        except InvalidInputError as error:
            return self._refused(
                "invalid", f"{msg.header.frame_id} -> {msg.child_frame_id}: {error}; dropped")
        return parent.lstrip("/"), child.lstrip("/"), stamp, transform

    def _refused(self, reason: str, message: str) -> None:
        self.dropped[reason] += 1
        self._warnings.warn(f"tf {reason}", f"tf: {message}")

    def _on_jump(self, jump) -> None:
        if jump.clock_change not in (ClockChange.ROS_TIME_NO_CHANGE,
                                     ClockChange.ROS_TIME_ACTIVATED,
                                     ClockChange.SYSTEM_TIME_NO_CHANGE) \
                or jump.delta.nanoseconds >= 0:
            return
        self.buffer.clear()
        self._node.get_logger().warning(
            f"time jumped back by {-jump.delta.nanoseconds * 1e-9:.3f} s: tf buffer cleared")
        if self._on_jump_back is not None:
            self._on_jump_back()

    def destroy(self) -> None:
        for subscription in self._subscriptions:
            self._node.destroy_subscription(subscription)
        self._subscriptions = []
        self._jump.unregister()


class TransformBroadcaster:
    """Publishes transforms on ``/tf``."""

    def __init__(self, node: Node, topic: str = "/tf") -> None:
        self._publisher = node.create_publisher(TFMessage, topic, TF_QOS)

    def send(self, transforms: Iterable[TransformStamped]) -> None:
        self._publisher.publish(TFMessage(transforms=list(transforms)))


class StaticTransformBroadcaster:
    """Publishes transforms on ``/tf_static``, keeping every one sent so far (by child) in
    the one latched message, as tf2_ros's static broadcaster does."""

    def __init__(self, node: Node, topic: str = "/tf_static") -> None:
        self._publisher = node.create_publisher(TFMessage, topic, TF_STATIC_PUBLISHER_QOS)
        self._by_child: dict[str, TransformStamped] = {}

    def send(self, transforms: Iterable[TransformStamped]) -> None:
        for transform in transforms:
            self._by_child[transform.child_frame_id] = transform
        self._publisher.publish(TFMessage(transforms=list(self._by_child.values())))
