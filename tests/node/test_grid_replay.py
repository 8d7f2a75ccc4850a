"""A recorded grid_localizer run in which it left scans out replays EQUAL.

A driver sends the localizer odometry and ray-cast scans of a robot driving
along the corridor, in orders that make it skip scans the way it does under
load: a scan before its odometry (it waits), a second scan while one waits
(the first is superseded), a scan whose odometry comes too late (dropped),
and scans without enough motion; then a global localization and an initial
pose. Everything sent and published is written to an MCAP file as
estimation_demo records it, and the replay must make every update again.
"""

import math
import time

import numpy as np
import pytest
import yaml
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import OccupancyGrid, Odometry
from rclpy.node import Node
from rclpy.serialization import serialize_message
from sensor_msgs.msg import LaserScan
from std_msgs.msg import Float64
from std_srvs.srv import Trigger

from estimation_nodes.core.sim import planar
from estimation_nodes.nodes import grid_localizer
from estimation_nodes.nodes.grid_localizer import GridLocalizer
from estimation_nodes.nodes.grid_messages import fill_pose
from estimation_nodes.nodes.qos import latched_qos
from estimation_nodes.params.map_files import read_map_file
from estimation_nodes.tools.recording.mcap import McapRunWriter
from estimation_nodes.tools.replay import estimator as replay_cli
from estimation_nodes.tools.replay.grid_localizer import replay_grid
from tests.node.test_grid_nodes import STANDALONE
from tests.conftest import REPO, spin_until
from tests.node.test_grid_nodes import params

CORRIDOR = REPO / "maps" / "corridor.yaml"
SECOND = 10**9
T0 = 1000 * SECOND
OUTPUTS = {"/pose": PoseWithCovarianceStamped, "/localization_quality": Float64,
           "/belief_map": OccupancyGrid}
INPUTS = {"/odom": Odometry, "/scan": LaserScan, "/initialpose": PoseWithCovarianceStamped}


class Driver:
    """Sends the inputs and keeps every message sent or heard, raw, for the recording."""

    def __init__(self, context, executor, localizer: GridLocalizer) -> None:
        self.node = Node("driver", context=context)
        executor.add_node(self.node)
        self.executor, self.localizer = executor, localizer
        self.written: list[tuple[str, bytes, int]] = []
        self.publishers = {topic: self.node.create_publisher(kind, topic.lstrip("/"), 50)
                           for topic, kind in INPUTS.items()}
        for topic, kind in OUTPUTS.items():
            self.node.create_subscription(kind, topic.lstrip("/"), self._keep(topic),
                                          latched_qos(1000), raw=True)
        self.world = planar.planar_world(read_map_file(CORRIDOR))
        self.angles = -math.pi + 2 * math.pi * np.arange(120) / 120

    def _keep(self, topic: str):
        def keep(data: bytes, info) -> None:
            self.written.append((topic, data, info["source_timestamp"]))
        return keep

    def heard(self, topic: str) -> int:
        return sum(kept == topic for kept, _, _ in self.written)

    def send(self, topic: str, msg) -> None:
        self.publishers[topic].publish(msg)
        self.written.append((topic, serialize_message(msg), time.time_ns()))

    def wait(self, condition, what: str) -> None:
        assert spin_until(self.executor, condition, 10.0), f"the localizer did not {what}: " \
            f"handled {dict(self.localizer.handled)}, rejected {dict(self.localizer.rejected)}"

    def counted(self, key: str, table: str = "handled"):
        start = getattr(self.localizer, table)[key]
        return lambda: getattr(self.localizer, table)[key] > start

    def odom(self, step: int) -> None:
        msg = Odometry()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp(step), SECOND)
        fill_pose(msg.pose.pose, *pose(step))
        taken = self.counted("odom")
        self.send("/odom", msg)
        self.wait(taken, f"take odometry {step}")

    def scan(self, step: int, then: str) -> None:
        msg = LaserScan()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp(step), SECOND)
        msg.angle_min, msg.angle_increment = float(self.angles[0]), 2 * math.pi / 120
        msg.range_min, msg.range_max = 0.05, 12.0
        msg.ranges = planar.ray_cast(self.world, pose(step), self.angles, 12.0).tolist()
        outcome = {"updates": self.counted("scan"),
                   "is not due": self.counted("scan_without_motion"),
                   "waits": lambda: bool(self.localizer._waiting_scans)
                   and self.localizer._waiting_scans[-1][1] == stamp(step),
                   "supersedes": self.counted("scan_superseded")}[then]
        self.send("/scan", msg)
        self.wait(outcome, f"say scan {step} {then}")


def stamp(step: int) -> int:
    return T0 + step * SECOND // 10


def pose(step: int) -> tuple[float, float, float]:
    """Along the corridor, 0.2 m a step (a scan is due after 0.25 m), turning a little."""
    return (3.0 + 0.2 * step, 2.0, 0.01 * step)


