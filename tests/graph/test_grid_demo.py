"""estimation_demo --scenario grid_localization: the robot found without an initial pose."""

import re
import subprocess

import pytest
import yaml
from mcap.reader import make_reader

from tests.conftest import SCENARIOS
from tests.graph.graph_tools import executable


@pytest.mark.timeout(180)
def test_the_grid_demo_finds_the_robot_and_records_the_run(ros_env, tmp_path):
    # The shipped scenario, shorter: 14 s of wandering, kidnapped at 8 s.
    document = yaml.safe_load((SCENARIOS / "grid_localization.yaml").read_text())
    document["/**/planar_robot"]["ros__parameters"].update(duration=14.0, kidnap_after=8.0)
    # Nothing about the recorder: the demo has the robot wait for it and the localizer keep
    # its outputs for it (tools/demo/overrides.py), and says whether it missed anything.
    params = tmp_path / "grid.yaml"
    params.write_text(yaml.safe_dump(document))
    recording = tmp_path / "grid.mcap"
    demo = subprocess.run([executable("estimation_demo"), "--params-file", str(params),
                           "--record", str(recording), "--linger", "0.5"], env=ros_env,
                          capture_output=True, text=True, timeout=150)
    shown = demo.stdout[-4000:] + demo.stderr[-2000:]
    assert demo.returncode == 0, shown
    assert re.search(rf"recorded to {re.escape(str(recording))} \(\d+ messages, none missing\)",
                     demo.stdout), shown
    near, updates = (int(v) for v in re.search(
        r"within 0\.3 m and 10 deg of the truth in (\d+) of (\d+) updates", demo.stdout).groups())
    # The robot starts once the localizer is ready, and an update is due every 0.25 m of
    # its 7 m (14 s at 0.5 m/s): some 30, whatever the machine's speed; fewer means scans
    # were left out for want of time (allowed) for most of the run.
    assert updates >= 10, shown
    # Found from a uniform belief, and again after the kidnap, within a few updates.
    assert near / updates >= 0.8, shown
    last_quality = float(re.search(r"at the last (\d\.\d+)", demo.stdout).group(1))
    assert last_quality > 0.9, shown
    with recording.open("rb") as stream:
        summary = make_reader(stream).get_summary()
    channels = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
    assert channels["/scan"] == "sensor_msgs/msg/LaserScan"
    assert channels["/belief_map"] == "nav_msgs/msg/OccupancyGrid"
    counts = summary.statistics.channel_message_counts
    by_topic = {summary.channels[i].topic: n for i, n in counts.items()}
    assert by_topic["/pose"] >= updates and by_topic["/odom"] >= 100
    # The localizer offline over the recorded odometry and scans: the same updates, to 1e-9.
    replay = subprocess.run([executable("estimation_replay"), str(recording)], env=ros_env,
                            capture_output=True, text=True, timeout=120)
    print(replay.stdout)
    assert replay.returncode == 0, replay.stdout + replay.stderr
    compared = int(re.search(r"pose: (\d+) updates compared", replay.stdout).group(1))
    assert compared >= updates - 1 and "taken to have made" not in replay.stdout
    # And the picture of it, from the recording.
    picture = tmp_path / "grid.png"
    plot = subprocess.run([executable("estimation_plot"), str(recording), "-o", str(picture)],
                          env=ros_env, capture_output=True, text=True, timeout=120)
    assert plot.returncode == 0, plot.stderr
    assert picture.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_bad_map_ends_the_localizer_with_one_line(ros_env, tmp_path):
    (tmp_path / "map.yaml").write_text("image: missing.pgm\nresolution: 0.05\n"
                                       "origin: [0.0, 0.0, 0.0]\n")
    result = subprocess.run([executable("grid_localizer"), "--ros-args", "-p",
                             f"map_file:={tmp_path / 'map.yaml'}"], env=ros_env,
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    lines = [line for line in (result.stdout + result.stderr).splitlines() if line.strip()]
    assert len(lines) == 1 and "image" in lines[0] and "does not exist" in lines[0], lines
