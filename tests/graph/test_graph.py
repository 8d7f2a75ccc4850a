"""The real executables as subprocesses, found the way `ros2 run` finds them, observed here."""

import os
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from geometry_msgs.msg import PoseWithCovariance
from std_msgs.msg import Float64MultiArray, Int64, String

from estimation_nodes.core.tiles import histogram
from estimation_nodes.core.tiles.models import HistogramModel
from estimation_nodes.nodes.qos import INPUT_QOS
from tests.conftest import SCENARIOS, spin_until
from tests.graph.graph_tools import (
    beliefs,
    executable,
    settled,
    start_graph,
    wait_for_commander,
    wait_quiet,
)

EXECUTABLES = ("motion_commander", "tile_sensor", "linear_system", "estimator", "estimation_demo",
               "estimation_replay", "estimation_plot", "foxglove_view", "grid_localizer",
               "planar_robot")


def test_ros2_run_finds_every_executable():
    from ament_index_python.packages import get_package_prefix, get_package_share_directory

    prefix = Path(get_package_prefix("estimation_nodes"))
    for name in EXECUTABLES:
        path = prefix / "lib" / "estimation_nodes" / name
        assert path.is_file(), f"{path} missing"
        assert path.stat().st_mode & stat.S_IXUSR, f"{path} not executable"
    share = Path(get_package_share_directory("estimation_nodes"))
    from catkin_pkg.package import parse_package

    assert parse_package(str(share / "package.xml")).name == "estimation_nodes"
    assert {p.name for p in (share / "msgs_config").glob("*.yaml")} >= {
        "book_world.yaml", "example_6_14.yaml", "example_6_18.yaml", "grid_localization.yaml"}
    assert {p.name for p in (share / "maps").iterdir()} >= {
        "office.yaml", "office.pgm", "corridor.yaml", "corridor.pgm"}


def test_source_package_xml_parses():
    from catkin_pkg.package import parse_package

    package = parse_package(str(Path(__file__).resolve().parents[2] / "package.xml"))
    assert package.get_build_type() == "ament_python"


def test_example_6_14_end_to_end(processes, executor, collector_factory):
    seen = collector_factory({"belief_predicted": Float64MultiArray, "belief": Float64MultiArray})
    # Matched before the first command: the estimator keeps only its latest estimate for a
    # subscriber that comes later.
    started = start_graph(processes, SCENARIOS / "example_6_14.yaml",
                          listeners=(executor, seen))
    wait_for_commander(executor, started)
    assert spin_until(executor, lambda: seen.count("belief") >= 3, 20.0)
    wait_quiet(executor, seen)
    predicted = [[0.2] * 5, [0.2375, 0.25, 0.2375, 0.1375, 0.1375],
                 [0.1, 0.130714, 0.168571, 0.363571, 0.237143]]
    corrected = [[0.25, 0.25, 0.125, 0.125, 0.25],
                 [0.135714, 0.142857, 0.407143, 0.235714, 0.078571],
                 [0.048443, 0.063322, 0.244983, 0.528374, 0.114879]]
    settled(beliefs(seen.messages["belief_predicted"]), predicted, atol=1e-6)
    settled(beliefs(seen.messages["belief"]), corrected, atol=1e-6)


def test_example_6_18_end_to_end(processes, executor, collector_factory):
    seen = collector_factory({"kalman_estimate": PoseWithCovariance})
    started = start_graph(processes, SCENARIOS / "example_6_18.yaml",
                          listeners=(executor, seen))
    wait_for_commander(executor, started)
    assert spin_until(executor, lambda: seen.count("kalman_estimate") >= 5, 20.0)
    wait_quiet(executor, seen)
    got = [(m.pose.position.x, m.covariance[0]) for m in seen.messages["kalman_estimate"]]
    settled(got, list(zip(
        [2.113208, 5.045977, 7.021958, 8.010857, 9.005414],
        [3.849057, 2.375479, 2.089661, 2.022167, 2.005526])), atol=1e-6)


