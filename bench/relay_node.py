"""The reference for the DDS benchmarks: a bare rclpy node that republishes what it gets.

It subscribes to ``tile_observation`` and publishes the same String on
``relay_out`` (and ``kalman_measurement`` to ``relay_vector_out``, for the
matrix filter's path), with the estimator's own QoS on both sides, so a
benchmark can compare the estimator with the least any rclpy node in its place
could do.
"""

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray, String

from estimation_nodes.nodes.qos import INPUT_QOS, latched_qos


class Relay(Node):
    def __init__(self) -> None:
        super().__init__("relay")
        self._pub = self.create_publisher(String, "relay_out", latched_qos(1000))
        self.create_subscription(String, "tile_observation", self._pub.publish, INPUT_QOS)
        self._vector_pub = self.create_publisher(
            Float64MultiArray, "relay_vector_out", latched_qos(1000))
        self.create_subscription(Float64MultiArray, "kalman_measurement",
                                 self._vector_pub.publish, INPUT_QOS)


def main() -> None:
    rclpy.init()
    node = Relay()
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
