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


class InterruptedInItsTimer(Node):
    """Sends its own process a SIGINT from a timer, as a terminal's Ctrl-C would, and
    counts the callbacks run after it."""

    node_name = "interrupted_in_its_timer"

    def __init__(self) -> None:
        super().__init__(self.node_name)
        self.ticks_after = 0
        self._sent = False
        self.create_timer(0.01, self._tick)

    def _tick(self) -> None:
        if self._sent:
            self.ticks_after += 1
            return
        self._sent = True
        signal.raise_signal(signal.SIGINT)


def test_a_ctrl_c_during_the_spin_ends_it_at_its_next_turn(ros_env, sigint_restored):
    made = []

    def make():
        made.append(InterruptedInItsTimer())
        return made[-1]

    # Noted, not raised inside rclpy: run() returns 0 with the callback finished.
    assert run(make, ["node"]) == 0
    assert made and made[0].ticks_after == 0
