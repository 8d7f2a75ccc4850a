"""What the demo does so that its recording is complete, and how it says when one is not:
the nodes its monitor is added to, the outputs' depth, the sequence numbers' gaps."""

import pytest

from estimation_nodes.tools.demo.cli import report_recording
from estimation_nodes.tools.demo.overrides import (
    GRID_MONITOR,
    HISTORY_LIMIT,
    MONITOR,
    history_depth,
    largest_output_bytes,
    node_overrides,
)
from estimation_nodes.tools.recording.completeness import SequenceGaps
from tests.conftest import SCENARIOS
from tests.support import write_world


def gaps_of(numbers: dict[str, list]) -> SequenceGaps:
    gaps = SequenceGaps()
    for topic, sequence in numbers.items():
        for number in sequence:
            gaps.note(topic, number)
    return gaps


def test_numbers_missing_below_the_highest_are_reported_as_ranges():
    gaps = gaps_of({"/scan": [3, 4, 6, 9], "/odom": [1, 2, 3], "/pose": [None, None]})
    assert gaps.missing() == {"/scan": [(1, 2), (5, 5), (7, 8)]}
    assert gaps.describe() == ["/scan: 5 messages of 9 missing (sequence numbers 1-2, 5, 7-8)"]
    assert gaps.recorded == 7


def test_two_publishers_on_one_topic_never_make_a_gap_of_their_own():
    # MessageInfo does not say which publisher a number is from: each counts from 1.
    assert gaps_of({"/initialpose": [1, 2, 1, 2, 3]}).missing() == {}


def test_an_incomplete_recording_is_said_at_the_end_and_fails_the_run(capsys, tmp_path):
    path = tmp_path / "run.mcap"
    assert report_recording(path, gaps_of({"/scan": [2, 3]}), 0) == 1
    err = capsys.readouterr().err
    assert "misses messages that were published" in err
    assert "/scan: 1 message of 3 missing (sequence numbers 1)" in err
    assert report_recording(path, gaps_of({"/scan": [1, 2, 3]}), 0) == 0
    assert f"recorded to {path} (3 messages, none missing)" in capsys.readouterr().out


def overrides_of(scenario: str, kind: str, hears: bool = True, text: str = "") -> dict:
    return node_overrides((SCENARIOS / f"{scenario}.yaml").read_text() + text, kind, hears)


def test_the_monitor_joins_the_nodes_the_simulator_and_the_commander_wait_for():
    overrides = overrides_of("localization", "tiles")
    assert overrides["tile_sensor"] == ("-p", f"hold_for_nodes:=[estimator, {MONITOR}]")
    assert overrides["motion_commander"] == (
        "-p", f"required_nodes:=[estimator, tile_sensor, {MONITOR}]")
    matrix = overrides_of("tracking_2d", "linear_system")
    assert matrix["linear_system"] == ("-p", f"hold_for_nodes:=[estimator, {MONITOR}]")
    assert matrix["motion_commander"] == (
        "-p", f"required_nodes:=[estimator, linear_system, {MONITOR}]")


def test_the_robot_waits_for_the_monitor_only_when_it_records_or_serves_the_readings():
    assert overrides_of("grid_corridor", "grid")["planar_robot"] == (
        "-p", f"hold_for_nodes:=[grid_localizer, {GRID_MONITOR}]")
    assert "planar_robot" not in overrides_of("grid_corridor", "grid", hears=False)
    assert overrides_of("landmarks", "landmarks")["landmark_robot"] == (
        "-p", f"hold_for_nodes:=[ekf_localizer, {GRID_MONITOR}]")


def test_the_nodes_a_scenario_names_are_kept():
    text = ("/**/planar_robot:\n  ros__parameters:\n"
            "    hold_for_nodes: [grid_localizer, /elsewhere/recorder]\n")
    assert overrides_of("grid_corridor", "grid", text=text)["planar_robot"] == (
        "-p", f"hold_for_nodes:=[grid_localizer, /elsewhere/recorder, {GRID_MONITOR}]")


@pytest.mark.parametrize("message_bytes, given, depth", [
    (8_000_000, 1, 4),              # a belief of a million cells: bounded by bytes
    (8_000_000, 20, 20),            # never below what the scenario gives
    (400, 1, HISTORY_LIMIT),        # a pose: a whole run's worth
    (10**9, 1, 1),
])
def test_the_depth_is_bounded_by_bytes_and_never_lowered(message_bytes, given, depth):
    assert history_depth(message_bytes, given) == depth


def test_the_depth_follows_the_largest_output_of_each_kind(tmp_path):
    world = write_world(100_000, tmp_path)
    text = f"/**/estimator:\n  ros__parameters:\n    world_file: {world}\n"
    assert largest_output_bytes(text, "tiles") == 800_000
    overrides = node_overrides(text, "tiles", True)
    assert overrides["estimator"] == ("-p", "history_depth:=41")
    # The corridor's state grid: 16 m x 4 m at 0.1 m, a byte per cell of belief_map.
    corridor = (SCENARIOS / "grid_corridor.yaml").read_text()
    assert largest_output_bytes(corridor, "grid") == 160 * 40
    # A bad value leaves the depth alone: the node says what is wrong when it starts.
    assert "estimator" not in node_overrides(
        "/**/estimator:\n  ros__parameters:\n    world_file: /nonexistent\n", "tiles", True)
