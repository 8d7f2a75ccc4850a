"""What one run of the graph produced, topic by topic, in arrival order (no rclpy here).

The demo's monitor fills one live; a recording is read back into one; the
plot and the offline replay work from one.
"""

from __future__ import annotations

from bisect import bisect_right
from dataclasses import dataclass, field

import numpy as np

from estimation_nodes.core.validation import FloatArray
from estimation_nodes.params import topics


@dataclass
class RunRecord:
    """Every message of a run, one list per topic, each in arrival order."""

    commands: list[int] = field(default_factory=list)
    observations: list[str] = field(default_factory=list)
    measurements: list[float] = field(default_factory=list)
    truth: list[int] = field(default_factory=list)
    predicted: list[FloatArray] = field(default_factory=list)
    corrected: list[FloatArray] = field(default_factory=list)
    kalman: list[tuple[float, float]] = field(default_factory=list)
    kalman_predicted: list[tuple[float, float]] = field(default_factory=list)
    #: The matrix filter's full state (x, P) after each correction and each prediction.
    states: list[tuple[FloatArray, FloatArray]] = field(default_factory=list)
    states_predicted: list[tuple[FloatArray, FloatArray]] = field(default_factory=list)
    kalman_inputs: list[tuple[float, ...]] = field(default_factory=list)
    kalman_measurements: list[tuple[float, ...]] = field(default_factory=list)
    true_states: list[FloatArray] = field(default_factory=list)
    #: Input events in the order they were recorded: ("motion_cmd", u), ("tile_observation",
    #: class), ("position_measurement", z), ("kalman_input", u) or ("kalman_measurement", z)
    #: (vectors as tuples).
    events: list[tuple[str, object]] = field(default_factory=list)
    #: Source timestamps (ns) of each topic's messages, in the order of its list above;
    #: a topic without them (a record built by hand) is paired by position.
    stamps: dict[str, list[int]] = field(default_factory=dict)

    def stamp(self, topic: str, source_ns: int) -> None:
        """Keep the source timestamp of the message just added to ``topic``'s list."""
        self.stamps.setdefault(topic, []).append(source_ns)

    def add_event(self, topic: str, value: object) -> None:
        """Keep an input both in its topic's list and in the common event order."""
        {topics.MOTION_CMD: self.commands, topics.TILE_OBSERVATION: self.observations,
         topics.POSITION_MEASUREMENT: self.measurements, topics.KALMAN_INPUT: self.kalman_inputs,
         topics.KALMAN_MEASUREMENT: self.kalman_measurements}[topic].append(value)
        self.events.append((topic, value))

    @property
    def cells(self) -> int:
        """Size of the world, from the beliefs (0 when there are none)."""
        beliefs = self.corrected or self.predicted
        return int(beliefs[0].size) if beliefs else 0

    def per_step(self, topic: str) -> dict[int, int]:
        """Step -> index in ``topic``'s list of the estimate that settled that step.

        A step is one true position (or true state) of the simulator, published
        just before the reading it causes. Its estimate is the last one on
        ``topic`` published after it and before the next step's truth. The n-th
        estimate is not always the n-th step's: the estimator republishes an
        estimate when an input arrives late, so the source timestamps decide.
        """
        values = getattr(self, OUTPUT_LISTS[topic])
        truth_topic = topics.TRUE_STATE if self.true_states else topics.TRUE_POSITION
        steps = len(self.true_states or self.truth)
        value_stamps, step_stamps = self.stamps.get(topic, []), self.stamps.get(truth_topic, [])
        if len(value_stamps) != len(values) or len(step_stamps) != steps:
            return {index: index for index in range(min(len(values), steps))}
        settled = {}
        for index, stamp in enumerate(value_stamps):
            step = bisect_right(step_stamps, stamp) - 1
            if step >= 0:   # one published before the first truth is no step's
                settled[step] = index
        return settled

    def prediction_before(self, topic: str, index: int, predicted_topic: str) -> int | None:
        """Index of the last prediction on ``predicted_topic`` published before the
        estimate ``index`` of ``topic``: the prediction that correction started from."""
        stamps = self.stamps.get(predicted_topic, [])
        predicted = getattr(self, OUTPUT_LISTS[predicted_topic])
        if len(stamps) != len(predicted) or len(self.stamps.get(topic, [])) <= index:
            return index if index < len(predicted) else None
        before = bisect_right(stamps, self.stamps[topic][index]) - 1
        return before if before >= 0 else None


#: The RunRecord list that holds each estimator output.
OUTPUT_LISTS = {topics.BELIEF: "corrected", topics.BELIEF_PREDICTED: "predicted",
                topics.KALMAN_ESTIMATE: "kalman", topics.KALMAN_STATE: "states",
                topics.KALMAN_STATE_PREDICTED: "states_predicted"}


def summarize(record: RunRecord) -> str:
    """A few lines a person reads at a glance: counts, final estimates, how often right."""
    lines = ["", "summary:"]
    if record.predicted or record.corrected or not record.states:
        lines.append(f"  predictions {len(record.predicted)}, histogram corrections "
                     f"{len(record.corrected)}, Kalman corrections {len(record.kalman)}")
    if record.corrected:
        final = record.corrected[-1]
        lines.append(f"  final belief: most likely cell {int(np.argmax(final))} "
                     f"(p = {final.max():.6f})")
        settled = record.per_step(topics.BELIEF)
        if settled:
            hits = [int(np.argmax(record.corrected[index])) == record.truth[step] % final.size
                    for step, index in settled.items()]
            lines.append(f"  most likely cell == true cell in {sum(hits)} of {len(hits)} steps")
    if record.kalman and not record.true_states:
        x, var = record.kalman[-1]
        lines.append(f"  final Kalman estimate {x:.6f} +- {np.sqrt(var):.6f} (1 std)")
        settled = record.per_step(topics.KALMAN_ESTIMATE)
        if settled:
            errors = [record.kalman[index][0] - record.truth[step]
                      for step, index in settled.items()]
            lines.append(f"  Kalman RMS error {np.sqrt(np.mean(np.square(errors))):.6f} cells "
                         f"over {len(errors)} steps")
    if record.states and record.true_states:
        settled = record.per_step(topics.KALMAN_STATE)
        lines.append(f"  Kalman corrections {len(record.states)}; final state "
                     f"{np.array2string(record.states[-1][0], precision=4)}")
        if settled:
            errors = [record.states[index][0] - record.true_states[step]
                      for step, index in settled.items()]
            rms = np.sqrt(np.mean(np.square(errors), axis=0))
            lines.append(f"  RMS error per state component over {len(errors)} steps: "
                         f"{np.array2string(rms, precision=4)}")
    return "\n".join(lines)
