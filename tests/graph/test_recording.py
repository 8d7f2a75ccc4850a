"""Record a run to MCAP, read it with the mcap tools, replay it offline, plot it."""

import re
import subprocess
import threading

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from tests.conftest import SCENARIOS, spin_until
from tests.graph.graph_tools import executable, node_command
from tests.unit.test_plot import png_size

EXPECTED_TOPICS = {
    "/motion_cmd": "std_msgs/msg/Int32",
    "/tile_observation": "std_msgs/msg/String",
    "/position_measurement": "std_msgs/msg/Float64",
    "/true_position": "std_msgs/msg/Int64",
    "/belief_predicted": "std_msgs/msg/Float64MultiArray",
    "/belief": "std_msgs/msg/Float64MultiArray",
    "/kalman_estimate": "geometry_msgs/msg/PoseWithCovariance",
    "/kalman_estimate_stamped": "geometry_msgs/msg/PoseWithCovarianceStamped",
    "/kalman_estimate_predicted": "geometry_msgs/msg/PoseWithCovariance",
    "/kalman_estimate_predicted_stamped": "geometry_msgs/msg/PoseWithCovarianceStamped",
    "/kalman_state": "std_msgs/msg/Float64MultiArray",
    "/kalman_state_predicted": "std_msgs/msg/Float64MultiArray",
}


def record_run(ros_env, tmp_path, scenario, *extra):
    mcap_path, png_path = tmp_path / f"{scenario}.mcap", tmp_path / f"{scenario}.png"
    result = subprocess.run(
        [executable("estimation_demo"), "--scenario", scenario, "--settle", "0.5",
         "--linger", "0.5", "--quiet", "--record", str(mcap_path), "--plot", str(png_path),
         *extra], env=ros_env, capture_output=True, text=True, timeout=180)
    assert result.returncode == 0, result.stdout + result.stderr
    # The demo's own word that the recording holds every message published.
    assert f"recorded to {mcap_path} (" in result.stdout and "none missing)" in result.stdout, \
        result.stdout
    return mcap_path, png_path


#: What the graph publishes once per step: the commander, the sensor.
INPUTS = ("/motion_cmd", "/tile_observation", "/position_measurement", "/true_position")


def assert_counts(by_topic: dict, steps: int) -> None:
    """Each input once per step; each estimate at least once: the estimator publishes one
    again after an input that arrived late (core/causal_order.py), and the replay pairs
    them with the steps."""
    counts = {t: len(m) for t, m in by_topic.items()}
    assert {t: n for t, n in counts.items() if t in INPUTS} == {
        t: steps for t in INPUTS if t in by_topic}, counts
    assert all(n >= steps for t, n in counts.items() if t not in INPUTS), counts


def decoded_by_topic(path):
    by_topic, schemas = {}, {}
    with path.open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        header = reader.get_header()
        for schema, channel, _message, decoded in reader.iter_decoded_messages():
            by_topic.setdefault(channel.topic, []).append(decoded)
            schemas[channel.topic] = (schema.name, schema.encoding, channel.message_encoding)
    return header, by_topic, schemas


def compared_and_largest_difference(replay_output: str, topic: str) -> tuple[int, float]:
    """What estimation_replay printed for ``topic``: estimates compared, largest difference."""
    found = re.search(rf"^{topic}: (\d+) estimates compared, largest difference (\S+?)[;\n]",
                      replay_output, re.M)
    assert found, replay_output
    return int(found.group(1)), float(found.group(2))


