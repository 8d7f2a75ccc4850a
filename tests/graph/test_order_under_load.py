"""On one host under CPU load, with a recorder beside the sensor: estimates as causal order gives.

Both cores are kept busy by two spinning processes while the localization
scenario runs; a recorder (tests/graph/record_run.py) that matches the sensor
before the estimator does may not let a reading out that the estimator
misses. estimation_replay then matches every estimate with the filter run
offline over the recorded inputs in the order they were published.
"""

from __future__ import annotations

import sys
import time

import pytest

from estimation_nodes.tools.demo.graph_runtime import stop_process
from tests.conftest import REPO, SCENARIOS
from tests.graph.graph_tools import node_command, scaled, wait_for_line
from tests.graph.test_two_hosts import compared, replayed

#: The recorder's node (tests/graph/record_run.py runs the demo's monitor).
RECORDER = "estimation_demo_monitor"
RECORDED = f"[estimator, {RECORDER}]"
RECORDED_AND_SENSOR = f"[estimator, tile_sensor, {RECORDER}]"
SPIN = "import time\nend = time.monotonic() + 120\nwhile time.monotonic() < end: pass\n"


@pytest.mark.timeout(240)
def test_seeded_run_under_cpu_load_equals_the_causal_filter(processes, tmp_path):
    scenario = SCENARIOS / "localization.yaml"
    hogs = [processes([sys.executable, "-c", SPIN]) for _ in range(2)]
    try:
        recording = tmp_path / "run.mcap"
        # The recorder first: it matches the sensor long before the estimator exists.
        started = time.monotonic()
        recorder = processes([sys.executable, "-m", "tests.graph.record_run", str(recording),
                              str(scenario), "40"], cwd=REPO)
        assert "recording" in recorder.stdout.readline()
        startup = time.monotonic() - started
        # The recorder must get every input too: the sensor and the commander wait for it
        # as they wait for the estimator.
        processes(node_command("tile_sensor", scenario, "-p", f"hold_for_nodes:={RECORDED}"))
        commander = processes(node_command(
            "motion_commander", scenario, "-p", "start_delay:=0.5", "-p",
            "exit_when_done:=true", "-p", "rate_hz:=10.0", "-p",
            f"required_nodes:={RECORDED_AND_SENSOR}"))
        estimator = processes(node_command("estimator", scenario,
                                           "-p", "history_depth:=1000"))
        assert commander.wait(timeout=120) == 0, commander.stdout.read()
        # Until every estimate has reached the recorder (a miss: the replay below says
        # which are missing).
        wait_for_line(recorder, "settled", scaled(startup))
    finally:
        for hog in hogs:
            stop_process(hog, grace=1.0)
    assert estimator.poll() is None, "the estimator died"
    stop_process(recorder, grace=10.0)
    output = replayed(recording)
    assert compared(output, "belief") == 40 and compared(output, "belief_predicted") == 40
