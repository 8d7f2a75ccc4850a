"""estimation_replay: run the filters offline over a recording and compare with what was published.

    estimation_replay RUN.mcap [--params-file FILE] [--tolerance 1e-9]

The recording's inputs (motion_cmd, tile_observation, position_measurement,
in the order they were published) go through the same filters the estimator uses, built from
the parameters stored in the recording (or a file you give). Each offline
estimate is compared with the estimate recorded online, in order, topic by
topic. Exit 0 when all agree to the tolerance, 1 otherwise, with each
differing step shown; 2 when the recording cannot be read.

Events of different topics reach the estimator in no guaranteed order, and
it handles them as they arrive, so a run under heavy load can differ where
a command reached it after the observation it caused; at the demo's rates
they do not.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from estimation_nodes.core.filter_state import HistogramFilter, KalmanFilter
from estimation_nodes.params import topics
from estimation_nodes.params.builders import build_estimator_settings
from estimation_nodes.params.files import check_params_file, read_node_parameters
from estimation_nodes.params.specs import ESTIMATOR_SPECS, spec_defaults
from estimation_nodes.params.wording import plural
from estimation_nodes.tools.recording import Recording, RecordingError, read_recording


@dataclass
class Comparison:
    """Offline against online, per output topic."""

    compared: dict[str, int] = field(default_factory=dict)
    differences: list[str] = field(default_factory=list)
    worst: dict[str, float] = field(default_factory=dict)

    @property
    def equal(self) -> bool:
        return not self.differences

    def check(self, topic: str, index: int, online, offline, tolerance: float) -> None:
        self.compared[topic] = self.compared.get(topic, 0) + 1
        if online is None:
            self.differences.append(f"{topic} #{index + 1}: computed offline, not recorded")
            return
        online, offline = np.asarray(online, float), np.asarray(offline, float)
        error = float(np.max(np.abs(online - offline))) if online.shape == offline.shape \
            else float("inf")
        self.worst[topic] = max(self.worst.get(topic, 0.0), error)
        if not error <= tolerance:
            self.differences.append(
                f"{topic} #{index + 1}: |online - offline| = {error:.3g}\n"
                f"    online  {np.array2string(online, precision=9, threshold=12)}\n"
                f"    offline {np.array2string(offline, precision=9, threshold=12)}")


def estimator_values(parameters_yaml: str, node: str = "/estimator") -> dict:
    """The values the estimator named ``node`` (fully qualified) gets: its defaults, then
    every section of the file that applies to it, as rcl applies them."""
    values = spec_defaults(ESTIMATOR_SPECS)
    values.update(read_node_parameters(parameters_yaml, node))
    return values


def estimator_name(recording: Recording) -> str:
    """The recorded estimator's fully qualified name, from the namespace of its belief topic."""
    for topic in recording.counts:
        namespace, _, base = topic.rpartition("/")
        if base == topics.BELIEF:
            return f"{namespace}/estimator"
    return "/estimator"


def _at(sequence: list, index: int):
    return sequence[index] if index < len(sequence) else None


def replay(recording: Recording, parameters_yaml: str, tolerance: float) -> Comparison:
    """Run the filters over the recorded inputs; compare every estimate with the recorded one."""
    values = estimator_values(parameters_yaml, estimator_name(recording))
    settings = build_estimator_settings(values)
    # The same code path as the recorded estimator: both are exact only to rounding.
    belief = HistogramFilter(
        settings.histogram, settings.initial_belief, values["compiled_kernels"])
    kalman = KalmanFilter(settings.kalman.initial, settings.kalman.model)
    run = recording.record
    comparison = Comparison()
    recorded = {
        topics.BELIEF_PREDICTED: run.predicted,
        topics.BELIEF: run.corrected,
        topics.KALMAN_ESTIMATE_PREDICTED: run.kalman_predicted,
        topics.KALMAN_ESTIMATE: run.kalman,
        topics.KALMAN_STATE_PREDICTED: [_flat(*state) for state in run.states_predicted],
        topics.KALMAN_STATE: [_flat(*state) for state in run.states],
    }
    counts = {output: 0 for output in recorded}
    # The component kalman_estimate shows as its x (the 1-D filter's position).
    shown = settings.kalman.pose_components[0]

    def check(output: str, offline) -> None:
        index = counts[output]
        counts[output] += 1
        comparison.check(output, index, _at(recorded[output], index), offline, tolerance)

    def kalman_step(predicted: bool, value) -> None:
        # As the estimator: a step it rejected published nothing, so nothing to compare.
        try:
            (kalman.predict if predicted else kalman.correct)(value)
        except ValueError:
            return
        suffix = "_predicted" if predicted else ""
        # The pose's x and its variance, as the estimator fills them (0 for no component).
        pose = (kalman.x[shown], kalman.P[shown, shown]) if shown >= 0 else (0.0, 0.0)
        check(topics.KALMAN_ESTIMATE + suffix, pose)
        check(topics.KALMAN_STATE + suffix, _flat(kalman.x, kalman.P))

    for topic, value in run.events:
        if topic == topics.MOTION_CMD:
            belief.predict(value)
            check(topics.BELIEF_PREDICTED, belief.belief)
            if kalman.input_size == 1:
                kalman_step(True, float(value))
        elif topic == topics.TILE_OBSERVATION:
            try:
                belief.correct(value)
            except ValueError:
                continue
            check(topics.BELIEF, belief.belief)
        elif topic in (topics.KALMAN_INPUT, topics.KALMAN_MEASUREMENT):
            # Subscribed in matrix mode only, as the estimator does.
            if settings.kalman.mode == "matrix":
                kalman_step(topic == topics.KALMAN_INPUT, value)
        else:
            kalman_step(False, value)
    for output, online in recorded.items():
        for index in range(counts[output], len(online)):
            comparison.differences.append(
                f"{output} #{index + 1}: recorded online, no input to compute it offline")
    return comparison


def _flat(x: np.ndarray, P: np.ndarray) -> np.ndarray:
    return np.concatenate([np.asarray(x, float), np.asarray(P, float).ravel()])


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="estimation_replay",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("recording", type=Path)
    parser.add_argument("--params-file", type=Path,
                        help="estimator parameters (default: those stored in the recording)")
    parser.add_argument("--tolerance", type=float, default=1e-9)
    args = parser.parse_args(argv)
    try:
        recording = read_recording(args.recording)
        if args.params_file:
            parameters_yaml = check_params_file(args.params_file).read_text(encoding="utf-8")
        else:
            parameters_yaml = recording.metadata.get("parameters_yaml", "")
        comparison = replay(recording, parameters_yaml, args.tolerance)
    except (RecordingError, ValueError) as error:
        print(f"estimation_replay: {error}", file=sys.stderr)
        sys.exit(2)
    for topic, count in sorted(recording.counts.items()):
        print(f"  {topic}: {plural(count, 'message')}")
    for topic, count in comparison.compared.items():
        print(f"{topic}: {count} estimates compared, largest difference "
              f"{comparison.worst.get(topic, float('nan')):.3g}")
    for line in comparison.differences:
        print(line)
    verdict = "EQUAL" if comparison.equal else f"DIFFERENT ({len(comparison.differences)})"
    print(f"online vs offline to {args.tolerance:g}: {verdict}")
    sys.exit(0 if comparison.equal else 1)


if __name__ == "__main__":
    main()
