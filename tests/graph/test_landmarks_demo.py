"""estimation_demo --scenario landmarks --plot: the track among the landmarks, drawn from the
run's recording, the same picture from estimation_plot, and the recording replayed EQUAL."""

import subprocess

import pytest
import yaml
from mcap.reader import make_reader

from tests.conftest import SCENARIOS
from tests.graph.graph_tools import executable
from tests.unit.test_plot import png_size


@pytest.mark.timeout(180)
def test_the_landmarks_demo_draws_its_track(ros_env, tmp_path):
    # The shipped scenario, shorter; the demo has the robot wait for its recorder.
    document = yaml.safe_load((SCENARIOS / "landmarks.yaml").read_text())
    document["/**/landmark_robot"]["ros__parameters"].update(duration=8.0)
    params = tmp_path / "landmarks.yaml"
    params.write_text(yaml.safe_dump(document))
    picture, recording = tmp_path / "track.png", tmp_path / "track.mcap"
    demo = subprocess.run([executable("estimation_demo"), "--params-file", str(params),
                           "--record", str(recording), "--plot", str(picture),
                           "--linger", "0.5"], env=ros_env, capture_output=True, text=True,
                          timeout=150)
    assert demo.returncode == 0, demo.stdout + demo.stderr
    assert "none missing)" in demo.stdout, demo.stdout + demo.stderr
    assert f"plot written to {picture}" in demo.stdout
    assert png_size(picture)[:2] == (1500, 650)
    with recording.open("rb") as stream:
        summary = make_reader(stream).get_summary()
    by_topic = {summary.channels[i].topic: n
                for i, n in summary.statistics.channel_message_counts.items()}
    assert by_topic["/pose"] > 0 and by_topic["/true_pose"] > 0, by_topic
    # The filter offline over the recorded odometry and frames publishes the same poses.
    replay = subprocess.run([executable("estimation_replay"), str(recording)], env=ros_env,
                            capture_output=True, text=True, timeout=120)
    assert replay.returncode == 0, replay.stdout + replay.stderr
    assert "online vs offline to 1e-09: EQUAL" in replay.stdout, replay.stdout
    again = tmp_path / "again.png"
    plot = subprocess.run([executable("estimation_plot"), str(recording), "-o", str(again)],
                          env=ros_env, capture_output=True, text=True, timeout=120)
    assert plot.returncode == 0, plot.stderr
    assert png_size(again)[:2] == (1500, 650)
