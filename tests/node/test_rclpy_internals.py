"""The private rclpy API that nodes/rclpy_internals.py relies on is still there.

If one of these fails after an rclpy upgrade, the message names what changed:
replace that piece (or drop the one-waitable optimization for rclpy's public
SubscriptionEventCallbacks) before anything else.
"""

import importlib

import pytest
from rclpy.node import Node
from std_msgs.msg import String

from estimation_nodes.nodes.qos import INPUT_QOS


@pytest.mark.parametrize("module, name", [
    ("rclpy._rclpy_pybind11", "RCLError"),
    ("rclpy.impl.implementation_singleton", "rclpy_implementation"),
    ("rclpy.executors", "await_or_execute"),
])
def test_private_names_still_exist(module, name):
    assert hasattr(importlib.import_module(module), name), (
        f"rclpy changed: {module}.{name} is gone; nodes/rclpy_internals.py uses it")


def test_an_event_handle_can_be_made_waited_on_and_taken(context):
    from rclpy.event_handler import SubscriptionEventCallbacks
    from rclpy.executors import SingleThreadedExecutor

    from estimation_nodes.nodes.rclpy_internals import MESSAGE_LOST, SubscriptionEvents

    node = Node("internals_probe", context=context)
    executor = SingleThreadedExecutor(context=context)
    try:
        subscription = node.create_subscription(
            String, "probe", lambda msg: None, INPUT_QOS,
            event_callbacks=SubscriptionEventCallbacks(use_default_callbacks=False))
        events = SubscriptionEvents(node.default_callback_group)
        try:
            events.watch(subscription, MESSAGE_LOST, lambda info: None)
        except (AttributeError, TypeError) as error:
            pytest.fail(f"rclpy changed: EventHandle(subscription handle, event type) "
                        f"failed: {error}")
        node.add_waitable(events)
        executor.add_node(node)
        try:
            # One pass through the executor: add_to_wait_set, is_ready, (take_data).
            executor.spin_once(timeout_sec=0.05)
        except (AttributeError, TypeError) as error:
            pytest.fail(f"rclpy changed: the wait set's event API (add_event, "
                        f"is_ready('event', i)) failed: {error}")
        node.remove_waitable(events)
        events.destroy()
    finally:
        executor.shutdown()
        node.destroy_node()


def test_the_overrides_given_to_a_node_can_be_read(context):
    from rclpy.parameter import Parameter

    from estimation_nodes.nodes.rclpy_internals import parameter_overrides

    node = Node("overrides_probe", context=context,
                parameter_overrides=[Parameter("given", value=1)])
    try:
        assert "given" in parameter_overrides(node), (
            "rclpy changed: Node._parameter_overrides no longer holds the given values")
    finally:
        node.destroy_node()


class FakeHandle:
    """Counts how deeply it is held, as an rcl handle's context manager does."""

    def __init__(self, gone=False):
        self.held, self.gone = 0, gone

    def __enter__(self):
        if self.gone:
            raise RuntimeError("destroyed")
        self.held += 1

    def __exit__(self, *exc_info):
        self.held -= 1


def test_the_events_waitable_holds_its_handles_for_the_wait_and_no_longer():
    from rclpy.callback_groups import MutuallyExclusiveCallbackGroup

    from estimation_nodes.nodes.rclpy_internals import SubscriptionEvents

    events = SubscriptionEvents(MutuallyExclusiveCallbackGroup())
    first, second = FakeHandle(), FakeHandle()
    events._handles = [first, second]
    events.__enter__()
    assert (first.held, second.held) == (1, 1)
    events.__exit__(None, None, None)
    assert (first.held, second.held) == (0, 0)
    # A handle destroyed meanwhile: the executor skips the waitable, which must let go of
    # the handles it took before it.
    events._handles = [first, FakeHandle(gone=True)]
    with pytest.raises(RuntimeError):
        events.__enter__()
    assert first.held == 0