def test_seeded_random_run_localizes_and_matches_offline_filter(
        processes, executor, collector_factory):
    scenario = SCENARIOS / "localization.yaml"
    seen = collector_factory({"belief": Float64MultiArray, "true_position": Int64,
                              "tile_observation": (String, INPUT_QOS)})
    started = start_graph(processes, scenario, "-p", "rate_hz:=20.0",
                          listeners=(executor, seen))
    wait_for_commander(executor, started)
    steps = yaml.safe_load(scenario.read_text())["/**/motion_commander"]["ros__parameters"][
        "max_commands"]
    # Every topic the checks read, complete: a reader matched late gets its first
    # samples by reliable repair, seconds after the later ones (seen under CPU load).
    assert spin_until(executor, lambda: all(
        seen.count(topic) >= steps for topic in ("belief", "true_position", "tile_observation")),
        20.0)
    wait_quiet(executor, seen)
    # The graph computed exactly what the core computes over the same observations, in
    # the order they happened.
    params = yaml.safe_load(scenario.read_text())["/**/estimator"]["ros__parameters"]
    model = HistogramModel.from_lists(params["world"], params["classes"],
                                      params["sensor_model"], params["motion_kernel"])
    belief, offline = histogram.uniform(model.size), []
    for msg in seen.messages["tile_observation"]:
        belief = histogram.predict(belief, 1, model.kernel)
        belief, _ = histogram.correct(belief, model.likelihood(msg.data))
        offline.append(belief)
    online = settled(beliefs(seen.messages["belief"]), offline, atol=1e-12)
    truth = [m.data for m in seen.messages["true_position"]]
    hits = [int(np.argmax(b)) == t % b.size for b, t in zip(online, truth)]
    converged = hits[10:]
    print(f"most likely cell == true cell in {sum(converged)} of {len(converged)} steps "
          f"after step 10 ({sum(hits)} of {len(hits)} in all)")
    assert sum(converged) / len(converged) >= 0.7


