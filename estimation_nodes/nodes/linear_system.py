"""The simulated linear system of the book's Eq. 6.34, for the matrix Kalman filter.

On every ``kalman_input`` (m values) the true state moves as
x(k+1) = A x(k) + B u(k) + F w(k) with w drawn from N(0, Q); the node then
publishes the truth on ``true_state`` and a measurement z = C x + v, v drawn
from N(0, R), on ``kalman_measurement``. The matrices are the estimator's
``kalman.matrix.*`` parameters, so one scenario section serves both.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray

from estimation_nodes.core.sim import draws as simulation
from estimation_nodes.nodes import wire
from estimation_nodes.nodes.held_publisher import HeldPublisher, subscribe_when_ready
from estimation_nodes.nodes.parameters import declare_and_build
from estimation_nodes.nodes.process import main_for
from estimation_nodes.nodes.qos import INPUT_QOS, latched_qos
from estimation_nodes.params import topics
from estimation_nodes.params.simulators import build_linear_system_settings
from estimation_nodes.params.specs import LINEAR_SYSTEM_SPECS
from estimation_nodes.params.wording import plural


class LinearSystem(Node):
    """Ground truth and noisy measurements of a linear Gaussian system."""

    node_name = "linear_system"

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(self.node_name, **kwargs)
        values, settings = declare_and_build(
            self, LINEAR_SYSTEM_SPECS, build_linear_system_settings)
        self._model = settings.model
        self._state = settings.initial_state.copy()
        seed = values["seed"]
        self._rng = np.random.default_rng(None if seed < 0 else seed)
        self._truth_pub = self.create_publisher(
            Float64MultiArray, topics.TRUE_STATE, latched_qos(100))
        self._measurement_pub = HeldPublisher(
            self, Float64MultiArray, topics.KALMAN_MEASUREMENT, values["hold_until_matched"],
            values["hold_for_nodes"])
        subscribe_when_ready(self, [self._measurement_pub], values["hold_until_matched"],
                             lambda: self.create_subscription(
                                 Float64MultiArray, topics.KALMAN_INPUT, self._on_kalman_input,
                                 INPUT_QOS))
        self.rejected = 0
        model = self._model
        self.get_logger().info(
            f"ready: {plural(model.state_size, 'state')}, {plural(model.input_size, 'input')}, "
            f"{plural(model.measurement_size, 'measurement')} (seed {seed})")

    def _on_kalman_input(self, msg: Float64MultiArray) -> None:
        u = np.frombuffer(msg.data, dtype=np.float64)
        if u.size != self._model.input_size or not np.isfinite(u).all():
            self.rejected += 1
            self.get_logger().warning(
                f"kalman_input dropped: expected {self._model.input_size} finite values, "
                f"got {u.tolist()}", throttle_duration_sec=5.0)
            return
        with np.errstate(over="ignore", invalid="ignore"):   # checked just below
            state, z = simulation.linear_system_step(self._state, u, self._model, self._rng)
        if not (np.isfinite(state).all() and np.isfinite(z).all()):
            self.rejected += 1
            self.get_logger().warning(
                f"kalman_input {u.tolist()} dropped: the simulated state would not be finite",
                throttle_duration_sec=5.0)
            return
        self._state = state
        self._truth_pub.publish(wire.vector(self._state, "state"))
        self._measurement_pub.publish(wire.vector(z, "measurement"))


main = main_for(LinearSystem)

if __name__ == "__main__":
    main()
