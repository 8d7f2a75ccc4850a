"""estimation_play: a recording's messages published again to a subscriber, each one, in
the recorded order per topic, with the QoS a driver uses, and /clock with --clock."""

from __future__ import annotations

import subprocess
import sys

import pytest
from nav_msgs.msg import Odometry
from rclpy.qos import qos_profile_sensor_data
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import LaserScan

from estimation_nodes.nodes.qos import INPUT_QOS
from estimation_nodes.tools.importers import cli
from tests.conftest import spin_until
from tests.unit.test_importers import corrected_log

PLAY = [sys.executable, "-m", "estimation_nodes.tools.recording.play"]


@pytest.fixture
def recording(tmp_path):
    log = tmp_path / "run.log"
    log.write_text(corrected_log())
    out = tmp_path / "run.mcap"
    cli.main(["carmen", str(log), "-o", str(out)])
    return out


def stamp_s(msg) -> float:
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


@pytest.mark.timeout(90)
def test_every_message_is_played_in_its_order_with_a_clock(recording, collector_factory,
                                                           executor, processes):
    seen = collector_factory({"/scan": (LaserScan, qos_profile_sensor_data),
                              "/odom": (Odometry, INPUT_QOS), "/clock": (Clock, 10)})
    # The player counts our subscriptions before they may know its publishers; the delay
    # lets our side of each match complete before the first message (see play.py).
    player = processes([*PLAY, str(recording), "--rate", "4", "--clock",
                        "--topics", "/scan", "odom", "--wait-for-subscribers", "30",
                        "--delay", "3"])
    assert spin_until(executor, lambda: player.poll() is not None, 60), "the play never ended"
    output = player.stdout.read()
    assert player.returncode == 0, output
    # /ground_truth was not asked for: 2 scans and 6 odometry messages were played.
    assert "8 messages published" in output
    # Best effort may lose a scan on a loaded machine; odometry is reliable.
    assert spin_until(executor, lambda: seen.count("/odom") == 6, 10), \
        [stamp_s(m) for m in seen.messages["/odom"]]
    assert [stamp_s(m) for m in seen.messages["/odom"]] == pytest.approx(
        [0.01, 1.01, 1.02, 2.01, 3.01, 3.02])
    assert {stamp_s(m) for m in seen.messages["/scan"]} <= {1.02, 3.02}
    clock = [m.clock.sec + m.clock.nanosec * 1e-9 for m in seen.messages["/clock"]]
    assert clock and clock == sorted(clock) and max(clock) == pytest.approx(3.02)


@pytest.mark.parametrize("arguments, says", [(["missing.mcap"], "is not a file"),
                                              (["RUN", "--topics", "/nothing"], "no message")])
def test_a_recording_that_cannot_be_played_is_one_line_and_exit_2(recording, ros_env,
                                                                  arguments, says):
    arguments = [str(recording) if a == "RUN" else a for a in arguments]
    result = subprocess.run([*PLAY, *arguments], env=ros_env, capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 2 and says in result.stderr
    assert result.stderr.count("\n") == 1 and "Traceback" not in result.stderr
