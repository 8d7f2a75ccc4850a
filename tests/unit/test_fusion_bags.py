"""robot_localization's own bag tests, run in-process through ekf_node's / ukf_node's filter.

The peer plays each bag, runs its node with the test's parameter file, and passes when
the last ``odometry/filtered`` position is within a tolerance of its own result (the
expected positions below are the peer's, from ../shared/data/robot_localization/README.md).
The parameter files are the peer's, unchanged (tests/data/robot_localization/).

test1.bag has no /tf: the peer's test publishes the IMU's mount. Its ROS 1 launch gave it
as ``static_transform_publisher 0 -0.3 0.52 -1.570796327 0 1.570796327`` (x y z yaw pitch
roll), so here by the ``--mount`` parameter: yaw -pi/2, roll pi/2. (The ROS 2 branch's
rewrite with --roll/--yaw swapped the two; with it the roll converges to pi.)
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from estimation_nodes.params.fusion import fusion_config, parameters_of_file
from estimation_nodes.tools.fusion import offline
from estimation_nodes.tools.recording import bags

SHARED = Path(__file__).resolve().parents[3] / "shared" / "data" / "robot_localization"
FILES = Path(__file__).resolve().parents[1] / "data" / "robot_localization"
HUSKY_IMU_MOUNT = "imu_link=0,-0.3,0.52,1.570796327,0,-1.570796327"

#: (bag, filter, the peer's final x y z, its tolerance)
PEER_TESTS = [
    ("test1.bag", "ekf", (-40.0454, -76.9988, -2.6974), 1.0452),
    ("test1.bag", "ukf", (-39.7333, -76.9820, -2.4427), 1.2910),
    ("test2.bag", "ekf", (1.0206, 3.4292, 0.7419), 0.1383),
    ("test2.bag", "ukf", (1.0438, 3.4940, 0.7260), 0.2351),
]


def run_peer_test(bag: str, kind: str) -> offline.FusionRun:
    number = "1" if bag == "test1.bag" else "2"
    params = parameters_of_file(str(FILES / f"test_{kind}_localization_node_bag{number}.yaml"))
    config = fusion_config(params)
    assert config.settings.kind == kind
    topics = {sensor.topic for sensor in config.sensors.values()}
    mounts = dict([offline.parse_mount(HUSKY_IMU_MOUNT)]) if number == "1" else {}
    return offline.run(config, offline.bag_messages(SHARED / bag, topics), mounts)


@pytest.mark.skipif(not SHARED.is_dir(), reason="../shared/data/robot_localization is absent")
@pytest.mark.timeout(600)
@pytest.mark.parametrize(("bag", "kind", "expected", "tolerance"), PEER_TESTS,
                         ids=[f"{b}-{k}" for b, k, _, _ in PEER_TESTS])
def test_the_peers_bag_test_passes_in_process(bag, kind, expected, tolerance):
    result = run_peer_test(bag, kind)
    final = result.fusion.x[:3]
    distance = float(np.linalg.norm(final - np.asarray(expected)))
    print(f"{bag} {kind}: final {np.round(final, 4)}, {distance:.4f} m from the peer's "
          f"(tolerance {tolerance})")
    assert distance < tolerance
    # Every input was taken: nothing dropped, nothing rejected (no thresholds are set).
    assert result.inputs.dropped == {}
    assert result.fusion.counts.rejected == {}
    assert np.all(np.isfinite(result.fusion.p))
    assert math.isfinite(float(np.trace(result.fusion.p)))


@pytest.mark.skipif(not SHARED.is_dir(), reason="../shared/data/robot_localization is absent")
def test_the_offline_run_reads_the_bags_messages_as_the_node_receives_them():
    """estimation_fuse takes the messages as rosbags decoded them (no copy into rclpy's
    classes): the run is the same, to the bit, as on the rclpy messages the node gets."""
    config = fusion_config(parameters_of_file(
        str(FILES / "test_ekf_localization_node_bag2.yaml")))
    topics = {sensor.topic for sensor in config.sensors.values()}
    decoded = offline.run(config, offline.bag_messages(SHARED / "test2.bag", topics))
    as_rclpy = offline.run(config, ((stamp, topic, msg) for stamp, topic, _, msg
                                    in bags.bag_messages(SHARED / "test2.bag", topics)))
    assert len(decoded.outputs) == len(as_rclpy.outputs) > 3000
    for (stamp, x), (stamp_rclpy, x_rclpy) in zip(decoded.outputs, as_rclpy.outputs):
        assert stamp == stamp_rclpy
        np.testing.assert_array_equal(x, x_rclpy)
    np.testing.assert_array_equal(decoded.fusion.p, as_rclpy.fusion.p)


@pytest.mark.skipif(not SHARED.is_dir(), reason="../shared/data/robot_localization is absent")
def test_estimation_fuse_prints_the_final_position(capsys):
    code = offline.main([str(SHARED / "test2.bag"), "--params-file",
                         str(FILES / "test_ekf_localization_node_bag2.yaml")])
    out = capsys.readouterr().out
    assert code == 0
    assert "ekf: final position x 1.0" in out


def test_estimation_fuse_refuses_a_bad_parameter_file_in_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("ekf:\n  ros__parameters:\n    frequency: 30.0\n    odom0: /odom\n"
                   "    odom0_config: [true, false]\n")
    code = offline.main([str(tmp_path / "x.bag"), "--params-file", str(bad)])
    err = capsys.readouterr().err
    assert code == 2
    assert "odom0_config: expected 15 booleans" in err


#: Run in a process of its own (the kernels' signatures grow in a process, never shrink):
#: which kernels a bag's readings made numba compile anew after warm_up.
COMPILED_DURING_A_RUN = """
import sys
from estimation_nodes.core.fusion import steps
from estimation_nodes.tools.fusion import offline
steps.prepare_compiled()
kernels = steps.kernels()
dispatchers = {name: getattr(kernels, name) for name in dir(kernels)
               if hasattr(getattr(kernels, name), "signatures")}
before = {name: len(d.signatures) for name, d in dispatchers.items()}
for kind in ("ekf", "ukf"):
    offline.main([sys.argv[1], "--params-file", sys.argv[2].format(kind=kind)])
print("compiled during the run:",
      sorted(name for name, d in dispatchers.items() if len(d.signatures) > before[name]))
"""


@pytest.mark.skipif(not SHARED.is_dir(), reason="../shared/data/robot_localization is absent")
@pytest.mark.timeout(300)
def test_a_bags_readings_need_no_kernel_but_those_warm_up_made():
    """The node and estimation_fuse load the kernels at start (warm_up); a reading whose
    arrays had other types (a bag reader's read-only buffers) would make numba compile a
    second version in the middle of a run, seconds on a fresh install."""
    params = str(FILES / "test_{kind}_localization_node_bag2.yaml")
    result = subprocess.run([sys.executable, "-c", COMPILED_DURING_A_RUN,
                             str(SHARED / "test2.bag"), params],
                            capture_output=True, text=True, timeout=280)
    assert result.returncode == 0, result.stderr
    assert "compiled during the run: []" in result.stdout, result.stdout