def test_example_6_14_recording_has_every_topic_and_replays_exactly(ros_env, tmp_path):
    mcap_path, png_path = record_run(ros_env, tmp_path, "example_6_14")
    header, by_topic, schemas = decoded_by_topic(mcap_path)
    assert header.profile == "ros2"
    assert {t: s[0] for t, s in schemas.items()} == {
        t: n for t, n in EXPECTED_TOPICS.items()
        if t not in ("/position_measurement", "/kalman_estimate", "/kalman_estimate_stamped",
                     "/kalman_state")}
    assert all(s[1:] == ("ros2msg", "cdr") for s in schemas.values())
    assert_counts(by_topic, 3)
    assert [m.data for m in by_topic["/tile_observation"]] == ["bright", "dark", "dark"]
    np.testing.assert_allclose(by_topic["/belief"][-1].data,
                               [0.048443, 0.063322, 0.244983, 0.528374, 0.114879], atol=1e-6)
    assert by_topic["/belief"][0].layout.dim[0].label == "cells"

    replay = subprocess.run([executable("estimation_replay"), str(mcap_path)], env=ros_env,
                            capture_output=True, text=True, timeout=60)
    assert replay.returncode == 0, replay.stdout + replay.stderr
    assert "online vs offline to 1e-09: EQUAL" in replay.stdout
    assert png_size(png_path)[:2] == (1600, 1200)


def test_seeded_random_run_records_all_topics_and_replays_exactly(ros_env, tmp_path):
    mcap_path, _ = record_run(ros_env, tmp_path, "localization", "--settle", "0.5")
    _, by_topic, schemas = decoded_by_topic(mcap_path)
    assert {t: s[0] for t, s in schemas.items()} == EXPECTED_TOPICS
    assert_counts(by_topic, 40)
    replay = subprocess.run([executable("estimation_replay"), str(mcap_path)], env=ros_env,
                            capture_output=True, text=True, timeout=60)
    assert replay.returncode == 0, replay.stdout + replay.stderr
    assert "online vs offline to 1e-09: EQUAL" in replay.stdout, replay.stdout
    for topic in ("belief", "belief_predicted", "kalman_estimate", "kalman_state"):
        compared, largest = compared_and_largest_difference(replay.stdout, topic)
        # Equal up to rounding: BLAS's dot product may round by an ulp differently for an
        # array at another address, as a belief computed again after a late event is.
        assert compared == 40 and largest <= 1e-12, replay.stdout

    plot = subprocess.run([executable("estimation_plot"), str(mcap_path), "-o",
                           str(tmp_path / "from_recording.png")], env=ros_env,
                          capture_output=True, text=True, timeout=60)
    assert plot.returncode == 0, plot.stderr
    assert png_size(tmp_path / "from_recording.png")[:2] == (1600, 1200)


def test_replay_shows_where_other_parameters_differ(ros_env, tmp_path):
    mcap_path, _ = record_run(ros_env, tmp_path, "example_6_14")
    other = tmp_path / "other.yaml"
    other.write_text("/**/estimator:\n  ros__parameters:\n    motion_kernel: [0.2, 0.6, 0.2]\n")
    replay = subprocess.run([executable("estimation_replay"), str(mcap_path), "--params-file",
                             str(other)], env=ros_env, capture_output=True, text=True,
                            timeout=60)
    assert replay.returncode == 1
    assert "belief_predicted #2: |online - offline|" in replay.stdout
    assert "DIFFERENT" in replay.stdout


@pytest.mark.parametrize("args, message", [
    (["--record", "/nonexistent-dir/run.mcap"], "does not exist"),
    (["--record", "run.bag"], "should end in .mcap"),
])
def test_demo_rejects_bad_record_paths(ros_env, tmp_path, args, message):
    result = subprocess.run([executable("estimation_demo"), "--scenario", "example_6_14",
                             "--in-process", *args], env=ros_env, capture_output=True,
                            text=True, timeout=60, cwd=tmp_path)
    assert result.returncode == 2 and message in result.stderr, result.stderr