def test_bad_parameter_at_start_up_exits_2_with_one_clear_line(ros_env):
    result = subprocess.run(
        [executable("estimator"), "--ros-args", "-p", "motion_kernel:=[0.5, 0.5]"],
        env=ros_env, capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    lines = [line for line in (result.stdout + result.stderr).splitlines() if line.strip()]
    assert len(lines) == 1, lines
    assert "motion_kernel" in lines[0] and "odd number" in lines[0] and "[0.5 0.5]" in lines[0]


def test_demo_runs_a_scenario_and_exits_0(ros_env):
    result = subprocess.run(
        [executable("estimation_demo"), "--scenario", "example_6_14", "--settle", "0.5",
         "--linger", "0.5"], env=ros_env, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "0.048443 0.063322 0.244983 0.528374 0.114879" in result.stdout
    assert "final belief: most likely cell 3" in result.stdout


def test_the_default_run_localizes_and_names_the_book_s_scenarios(ros_env):
    result = subprocess.run([executable("estimation_demo"), "--settle", "0.5", "--linger",
                             "0.5", "--quiet"], env=ros_env, capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "localization.yaml" in result.stdout
    hits = int(result.stdout.split("most likely cell == true cell in ")[1].split()[0])
    assert hits >= 30, result.stdout   # 36 of 40 seeded; the book's world gives 5 of 30
    assert "other scenarios: book_world, example_6_14, example_6_18" in result.stdout


def test_a_node_that_cannot_start_ends_the_demo_at_once(ros_env, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("/**/estimator:\n  ros__parameters:\n    kalman:\n      var_u: -1.0\n")
    # At once, not after --timeout (which would end it with 1, "--timeout reached"):
    # the run ends when a node does.
    result = subprocess.run([executable("estimation_demo"), "--params-file", str(bad),
                             "--timeout", "3600"], env=ros_env, capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 2, result.stdout + result.stderr
    assert "kalman.var_u" in result.stderr and "Traceback" not in result.stderr


def test_demo_in_process_reproduces_example_6_18(ros_env):
    result = subprocess.run(
        [executable("estimation_demo"), "--scenario", "example_6_18", "--in-process",
         "--settle", "0.2", "--linger", "0.2"], env=ros_env, capture_output=True, text=True,
        timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "final Kalman estimate 9.005414 +- 1.416166" in result.stdout


@pytest.mark.parametrize("bad, message", [
    ("missing.yaml", "is not a file"),
    ("broken.yaml", "is not valid YAML"),
])
def test_demo_rejects_bad_params_file(ros_env, tmp_path, bad, message):
    (tmp_path / "broken.yaml").write_text("/estimator: {ros__parameters: [unclosed\n")
    result = subprocess.run([executable("estimation_demo"), "--params-file",
                             str(tmp_path / bad)], env=ros_env, capture_output=True,
                            text=True, timeout=60)
    assert result.returncode == 2
    assert message in result.stderr and "Traceback" not in result.stderr


def children_of(pid: int) -> list[int]:
    path = Path(f"/proc/{pid}/task/{pid}/children")
    return [int(p) for p in path.read_text().split()] if path.exists() else []


def running(pid: int) -> bool:
    """The process exists and is not a zombie waiting to be reaped."""
    stat = Path(f"/proc/{pid}/stat")
    return stat.exists() and stat.read_text().rsplit(")", 1)[1].split()[0] != "Z"


def start_demo(ros_env, *args, **popen_args) -> tuple[subprocess.Popen, list[int]]:
    """The demo as a process, once its three nodes are running: (demo, node pids)."""
    demo = subprocess.Popen([sys.executable, "-m", "estimation_nodes.tools.demo.cli", *args],
                            env=ros_env, **popen_args)
    deadline = time.monotonic() + 30
    while len(children_of(demo.pid)) < 3 and time.monotonic() < deadline:
        time.sleep(0.1)
    return demo, children_of(demo.pid)


def test_demo_ctrl_c_leaves_no_process_behind(ros_env, domain_id):
    demo, children = start_demo(ros_env, "--scenario", "book_world", "--settle", "0.5",
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        assert len(children) == 3
        demo.send_signal(signal.SIGINT)
        output, _ = demo.communicate(timeout=30)
        assert demo.returncode == 130, output
        assert "summary:" in output
        assert not [child for child in children if running(child)]
    finally:
        if demo.poll() is None:
            demo.kill()
            demo.wait()


def test_nodes_end_when_the_demo_is_killed(ros_env):
    # SIGKILL gives the demo no chance to stop its children: they must end on their
    # own rather than run on, publishing into whatever next uses the domain.
    demo, children = start_demo(ros_env, "--scenario", "localization", "--settle", "0.5",
                                "--quiet", stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    demo.kill()
    demo.wait()
    assert len(children) == 3
    deadline = time.monotonic() + 20
    alive = children
    while alive and time.monotonic() < deadline:
        time.sleep(0.1)
        alive = [pid for pid in children if running(pid)]
    for pid in alive:   # end what the failure left behind, by pid
        os.kill(pid, signal.SIGKILL)
    assert not alive, f"orphaned nodes still running: {alive}"


def test_ros_processes_confined_to_localhost_by_demo(ros_env):
    env = {k: v for k, v in ros_env.items() if k != "ROS_AUTOMATIC_DISCOVERY_RANGE"}
    result = subprocess.run(
        [executable("estimation_demo"), "--scenario", "example_6_14", "--in-process",
         "--settle", "0.1", "--linger", "0.1", "--quiet"], env=env, capture_output=True,
        text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert "ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST" in result.stdout


def test_two_robots_in_namespaces_do_not_mix(processes, executor, collector_factory):
    from tests.graph.graph_tools import SETTLE, node_command

    seen = collector_factory({"/robot1/belief": Float64MultiArray,
                              "/robot2/belief": Float64MultiArray,
                              "/belief": Float64MultiArray})
    commanders = []
    for robot, scenario in (("robot1", "example_6_14.yaml"), ("robot2", "localization.yaml")):
        for name in ("estimator", "tile_sensor", "motion_commander"):
            extra = ["-r", f"__ns:=/{robot}"]
            if name == "motion_commander":
                extra += ["-p", f"start_delay:={SETTLE}", "-p", "exit_when_done:=true",
                          "-p", "max_commands:=3", "-p", "rate_hz:=5.0"]
            process = processes(node_command(name, SCENARIOS / scenario, *extra))
            if name == "motion_commander":
                commanders.append(process)
    for commander in commanders:
        wait_for_commander(executor, {"motion_commander": commander})
    assert spin_until(executor, lambda: seen.count("/robot1/belief") >= 3
                      and seen.count("/robot2/belief") >= 3, 20.0)
    wait_quiet(executor, seen)
    assert seen.count("/belief") == 0
    assert {len(m.data) for m in seen.messages["/robot1/belief"]} == {5}
    assert {len(m.data) for m in seen.messages["/robot2/belief"]} == {20}
    np.testing.assert_allclose(beliefs(seen.messages["/robot1/belief"])[-1],
                               [0.048443, 0.063322, 0.244983, 0.528374, 0.114879], atol=1e-6)


@pytest.mark.parametrize("name, message", [
    ("../../etc/hosts", "is not a scenario name"),
    ("no_such_scenario", "known scenarios: ['book_world', 'example_6_14'"),
])
def test_demo_rejects_bad_scenario_names(ros_env, name, message):
    result = subprocess.run([executable("estimation_demo"), "--scenario", name], env=ros_env,
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and message in result.stderr, result.stderr
