"""robot_localization's bag tests as the peer runs them: the bag played with ``--clock``
(estimation_play, a ROS 1 bag through rosbags), ``ekf_node`` / ``ukf_node`` started with the
peer's parameter file unchanged under ``use_sim_time``, the IMU's mount (test1) on
``/tf_static``; the last ``odometry/filtered`` position within the peer's tolerance of its
result, and the estimate on ``/tf`` as ``odom -> base_link``.

test1.bag spans 395 s and test2.bag 61 s: test1 is played at 4 times its rate (the peer
plays both at 1), which keeps the suite short and leaves the filter the same inputs on the
bag's clock. Faster is not safe: the peer's files subscribe best effort with queues of 10,
and a node that lags under load loses readings (test1 at 8x was once 3.5 m off; test2 at 2x,
with both cores busy and more beside them, 1.4 m).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from nav_msgs.msg import Odometry
from tf2_msgs.msg import TFMessage

from estimation_nodes.core.geometry import quaternion_from_rpy
from estimation_nodes.core.transforms.rigid import Transform
from estimation_nodes.nodes.tf import TF_QOS, StaticTransformBroadcaster, to_message
from tests.conftest import spin_until
from tests.graph.graph_tools import executable
from tests.unit.test_fusion_bags import FILES, PEER_TESTS, SHARED

#: The Husky's IMU mount in test1 (tests/unit/test_fusion_bags.py says how it was read).
HUSKY_IMU = Transform((0.0, -0.3, 0.52), quaternion_from_rpy(math.pi / 2, 0.0, -math.pi / 2))
RATES = {"test1.bag": 4.0, "test2.bag": 1.0}


@pytest.mark.skipif(not SHARED.is_dir(), reason="../shared/data/robot_localization is absent")
@pytest.mark.timeout(300)
@pytest.mark.parametrize(("bag", "kind", "expected", "tolerance"), PEER_TESTS,
                         ids=[f"{b}-{k}" for b, k, _, _ in PEER_TESTS])
def test_the_peers_bag_test_passes_over_dds(bag, kind, expected, tolerance, context,
                                            executor, collector_factory, processes):
    number = "1" if bag == "test1.bag" else "2"
    params = FILES / f"test_{kind}_localization_node_bag{number}.yaml"
    node_name = f"test_{kind}_localization_node_bag{number}_{kind}"
    seen = collector_factory({"/odometry/filtered": (Odometry, 100), "/tf": (TFMessage, TF_QOS)})
    if number == "1":
        static = StaticTransformBroadcaster(seen.node)
        static.send([to_message("base_link", "imu_link", 0, HUSKY_IMU)])
    node = processes([executable(f"{kind}_node"), "--ros-args", "-r", f"__node:={node_name}",
                      "--params-file", str(params)])
    player = processes([executable("estimation_play"), str(SHARED / bag), "--clock",
                        "--rate", str(RATES[bag]), "--wait-for-subscribers", "60",
                        "--delay", "2"])
    span = 400 if number == "1" else 62
    assert spin_until(executor, lambda: player.poll() is not None,
                      span / RATES[bag] + 120), "the play never ended"
    played = player.stdout.read()
    assert player.returncode == 0, played
    assert spin_until(executor, lambda: seen.count("/odometry/filtered") > 0, 10), \
        node.stdout.read() if node.poll() is not None else "no odometry/filtered"
    spin_until(executor, lambda: False, 1.0)   # the last outputs in flight
    last = seen.messages["/odometry/filtered"][-1]
    final = np.array([last.pose.pose.position.x, last.pose.pose.position.y,
                      last.pose.pose.position.z])
    distance = float(np.linalg.norm(final - np.asarray(expected)))
    print(f"{bag} {kind} over DDS: final {np.round(final, 4)}, {distance:.4f} m from the "
          f"peer's (tolerance {tolerance}); {seen.count('/odometry/filtered')} outputs")
    assert distance < tolerance
    # The same estimate on /tf: odom -> base_link at the output's stamp.
    transforms = {(t.header.stamp.sec, t.header.stamp.nanosec): t
                  for msg in seen.messages["/tf"] for t in msg.transforms
                  if t.header.frame_id == "odom" and t.child_frame_id == "base_link"}
    on_tf = transforms[(last.header.stamp.sec, last.header.stamp.nanosec)].transform
    assert (on_tf.translation.x, on_tf.translation.y, on_tf.translation.z) == tuple(final)
