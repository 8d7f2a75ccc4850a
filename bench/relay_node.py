"""The reference for the DDS benchmarks: a bare rclpy node that republishes what it gets.

It subscribes to ``tile_observation`` and publishes the same String on
``relay_out`` (and ``kalman_measurement`` to ``relay_vector_out``, for the
matrix filter's path), with the estimator's own QoS on both sides, so a
benchmark can compare the estimator with the least any rclpy node in its place
could do. For ekf_localizer's place (bench/landmarks/ekf_node.py latency): every ``odom`` and
``landmark_observations`` message is answered on ``pose`` by an empty
PoseWithCovarianceStamped with the event's header, the localizer's QoS on both sides.
For ekf_node's place (bench/fusion/fusion_node.py latency, ``relay_node.py fusion TOPIC:KIND
...``): every message on each input (KIND odom or imu) is answered on
``odometry/filtered`` by an empty Odometry with the message's header, ekf_node's QoS on
both sides.
"""

import sys

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from rclpy.qos import QoSProfile, qos_profile_sensor_data
from sensor_msgs.msg import Imu, PointCloud2
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
        self._pose_pub = self.create_publisher(PoseWithCovarianceStamped, "pose",
                                               latched_qos(1))
        self.create_subscription(Odometry, "odom", self._answer, INPUT_QOS)
        self.create_subscription(PointCloud2, "landmark_observations", self._answer, INPUT_QOS)

    def _answer(self, event) -> None:
        pose = PoseWithCovarianceStamped()
        pose.header = event.header
        self._pose_pub.publish(pose)


class FusionRelay(Node):
    """ekf_node's inputs in (queue 10, best effort, as its subscriptions), an Odometry out on
    odometry/filtered (depth 10, as its publisher) for each."""

    def __init__(self, inputs: list[tuple[str, str]]) -> None:
        super().__init__("fusion_relay")
        self._pub = self.create_publisher(Odometry, "odometry/filtered", 10)
        qos = QoSProfile(depth=10, reliability=qos_profile_sensor_data.reliability)
        for topic, kind in inputs:
            self.create_subscription(Odometry if kind == "odom" else Imu, topic,
                                     self._answer, qos)

    def _answer(self, reading) -> None:
        odometry = Odometry()
        odometry.header = reading.header
        self._pub.publish(odometry)


def main() -> None:
    rclpy.init()
    if sys.argv[1:2] == ["fusion"]:
        node = FusionRelay([tuple(entry.split(":")) for entry in sys.argv[2:]])
    else:
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
