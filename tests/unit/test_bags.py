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


def write_rosbag2(folder: Path) -> None:
    """A rosbag2 (MCAP) of three IMU readings and one message of a robot's own type."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(get_types_from_msg("float64 charge", "robot_own_msgs/msg/Battery"))
    imu_type, battery_type = store.types["sensor_msgs/msg/Imu"], \
        store.types["robot_own_msgs/msg/Battery"]
    header = store.types["std_msgs/msg/Header"]
    time = store.types["builtin_interfaces/msg/Time"]
    vector = store.types["geometry_msgs/msg/Vector3"]
    quaternion = store.types["geometry_msgs/msg/Quaternion"]
    with Writer(folder, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        imu = writer.add_connection("/imu/data", imu_type.__msgtype__, typestore=store)
        battery = writer.add_connection("/battery", battery_type.__msgtype__, typestore=store)
        for k in range(3):
            msg = imu_type(header(time(10 + k, 0), "imu_link"),
                           quaternion(0.0, 0.0, 0.0, 1.0), np.zeros(9),
                           vector(0.0, 0.0, 0.1 * k), np.zeros(9),
                           vector(0.0, 0.0, 9.8), np.zeros(9))
            writer.write(imu, (10 + k) * 10**9, store.serialize_cdr(msg, imu_type.__msgtype__))
        writer.write(battery, 11 * 10**9,
                     store.serialize_cdr(battery_type(0.5), battery_type.__msgtype__))


def test_a_robots_bag_becomes_a_recording_its_own_types_left_out_and_said(tmp_path):
    from rclpy.serialization import deserialize_message

    from estimation_nodes.tools.recording.play import read_raw

    bag = tmp_path / "robot_bag"
    write_rosbag2(bag)
    out = tmp_path / "robot.mcap"
    result = subprocess.run(
        [sys.executable, "-m", "estimation_nodes.tools.importers.cli", "rosbag", str(bag),
         "-o", str(out)], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert "/imu/data: 3 messages" in result.stdout
    assert "/battery left out: its type robot_own_msgs/msg/Battery is not installed here" \
        in result.stdout
    played = read_raw(out)
    assert [(m.topic, m.log_time_ns) for m in played] == \
        [("/imu/data", (10 + k) * 10**9) for k in range(3)]
    last = deserialize_message(played[-1].data, Imu)
    assert (last.header.frame_id, last.header.stamp.sec) == ("imu_link", 12)
    assert last.angular_velocity.z == pytest.approx(0.2)
    assert last.linear_acceleration.z == 9.8
    # The bag itself plays too, its own type left out with one line.
    played_bag = read_raw(bag)
    assert [m.topic for m in played_bag] == ["/imu/data"] * 3


def test_a_folder_that_is_no_bag_is_refused_by_the_importer(tmp_path):
    result = subprocess.run(
        [sys.executable, "-m", "estimation_nodes.tools.importers.cli", "rosbag",
         str(tmp_path), "-o", str(tmp_path / "x.mcap")], capture_output=True, text=True,
        timeout=60)
    assert result.returncode == 2 and "not a ROS 1 bag (.bag) or a rosbag2 folder" \
        in result.stderr, result.stderr
