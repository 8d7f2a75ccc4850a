"""nodes/tf.py over DDS in one process: tf2_msgs (built from its IDL by the install) carries
/tf and /tf_static between a broadcaster and a listener; a late listener still gets the
static transforms; broken transforms are dropped and counted, the tree untouched; a clock
that jumps back clears the dynamic transforms."""

from __future__ import annotations

import math

import pytest
from rclpy.serialization import deserialize_message, serialize_message
from rosgraph_msgs.msg import Clock
from tf2_msgs.msg import TFMessage

from estimation_nodes.core.transforms.buffer import TransformBuffer
from estimation_nodes.core.transforms.rigid import Transform
from estimation_nodes.nodes.tf import (StaticTransformBroadcaster, TransformBroadcaster,
                                       TransformListener, to_message)
from tests.conftest import spin_until

S = 1_000_000_000


def test_a_tf_message_round_trips_through_cdr():
    msg = TFMessage(transforms=[to_message("odom", "base_link", 3 * S + 5,
                                           Transform.planar(1.0, 2.0, 0.5))])
    back = deserialize_message(serialize_message(msg), TFMessage)
    assert back.transforms[0].child_frame_id == "base_link"
    assert back.transforms[0].header.stamp.nanosec == 5
    assert back.transforms[0].transform.translation.y == 2.0


def test_transforms_sent_are_looked_up_and_a_late_listener_gets_the_static_ones(
        make_node, executor):
    sender = make_node("sender")
    static = StaticTransformBroadcaster(sender)
    dynamic = TransformBroadcaster(sender)
    static.send([to_message("base_link", "laser", 0, Transform((0.25, 0.0, 0.1)))])
    static.send([to_message("base_link", "imu_link", 0, Transform((0.0, -0.3, 0.5)))])
    buffer = TransformBuffer()
    listener = TransformListener(make_node("listener"), buffer)
    assert spin_until(executor, lambda: buffer.can_transform("base_link", "imu_link"), 10.0)
    assert buffer.can_transform("base_link", "laser")   # both kept in the latched message

    def sent_and_held() -> bool:
        dynamic.send([to_message("odom", "base_link", 1 * S, Transform.planar(0, 0, 0)),
                      to_message("odom", "base_link", 2 * S,
                                 Transform.planar(2.0, 0.0, math.pi / 2))])
        return buffer.can_transform("odom", "laser", 2 * S)

    assert spin_until(executor, sent_and_held, 10.0)
    x, y, yaw = buffer.lookup("odom", "laser", int(1.5 * S)).as_planar()
    assert (x, y, yaw) == pytest.approx((1.0 + 0.25 * math.cos(math.pi / 4),
                                         0.25 * math.sin(math.pi / 4), math.pi / 4))
    assert not listener.dropped


def test_broken_transforms_are_dropped_and_counted(make_node, executor):
    sender = make_node("sender")
    dynamic = TransformBroadcaster(sender)
    buffer = TransformBuffer()
    listener = TransformListener(make_node("listener"), buffer)
    assert spin_until(executor, lambda: dynamic._publisher.get_subscription_count() > 0, 10.0)
    good = to_message("odom", "base_link", 1 * S, Transform.planar(1.0, 0.0, 0.0))
    nan = to_message("odom", "base_link", 2 * S, Transform.planar(1.0, 0.0, 0.0))
    nan.transform.translation.x = math.nan
    loop = to_message("base_link", "odom", 2 * S, Transform())
    second_parent = to_message("map", "base_link", 2 * S, Transform())
    dynamic.send([good, nan, loop, second_parent])
    assert spin_until(executor, lambda: sum(listener.dropped.values()) == 3, 10.0), \
        listener.dropped
    assert listener.dropped == {"invalid": 1, "loop": 1, "second_parent": 1}
    assert buffer.parent_of("base_link") == "odom"
    assert buffer.lookup("odom", "base_link").translation == (1.0, 0.0, 0.0)


def test_a_clock_that_jumps_back_clears_the_dynamic_transforms(make_node, executor):
    clock_source = make_node("clock_source")
    clock = clock_source.create_publisher(Clock, "/clock", 10)
    node = make_node("listener", use_sim_time=True)
    buffer = TransformBuffer()
    jumps = []
    TransformListener(node, buffer, on_jump_back=lambda: jumps.append(True))
    buffer.set_transform("odom", "base_link", 50 * S, Transform())
    buffer.set_transform("base_link", "laser", 0, Transform(), static=True)

    def tick(seconds: int) -> None:
        msg = Clock()
        msg.clock.sec = seconds
        clock.publish(msg)

    assert spin_until(executor, lambda: (tick(100), node.get_clock().now().nanoseconds
                                         == 100 * S)[1], 10.0)
    assert spin_until(executor, lambda: (tick(10), bool(jumps))[1], 10.0)
    assert not buffer.can_transform("odom", "base_link")
    assert buffer.can_transform("base_link", "laser")


def test_a_transform_from_the_future_and_a_changed_static_one_are_dropped_and_counted(
        make_node, executor):
    sender = make_node("sender")
    dynamic, static = TransformBroadcaster(sender), StaticTransformBroadcaster(sender)
    listener_node = make_node("listener")
    buffer = TransformBuffer()
    listener = TransformListener(listener_node, buffer, future_tolerance_ns=S)
    assert spin_until(executor, lambda: dynamic._publisher.get_subscription_count() > 0, 10.0)
    now = listener_node.get_clock().now().nanoseconds
    dynamic.send([to_message("odom", "base_link", now + 60 * S, Transform())])
    static.send([to_message("base_link", "laser", 0, Transform((0.25, 0.0, 0.0)))])
    assert spin_until(executor, lambda: buffer.can_transform("base_link", "laser"), 10.0)
    static.send([to_message("base_link", "laser", 0, Transform((0.5, 0.0, 0.0)))])
    assert spin_until(executor, lambda: listener.dropped == {"future": 1, "static_changed": 1},
                      10.0), listener.dropped
    assert buffer.lookup("base_link", "laser").translation == (0.25, 0.0, 0.0)
    assert not buffer.can_transform("odom", "base_link")
