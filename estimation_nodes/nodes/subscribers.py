"""Whether the nodes that must hear a publisher are matched to it, by name.

A count of matched subscriptions is not enough: a recorder, a monitor or a
`ros2 topic echo` beside the graph counts as one, and readings sent while the
estimator itself has not matched yet are lost to it (on a volatile topic a
subscription gets only what is sent after it matched). So a publisher that
must not lose messages waits until each node it names has a subscription on
the topic in the ROS graph, and every compatible subscription the graph
shows is matched.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy


def fully_qualified(name: str, namespace: str) -> str:
    """A node name as ``/namespace/name``: absolute names as given, relative ones in
    ``namespace`` (the node's own, so one parameter file serves every robot)."""
    if name.startswith("/"):
        return name
    return f"{namespace.rstrip('/')}/{name}"


def missing_subscribers(node: Node, publisher, required: Iterable[str]) -> list[str]:
    """Which of the ``required`` nodes are not yet matched subscribers of ``publisher``.

    ``["(discovery)"]`` when every named node is in the graph but the publisher has not
    matched every compatible subscription yet (one of them may be a named node's).
    """
    wanted = [fully_qualified(name, node.get_namespace()) for name in required if name]
    topic = publisher.topic_name
    type_name = _type_name(publisher.msg_type)
    ours = publisher.qos_profile
    # Only those that can match: the same type, and QoS this publisher can serve.
    compatible = [info for info in node.get_subscriptions_info_by_topic(topic)
                  if info.topic_type == type_name and _compatible(ours, info.qos_profile)]
    present = {fully_qualified(info.node_name, info.node_namespace) for info in compatible}
    missing = [name for name in wanted if name not in present]
    if missing:
        return missing
    if publisher.get_subscription_count() < len(compatible):
        return ["(discovery)"]
    return []


def _type_name(msg_type: type) -> str:
    """'std_msgs/msg/String' for std_msgs.msg.String."""
    return f"{msg_type.__module__.split('.')[0]}/msg/{msg_type.__name__}"


def _compatible(publisher_qos, subscription_qos) -> bool:
    """Whether reliability and durability let the two match. rclpy's qos_check_compatible
    reads the graph's infinite deadline and lease as set and calls every pair an error."""
    if subscription_qos.reliability == ReliabilityPolicy.RELIABLE \
            and publisher_qos.reliability == ReliabilityPolicy.BEST_EFFORT:
        return False
    return not (subscription_qos.durability == DurabilityPolicy.TRANSIENT_LOCAL
                and publisher_qos.durability == DurabilityPolicy.VOLATILE)


def missing_on_every(node: Node, publishers: Sequence, required: Sequence[str]) -> list[str]:
    """Which of the ``required`` nodes do not hear every one of ``publishers`` yet (with none
    named: ``["(any subscriber)"]`` until each publisher has a subscriber)."""
    missing: list[str] = []
    for publisher in publishers:
        if publisher.get_subscription_count() == 0:
            return list(required) or ["(any subscriber)"]
        missing += [name for name in missing_subscribers(node, publisher, required)
                    if name not in missing]
    return missing


def start_once_heard(node: Node, publishers: Sequence, required: Sequence[str],
                     start: Callable[[], None], what: str, period_s: float) -> None:
    """Call ``start`` now if the ``required`` nodes hear every one of ``publishers``, else
    once they do (looked at every ``period_s``): a simulated robot that starts moving
    before its localizer has matched its topics sends its first messages to nobody."""
    if not missing_on_every(node, publishers, required):
        start()
        return
    node.get_logger().info(f"waiting for {', '.join(required) or 'a node'} to hear {what} "
                           f"before moving")

    def check() -> None:
        if missing_on_every(node, publishers, required):
            return
        node.destroy_timer(timer)
        node.get_logger().info(f"{what} are heard: moving")
        start()

    timer = node.create_timer(period_s, check)
