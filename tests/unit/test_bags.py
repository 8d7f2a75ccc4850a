"""The one bag reader (tools/recording/bags.py): a robot's ROS 1 bag as this ROS 2's
messages, field by field, and a file that is no bag refused in one line by estimation_play."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from sensor_msgs.msg import Imu

from estimation_nodes.tools.recording.bags import bag_messages
from estimation_nodes.tools.recording.mcap import RecordingError

SHARED = Path(__file__).resolve().parents[3] / "shared" / "data" / "robot_localization"


@pytest.mark.skipif(not SHARED.is_dir(), reason="../shared/data/robot_localization is absent")
def test_a_ros1_bag_becomes_ros2_messages_field_by_field():
    from rosbags.highlevel import AnyReader

    with AnyReader([SHARED / "test2.bag"]) as reader:
        connection = next(c for c in reader.connections if c.topic == "/imu/data")
        _, _, raw = next(reader.messages(connections=[connection]))
        original = reader.deserialize(raw, connection.msgtype)
    stamp, topic, type_name, msg = next(bag_messages(SHARED / "test2.bag", {"/imu/data"}))
    assert (topic, type_name) == ("/imu/data", "sensor_msgs/msg/Imu")
    assert isinstance(msg, Imu) and stamp > 0
    assert msg.header.frame_id == original.header.frame_id
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == \
        (original.header.stamp.sec, original.header.stamp.nanosec)
    assert msg.orientation.w == original.orientation.w
    np.testing.assert_array_equal(msg.orientation_covariance,
                                  original.orientation_covariance)
    assert msg.linear_acceleration.z == original.linear_acceleration.z


def test_a_file_that_is_no_bag_is_refused(tmp_path):
    fake = tmp_path / "broken.bag"
    fake.write_bytes(b"not a bag at all")
    with pytest.raises(RecordingError, match="is not a bag rosbags can read"):
        list(bag_messages(fake))
    result = subprocess.run(
        [sys.executable, "-m", "estimation_nodes.tools.recording.play", str(fake)],
        capture_output=True, text=True, timeout=60)
    assert result.returncode == 2, result.stderr
    assert "is not a bag rosbags can read" in result.stderr
    assert "Traceback" not in result.stderr
