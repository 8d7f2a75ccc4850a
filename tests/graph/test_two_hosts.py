"""The graph across two hosts, calm and through a 5 s partition: estimates as causal order gives.

The estimator runs on host a; the tile sensor, the commander and a recorder
(an observer beside the sensor, as in the field) on host b (tests/graph/
hosts.py). The recorder's MCAP file holds what the sensor and commander sent
and what the estimator published; ``estimation_replay`` then runs the filter
offline over those inputs in the order they were published and matches every
estimate. Skipped where this process cannot make network namespaces.
"""

from __future__ import annotations

import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from estimation_nodes.tools.demo.graph_runtime import stop_process
from estimation_nodes.tools.recording.mcap import read_recording
from tests.conftest import REPO, SCENARIOS
from tests.graph import hosts
from tests.graph.graph_tools import executable, node_command, scaled, wait_for_line

pytestmark = pytest.mark.skipif(hosts.available() is not None,
                                reason=str(hosts.available()))

#: The recorder's node (tests/graph/record_run.py runs the demo's monitor).
RECORDER = "estimation_demo_monitor"
RECORDED = f"[estimator, {RECORDER}]"
RECORDED_AND_SENSOR = f"[estimator, tile_sensor, {RECORDER}]"
BOOK_FINAL_BELIEF = [0.048443, 0.063322, 0.244983, 0.528374, 0.114879]
#: The outputs keep a history deep enough for a remote subscriber to get every estimate
#: sent while the link is down (the default, 1, hands it the latest only).
ESTIMATOR_ARGS = ("-p", "history_depth:=1000")


@pytest.fixture
def two_hosts(domain_id):
    pair = hosts.TwoHosts(tag=domain_id % 250)
    pair.remove()            # what a killed run may have left
    try:
        pair.create()
    except subprocess.CalledProcessError as error:
        pair.remove()
        pytest.skip(f"cannot create network namespaces here: {error.stderr.strip()}")
    yield pair
    pair.remove()


def start_run(processes, ros_env, pair, scenario: Path, tmp_path: Path, steps: int,
              *commander_args, static_peers: bool = False):
    """Estimator on a; recorder, sensor and commander on b, ``steps`` commands. Returns
    (commander, recorder, recording path, estimator)."""

    def on(host, command):
        env = pair.environment(ros_env, static_peer_of=host if static_peers else None)
        return processes(pair.command(host, command), env=env, cwd=REPO)

    estimator = on("a", node_command("estimator", scenario, *ESTIMATOR_ARGS))
    recording = tmp_path / "run.mcap"
    recorder = on("b", [sys.executable, "-m", "tests.graph.record_run", str(recording),
                        str(scenario), str(steps)])
    assert "recording" in recorder.stdout.readline()
    # The recorder must get every input too: the sensor and the commander wait for it as
    # they wait for the estimator.
    on("b", node_command("tile_sensor", scenario, "-p", f"hold_for_nodes:={RECORDED}"))
    commander = on("b", node_command(
        "motion_commander", scenario, "-p", "start_delay:=1.0", "-p", "exit_when_done:=true",
        "-p", f"required_nodes:={RECORDED_AND_SENSOR}", *commander_args))
    return commander, recorder, recording, estimator


def wait_until_sending(commander: subprocess.Popen, timeout: float = 120.0) -> float:
    """Read the commander's log until it starts sending; the time it did."""
    deadline = time.monotonic() + timeout
    for line in commander.stdout:
        if "sending at" in line:
            return time.monotonic()
        assert time.monotonic() < deadline, "the commander did not start"
    raise AssertionError("the commander ended before sending")


def finish(commander, recorder, estimator, startup: float) -> None:
    """Once the commander is done and the recorder has every estimate (record_run's
    "settled"; a miss: the replay says which are missing), stop the recorder.

    After a partition the estimator answers the backlog with hundreds of estimates per
    topic at once; on a loaded machine some reach the recorder only after DDS has
    repaired what the receiving socket dropped, a heartbeat period (3 s) at a time: a
    minute was seen. Reliable delivery is promised, its time is not; the wait is long.
    """
    assert commander.wait(timeout=120) == 0, commander.stdout.read()
    wait_for_line(recorder, "settled", scaled(startup, factor=20.0, floor=120.0))
    assert estimator.poll() is None, "the estimator died"
    stop_process(recorder, grace=10.0)


