"""What one run of the graph produced, topic by topic, in arrival order (no rclpy here).

The demo's monitor fills one live; a recording is read back into one; the
plot and the offline replay work from one.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from estimation_nodes.core.models import FloatArray
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
        steps = min(len(record.corrected), len(record.truth))
        if steps:
            hits = [int(np.argmax(record.corrected[i])) == record.truth[i] % final.size
                    for i in range(steps)]
            lines.append(f"  most likely cell == true cell in {sum(hits)} of {steps} steps")
    if record.kalman and not record.true_states:
        x, var = record.kalman[-1]
        lines.append(f"  final Kalman estimate {x:.6f} +- {np.sqrt(var):.6f} (1 std)")
        steps = min(len(record.kalman), len(record.truth))
        if steps:
            errors = [record.kalman[i][0] - record.truth[i] for i in range(steps)]
            lines.append(f"  Kalman RMS error {np.sqrt(np.mean(np.square(errors))):.6f} cells "
                         f"over {steps} steps")
    if record.states and record.true_states:
        steps = min(len(record.states), len(record.true_states))
        errors = [record.states[i][0] - record.true_states[i] for i in range(steps)]
        rms = np.sqrt(np.mean(np.square(errors), axis=0))
        lines.append(f"  Kalman corrections {len(record.states)}; final state "
                     f"{np.array2string(record.states[-1][0], precision=4)}")
        lines.append(f"  RMS error per state component over {steps} steps: "
                     f"{np.array2string(rms, precision=4)}")
    return "\n".join(lines)
