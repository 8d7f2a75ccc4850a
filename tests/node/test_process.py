"""A node's process: how it ends."""

import signal

import pytest
import rclpy
from rclpy.node import Node

from estimation_nodes.nodes.process import run


class ShutDownDuringItsTimer(Node):
    """Does in one callback what Ctrl-C and a graph check of the estimator did together:
    the context shut down, then a graph query in a callback rclpy still ran."""

    node_name = "shut_down_during_its_timer"

    def __init__(self) -> None:
        super().__init__(self.node_name)
        self.create_timer(0.01, self._check_graph)

    def _check_graph(self) -> None:
        rclpy.shutdown()
        self.count_publishers("/motion_cmd")   # rcl: "node's context is invalid"


@pytest.fixture
def sigint_restored():
    """run() ignores SIGINT once it shuts down, for the rest of its process: here the
    test's, whose later children would inherit the ignored signal."""
    previous = signal.getsignal(signal.SIGINT)
    yield
    signal.signal(signal.SIGINT, previous)


def test_a_callback_after_shutdown_ends_the_node_normally(ros_env, sigint_restored):
    assert run(ShutDownDuringItsTimer, ["node"]) == 0
