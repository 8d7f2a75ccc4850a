"""The demo's monitor keeps each message's source timestamp, so a republished belief
is taken for its own step and not for the next one."""

import numpy as np
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
