"""How the demo says that its recording is not complete: the sequence numbers' gaps."""

from estimation_nodes.tools.demo.cli import report_recording
from estimation_nodes.tools.recording.completeness import SequenceGaps


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