@pytest.mark.timeout(120)
def test_a_run_in_which_the_localizer_left_scans_out_replays_equal(context, executor,
                                                                  tmp_path, capsys,
                                                                  monkeypatch):
    monkeypatch.setattr(grid_localizer, "WAITING_SCANS", 2)
    localizer = GridLocalizer(context=context, parameter_overrides=params(
        map_file=str(CORRIDOR), heading_bins=8, **STANDALONE))
    executor.add_node(localizer)
    driver = Driver(context, executor, localizer)
    try:
        # The start's outputs heard (latched) before anything can replace them.
        driver.wait(lambda: all(p.get_subscription_count() for p in driver.publishers.values())
                    and all(driver.heard(topic) for topic in OUTPUTS), "hear the driver")
        driver.odom(0)
        driver.scan(0, "updates")                  # the first scan updates at once
        driver.odom(1)
        driver.scan(1, "is not due")               # 0.2 m since the last update
        driver.scan(2, "waits")                    # before its odometry: it waits for it
        updated = driver.counted("scan")
        driver.odom(2)
        driver.wait(updated, "update with scan 2 once its odometry came")
        driver.odom(3)
        driver.scan(3, "is not due")
        driver.scan(4, "waits")                    # due (0.4 m), but ...
        driver.scan(5, "waits")                    # (behind it)
        driver.scan(6, "supersedes")               # ... left out: 2 scans wait here
        updated = driver.counted("scan")
        driver.odom(4)
        driver.odom(5)
        driver.wait(updated, "update with scan 5")
        not_due = driver.counted("scan_without_motion")
        driver.odom(6)
        driver.wait(not_due, "find scan 6 not due once its odometry came")
        driver.scan(7, "waits")                    # due, and its odometry comes too late
        driver.wait(driver.counted("scan_without_odometry", "rejected"),
                    "drop scan 7 after odom_wait")
        driver.odom(7)
        driver.odom(8)
        driver.scan(8, "updates")
        client = driver.node.create_client(Trigger, "/grid_localizer/global_localization")
        assert client.wait_for_service(timeout_sec=5.0)
        future = client.call_async(Trigger.Request())
        driver.wait(future.done, "reset")
        for step in (9, 10):
            driver.odom(step)
            driver.scan(step, "is not due" if step == 9 else "updates")
        prior = PoseWithCovarianceStamped()
        prior.header.stamp.sec, prior.header.stamp.nanosec = divmod(stamp(10) + 5000, SECOND)
        fill_pose(prior.pose.pose, *pose(10))
        prior.pose.covariance = np.diag([0.04, 0.04, 0, 0, 0, 0.01]).ravel().tolist()
        taken = driver.counted("initialpose")
        driver.send("/initialpose", prior)
        driver.wait(taken, "take the initial pose")
        for step in (11, 12):
            driver.odom(step)
            driver.scan(step, "is not due" if step == 11 else "updates")
        # An initial pose as `ros2 topic pub` sends one, without a stamp: answered with a
        # pose stamped at the localizer's clock, which no recorded input's stamp explains.
        unstamped = PoseWithCovarianceStamped()
        fill_pose(unstamped.pose.pose, *pose(12))
        unstamped.pose.covariance = np.diag([0.09, 0.09, 0, 0, 0, 0.02]).ravel().tolist()
        taken = driver.counted("initialpose")
        driver.send("/initialpose", unstamped)
        driver.wait(taken, "take the unstamped initial pose")
        driver.odom(13)
        driver.odom(14)
        driver.scan(14, "updates")
        # Its outputs: the start, each update, the reset and the two priors.
        published = 1 + localizer.localization.updates + 3
        heard = driver.heard
        driver.wait(lambda: all(heard(topic) == published for topic in OUTPUTS),
                    f"publish its {published} outputs (heard "
                    f"{ {topic: heard(topic) for topic in OUTPUTS} })")
    finally:
        driver.node.destroy_node()
        localizer.destroy_node()
    assert localizer.localization.updates == 7       # scans 0, 2, 5, 8, 10, 12, 14
    assert localizer.handled["scan_superseded"] == 1
    assert localizer.rejected["scan_without_odometry"] == 1

    path = tmp_path / "run.mcap"
    parameters = {"/grid_localizer": {"ros__parameters": {"map_file": str(CORRIDOR),
                                                          "heading_bins": 8, **STANDALONE}}}
    writer = McapRunWriter(path, {**{t: _type(k) for t, k in INPUTS.items()},
                                  **{t: _type(k) for t, k in OUTPUTS.items()}},
                           {"parameters_yaml": yaml.safe_dump(parameters), "kind": "grid"})
    for topic, data, published_ns in driver.written:
        writer.write(topic, data, published_ns, published_ns)
    writer.close()

    comparison = replay_grid(path, None, 1e-9)
    assert comparison.differences == [] and comparison.compared == 7
    assert dict(comparison.others) == {"start": 1, "reset": 1, "prior": 2}
    # Scans 4 and 7 were due by the rule: a replay taking every due scan would differ.
    assert comparison.left_out == 2
    with pytest.raises(SystemExit) as exit_code:
        replay_cli.main([str(path)])
    assert exit_code.value.code == 0
    assert "online vs offline to 1e-09: EQUAL" in capsys.readouterr().out


def _type(kind: type) -> str:
    return f"{kind.__module__.split('.')[0]}/msg/{kind.__name__}"