def test_replay_rejects_a_file_that_is_not_mcap(ros_env, tmp_path):
    bogus = tmp_path / "bogus.mcap"
    bogus.write_bytes(b"not an mcap file at all")
    result = subprocess.run([executable("estimation_replay"), str(bogus)], env=ros_env,
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and "not a readable MCAP recording" in result.stderr


class RobotLog:
    """The lines a child prints (stdout and stderr together), read by a thread as they come."""

    def __init__(self, process) -> None:
        self.lines: list[str] = []
        self._thread = threading.Thread(target=self._read, args=(process,), daemon=True)
        self._thread.start()

    def _read(self, process) -> None:
        for line in process.stdout:
            self.lines.append(line)

    def said(self, *texts: str) -> bool:
        return any(text in line for line in list(self.lines) for text in texts)


class Stamps:
    """A sink that keeps the header stamps of the scans and poses the monitor takes."""

    def __init__(self) -> None:
        from geometry_msgs.msg import PoseWithCovarianceStamped
        from sensor_msgs.msg import LaserScan

        self.types = {"/scan": LaserScan, "/pose": PoseWithCovarianceStamped}
        self.stamps: dict[str, list[int]] = {topic: [] for topic in self.types}

    def write(self, topic, data, log_time_ns, publish_time_ns, sequence=None) -> None:
        from rclpy.serialization import deserialize_message

        from estimation_nodes.tools.replay.grid_localizer import header_stamp_ns

        if topic in self.types:
            msg = deserialize_message(data, self.types[topic])
            self.stamps[topic].append(header_stamp_ns(msg))

    def past_first_update(self) -> bool:
        """The localizer's start and first update are in, and a scan as late as that
        update: the scans come in order, so its own is in too if it was ever to be."""
        poses, scans = self.stamps["/pose"], self.stamps["/scan"]
        return len(poses) >= 2 and bool(scans) and max(scans) >= poses[1]


@pytest.mark.timeout(180)
def test_a_late_recorder_named_by_the_demo_still_has_the_robots_first_scan(
        processes, context, executor, tmp_path):
    """The demo adds its monitor to the nodes the robot waits for (tools/demo/overrides.py):
    a monitor that comes after the robot is up still records its whole run from the first
    odometry and scan, so every scan the localizer took, and every pose it published."""
    from estimation_nodes.tools.demo.grid_run import GridMonitor, topic_types
    from estimation_nodes.tools.demo.overrides import GRID_MONITOR, node_overrides
    from estimation_nodes.tools.recording.mcap import McapRunWriter
    from estimation_nodes.tools.replay.grid_localizer import header_stamp_ns, recorded_records

    text = (SCENARIOS / "grid_corridor.yaml").read_text()
    params = tmp_path / "corridor.yaml"
    params.write_text(text + "/**/planar_robot:\n  ros__parameters:\n    seed: 7\n"
                      "    duration: 20.0\n")
    overrides = node_overrides(text, "grid", monitor_hears_inputs=True)
    processes(node_command("grid_localizer", params, *overrides["grid_localizer"]))
    robot = processes(node_command("planar_robot", params, *overrides["planar_robot"]))
    log = RobotLog(robot)
    # The monitor comes once the robot is up and says whom it waits for; without the
    # demo's monitor among them, once it has started moving (too late for its first scans).
    assert spin_until(executor, lambda: log.said(GRID_MONITOR, "are heard: moving"), 90.0), \
        "".join(log.lines)
    path = tmp_path / "late.mcap"
    writer = McapRunWriter(path, topic_types("grid"), {"parameters_yaml": text})
    heard = Stamps()
    monitor = GridMonitor(quiet=True, sinks=[writer, heard], context=context)
    executor.add_node(monitor)
    try:
        assert spin_until(executor, heard.past_first_update, 120.0), \
            ("".join(log.lines), heard.stamps)
    finally:
        executor.remove_node(monitor)
        monitor.destroy_node()
        writer.close()
    assert writer.gaps.missing() == {}, writer.gaps.describe()
    records, _ = recorded_records(path)
    scans = {header_stamp_ns(r.msg) for r in records if r.topic == "/scan"}
    stamps = [header_stamp_ns(r.msg) for r in records if r.topic == "/pose"]
    # The first pose is the localizer's start (uniform belief); each one after it is an
    # update with a scan, which the recording holds: the first one above all. (A pose
    # stamped after the last scan recorded may have come in before its scan: not judged.)
    assert scans and len(stamps) >= 2, (len(scans), stamps)
    assert stamps[1] in scans
    assert [stamp for stamp in stamps[1:] if stamp <= max(scans) and stamp not in scans] == []