def replayed(recording: Path, estimator: subprocess.Popen | None = None) -> str:
    """estimation_replay over the recording; its output, asserting it found them equal. On a
    difference the estimator (if given) is stopped and its log shown too: its warnings say
    what it rejected, lost or applied out of order."""
    replay = subprocess.run([executable("estimation_replay"), str(recording)],
                            capture_output=True, text=True, timeout=120, cwd=REPO)
    print(replay.stdout)
    if replay.returncode != 0 and estimator is not None:
        stop_process(estimator, grace=10.0)
        print("the estimator's log:\n" + estimator.stdout.read())
    assert replay.returncode == 0, replay.stdout + replay.stderr
    assert "EQUAL" in replay.stdout
    return replay.stdout


def compared(output: str, topic: str) -> int:
    return int(re.search(rf"^{topic}: (\d+) estimates compared", output, re.M).group(1))


@pytest.mark.timeout(240)
@pytest.mark.parametrize("static_peers", [False, True], ids=["multicast", "static_peers"])
def test_example_6_14_across_two_hosts_is_the_book(two_hosts, processes, ros_env, tmp_path,
                                                   static_peers):
    """With multicast discovery, and with ROS_STATIC_PEERS and no multicast route at all."""
    if static_peers:
        two_hosts.multicast = False
        for host in ("a", "b"):
            subprocess.run(["ip", "-n", two_hosts.names[host], "route", "del",
                            hosts.MULTICAST], capture_output=True, check=False)
    began = time.monotonic()
    commander, recorder, recording, estimator = start_run(
        processes, ros_env, two_hosts, SCENARIOS / "example_6_14.yaml", tmp_path, 3,
        static_peers=static_peers)
    finish(commander, recorder, estimator, wait_until_sending(commander) - began)
    output = replayed(recording)
    assert compared(output, "belief") == 3
    run = read_recording(recording).record
    assert [round(v, 6) for v in run.corrected[-1]] == BOOK_FINAL_BELIEF


@pytest.mark.timeout(360)
@pytest.mark.parametrize("outage", [0.0, 5.0, 5.0], ids=["calm", "partition", "partition2"])
def test_seeded_run_across_hosts_equals_the_causal_filter(two_hosts, processes, ros_env,
                                                          tmp_path, outage):
    """The localization scenario at 4 Hz, its link cut for ``outage`` s 3 s into the run."""
    began = time.monotonic()
    commander, recorder, recording, estimator = start_run(
        processes, ros_env, two_hosts, SCENARIOS / "localization.yaml", tmp_path, 40)
    started = wait_until_sending(commander)
    if outage:
        time.sleep(max(0.0, started + 3.0 - time.monotonic()))
        two_hosts.cut()
        cut_ns = time.time_ns()
        time.sleep(outage)
        two_hosts.heal()
        healed_ns = time.time_ns()
    finish(commander, recorder, estimator, started - began)
    output = replayed(recording, estimator)
    # Every reading the sensor sent was applied: 40 corrections, all equal to the filter
    # run offline in the order the events happened.
    assert compared(output, "belief") == 40 and compared(output, "belief_predicted") == 40
    if outage:
        report_recovery(recording, cut_ns, healed_ns)


def report_recovery(recording: Path, cut_ns: int, healed_ns: int) -> None:
    """Print what the partition held back and how soon the estimator answered once healed."""
    from mcap.reader import make_reader

    with recording.open("rb") as stream:
        messages = [(c.topic, m.publish_time, m.log_time) for _, c, m in
                    make_reader(stream).iter_messages(topics=["/belief", "/tile_observation"])]
    sent_while_cut = [p for t, p, _ in messages if t == "/tile_observation"
                      and cut_ns <= p < healed_ns]
    answered = [r for t, _, r in messages if t == "/belief" and r > healed_ns]
    print(f"partition {(healed_ns - cut_ns) / 1e9:.1f} s: {len(sent_while_cut)} readings sent "
          f"while cut; first estimate {(min(answered) - healed_ns) / 1e9:.2f} s after healing")
