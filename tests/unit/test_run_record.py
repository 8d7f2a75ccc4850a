"""The run record pairs each step's truth with the estimate that settled it, by stamps.

The estimator republishes an estimate when an input arrives late, so the lists
in arrival order can hold more estimates than steps; pairing by position then
compares every later estimate with the wrong truth (seen: a localizing run
summarized as 4 of 40 steps right).
"""

import numpy as np

from estimation_nodes.params import topics
from estimation_nodes.tools.recording.run_record import RunRecord, summarize


def one_hot(cell: int, size: int = 5) -> np.ndarray:
    belief = np.full(size, 0.01)
    belief[cell] = 1.0 - 0.01 * (size - 1)
    return belief


def add(record: RunRecord, topic: str, values: list, value, stamp: int) -> None:
    values.append(value)
    record.stamp(topic, stamp)


def localizing_run_with_a_republication() -> RunRecord:
    """Three steps, truth cells 1, 2, 3, stamps 100 ns apart. The correction of step
    2 is published twice: first wrongly (its command had not arrived), then settled."""
    record = RunRecord()
    for step, cell in enumerate([1, 2, 3]):
        start = 1000 + 100 * step
        add(record, topics.TRUE_POSITION, record.truth, cell, start)
        if step == 1:
            add(record, topics.BELIEF, record.corrected, one_hot(4), start + 10)
            add(record, topics.BELIEF_PREDICTED, record.predicted, one_hot(cell), start + 20)
        else:
            add(record, topics.BELIEF_PREDICTED, record.predicted, one_hot(cell), start - 5)
        add(record, topics.BELIEF, record.corrected, one_hot(cell), start + 30)
        add(record, topics.KALMAN_ESTIMATE, record.kalman, (cell + 0.5, 1.0), start + 40)
    return record


def test_each_step_takes_the_last_estimate_published_before_the_next_truth():
    record = localizing_run_with_a_republication()
    assert len(record.corrected) == 4
    assert record.per_step(topics.BELIEF) == {0: 0, 1: 2, 2: 3}
    assert record.per_step(topics.KALMAN_ESTIMATE) == {0: 0, 1: 1, 2: 2}


def test_the_summary_counts_every_step_right_despite_the_republication():
    text = summarize(localizing_run_with_a_republication())
    assert "most likely cell == true cell in 3 of 3 steps" in text
    assert "Kalman RMS error 0.500000 cells over 3 steps" in text


def test_a_correction_is_shown_with_the_prediction_published_before_it():
    record = localizing_run_with_a_republication()
    # Step 2's settled correction (index 2) came after the prediction republished with it.
    assert record.prediction_before(topics.BELIEF, 2, topics.BELIEF_PREDICTED) == 1
    # Step 1's prediction was published before its truth: still the one before its correction.
    assert record.prediction_before(topics.BELIEF, 0, topics.BELIEF_PREDICTED) == 0


def test_an_estimate_before_the_first_truth_belongs_to_no_step():
    record = localizing_run_with_a_republication()
    record.corrected.insert(0, one_hot(0))
    record.stamps[topics.BELIEF].insert(0, 500)
    assert record.per_step(topics.BELIEF) == {0: 1, 1: 3, 2: 4}


def test_a_record_without_stamps_is_paired_by_position():
    record = RunRecord(truth=[1, 2], corrected=[one_hot(1), one_hot(3), one_hot(2)])
    assert record.per_step(topics.BELIEF) == {0: 0, 1: 1}
    assert "most likely cell == true cell in 1 of 2 steps" in summarize(record)


def test_a_tracking_run_counts_steps_by_its_true_states():
    record = RunRecord()
    for step in range(3):
        start = 1000 + 100 * step
        add(record, topics.TRUE_STATE, record.true_states, np.array([step, 0.0]), start)
        for late in (0, 1) if step == 2 else (0,):   # step 3's estimate republished
            state = np.array([step + 0.1 + 5.0 * (late == 0 and step == 2), 0.0])
            add(record, topics.KALMAN_STATE, record.states, (state, np.eye(2)),
                start + 10 + late)
    assert record.per_step(topics.KALMAN_STATE) == {0: 0, 1: 1, 2: 3}
    assert "RMS error per state component over 3 steps: [0.1 0. ]" in summarize(record)
