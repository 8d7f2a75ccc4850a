"""The demo's monitor keeps each message's source timestamp, so a republished belief
is taken for its own step and not for the next one."""

import numpy as np
import pytest
from geometry_msgs.msg import PoseWithCovarianceStamped
from std_msgs.msg import Float64MultiArray, Int64

from estimation_nodes.nodes.qos import latched_qos
from estimation_nodes.params import topics
from estimation_nodes.tools.demo.monitor import RunMonitor
from estimation_nodes.tools.recording.run_record import summarize
from tests.conftest import spin_until


def belief_at(cell: int, size: int = 5) -> Float64MultiArray:
    values = np.full(size, 0.02)
    values[cell] = 0.92
    return Float64MultiArray(data=values.tolist())


def test_a_republished_belief_is_counted_for_its_own_step(context, executor):
    from rclpy.node import Node

    monitor = RunMonitor(quiet=True, context=context)
    source = Node("simulated_graph", context=context)
    executor.add_node(monitor)
    executor.add_node(source)
    try:
        truth = source.create_publisher(Int64, topics.TRUE_POSITION, latched_qos(100))
        belief = source.create_publisher(Float64MultiArray, topics.BELIEF, latched_qos(100))
        assert spin_until(executor, lambda: monitor.publishers_matched(
            (topics.TRUE_POSITION, topics.BELIEF)), 10.0)
        truth.publish(Int64(data=1))
        belief.publish(belief_at(3))   # provisional: its command had not arrived yet
        belief.publish(belief_at(1))   # republished once it did
        truth.publish(Int64(data=2))
        belief.publish(belief_at(2))
        record = monitor.record
        assert spin_until(executor, lambda: len(record.corrected) == 3
                          and len(record.truth) == 2, 10.0)
        assert record.per_step(topics.BELIEF) == {0: 1, 1: 2}
        assert "most likely cell == true cell in 2 of 2 steps" in summarize(record)
    finally:
        source.destroy_node()
        monitor.destroy_node()


def test_the_grid_monitor_pairs_each_pose_with_its_own_quality(context, executor):
    # grid_localizer publishes an update's quality, then its pose. Three updates are
    # waiting when the monitor spins: an executor that takes a ready pose before the
    # ready quality would pair it with the previous update's quality.
    from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
    from rclpy.node import Node
    from std_msgs.msg import Float64

    from estimation_nodes.tools.demo.grid_run import GridMonitor

    monitor = GridMonitor(quiet=True, sinks=[], context=context)
    source = Node("simulated_localizer", context=context)
    executor.add_node(monitor)
    executor.add_node(source)
    try:
        truth = source.create_publisher(PoseStamped, topics.TRUE_POSE, latched_qos(100))
        quality = source.create_publisher(Float64, topics.LOCALIZATION_QUALITY,
                                          latched_qos(100))
        pose = source.create_publisher(PoseWithCovarianceStamped, topics.POSE,
                                       latched_qos(100))
        assert spin_until(executor, lambda: all(monitor.count_publishers(topic) for topic in (
            topics.TRUE_POSE, topics.POSE, topics.LOCALIZATION_QUALITY)), 10.0)
        published = []
        for step in range(3):
            at = PoseStamped()
            at.header.stamp.sec = step + 1
            at.pose.orientation.w = 1.0
            truth.publish(at)
        for step, value in enumerate((0.1, 0.95, 0.3)):
            update = PoseWithCovarianceStamped()
            update.header.stamp.sec = step + 1
            update.pose.pose.position.x = float(step)
            update.pose.pose.orientation.w = 1.0
            quality.publish(Float64(data=value))
            pose.publish(update)
            published.append(value)
        record = monitor.record
        assert spin_until(executor, lambda: len(record.updates) == 3, 10.0)
        assert [u[3] for u in record.updates] == published
        assert [u[1] for u in record.updates] == [0.0, 1.0, 2.0]
    finally:
        executor.remove_node(source)
        executor.remove_node(monitor)
        source.destroy_node()
        monitor.destroy_node()


class Numbered:
    """A sink that keeps what completeness.py makes of each message's sequence number."""

    def __init__(self) -> None:
        from estimation_nodes.tools.recording.completeness import SequenceGaps

        self.gaps = SequenceGaps()
        self.count = 0

    def write(self, topic, data, log_time_ns, publish_time_ns, sequence=None) -> None:
        self.gaps.note(topic, sequence)
        self.count += 1


@pytest.mark.parametrize("monitor_kind", ["tiles", "grid"])
def test_a_monitor_that_matched_late_records_what_it_missed(context, executor, monitor_kind):
    # A latched publisher keeping 3 of the 5 beliefs it published before the monitor
    # matched: the monitor gets 3, 4 and 5, and its recording says 1 and 2 are missing.
    from rclpy.node import Node

    from estimation_nodes.tools.demo.grid_run import GridMonitor

    source = Node("simulated_graph", context=context)
    executor.add_node(source)
    topic = topics.BELIEF if monitor_kind == "tiles" else topics.POSE
    msg_type = Float64MultiArray if monitor_kind == "tiles" else PoseWithCovarianceStamped

    def message():
        return belief_at(1) if monitor_kind == "tiles" else PoseWithCovarianceStamped()

    publisher = source.create_publisher(msg_type, topic, latched_qos(3))
    for _ in range(5):
        publisher.publish(message())
    sink = Numbered()
    monitor = RunMonitor(quiet=True, sinks=[sink], context=context) \
        if monitor_kind == "tiles" else GridMonitor(quiet=True, sinks=[sink], context=context)
    executor.add_node(monitor)
    try:
        assert spin_until(executor, lambda: sink.count == 3, 10.0)
        assert sink.gaps.describe() == [f"/{topic}: 2 messages of 5 missing (sequence numbers "
                                        f"1-2)"]
        publisher.publish(message())
        assert spin_until(executor, lambda: sink.count == 4, 10.0)
        assert sink.gaps.missing() == {f"/{topic}": [(1, 2)]}
    finally:
        executor.remove_node(source)
        executor.remove_node(monitor)
        source.destroy_node()
        monitor.destroy_node()


def test_the_demos_monitor_leaves_out_a_sample_published_before_its_run_began(context,
                                                                              executor):
    """A graph still running in the domain keeps its latest belief for late subscribers:
    the demo's monitor, made before any node of its run, takes none of it for the run's."""
    import time

    from rclpy.node import Node

    stale = Node("graph_of_another_run", context=context)
    old = stale.create_publisher(Float64MultiArray, topics.BELIEF, latched_qos(1))
    old.publish(belief_at(1, size=5))
    monitor = RunMonitor(quiet=True, context=context, run_started_ns=time.time_ns())
    source = Node("simulated_graph", context=context)
    for node in (stale, monitor, source):
        executor.add_node(node)
    try:
        assert spin_until(executor, lambda: monitor.foreign["/" + topics.BELIEF] == 1, 10.0)
        belief = source.create_publisher(Float64MultiArray, topics.BELIEF, latched_qos(1))
        assert spin_until(executor, lambda: belief.get_subscription_count() > 0, 10.0)
        belief.publish(belief_at(2, size=20))
        assert spin_until(executor, lambda: len(monitor.record.corrected) == 1, 10.0)
        assert monitor.record.corrected[0].size == 20
    finally:
        for node in (stale, source, monitor):
            executor.remove_node(node)
            node.destroy_node()
