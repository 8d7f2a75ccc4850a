"""estimation_replay: run the filters offline over a recording and compare with what was published.

    estimation_replay RUN.mcap [--params-file FILE] [--tolerance 1e-9]

The recording's inputs (motion_cmd, tile_observation, position_measurement,
in the order they were published) go through the same filters the estimator uses, built from
the parameters stored in the recording (or a file you give). Each offline
estimate is compared with the estimate recorded online, in order, topic by
topic. Exit 0 when all agree to the tolerance, 1 otherwise, with each
differing step shown; 2 when the recording cannot be read.

The estimator applies events in the order they were published too, whatever
order they reached it in: when an event arrives late it goes back, applies
it and republishes the estimates after it. The estimates it published
before that were provisional; they are superseded, and reported as such. The
comparison takes, for each offline estimate, the online one that settled it:
every offline estimate must be matched, in order, and every superseded one
must be followed by the estimates that replace it.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from estimation_nodes.core.kalman.filter import KalmanFilter
from estimation_nodes.core.tiles.filter import HistogramFilter
from estimation_nodes.params import topics
from estimation_nodes.params.estimator import build_estimator_settings
from estimation_nodes.params.param_files import check_params_file, read_node_parameters
from estimation_nodes.params.specs import ESTIMATOR_SPECS, spec_defaults
from estimation_nodes.params.wording import plural
from estimation_nodes.tools.recording.mcap import Recording, RecordingError, read_recording


@dataclass
class Comparison:
    """Offline against online, per output topic."""

    compared: dict[str, int] = field(default_factory=dict)
    differences: list[str] = field(default_factory=list)
    worst: dict[str, float] = field(default_factory=dict)
    #: Online estimates superseded by a republication after a late event, per topic.
    superseded: dict[str, int] = field(default_factory=dict)

    @property
    def equal(self) -> bool:
        return not self.differences

    def compare(self, topic: str, online: list, offline: list, tolerance: float) -> None:
        """Match ``offline`` (the estimates in causal order) with what was published."""
        alignment = align(online, offline, tolerance)
        self.compared[topic] = len(offline)
        self.superseded[topic] = len(alignment.superseded)
        self.worst[topic] = alignment.worst
        matched = alignment.matched
        if matched < len(offline):
            self.differences.append(_missing(topic, matched, online, offline[matched]))
        unreplaced = [i for i in alignment.superseded if i > alignment.last_match]
        if unreplaced:
            self.differences.append(
                f"{topic}: {plural(len(unreplaced), 'online estimate')} after the last one "
                f"that equals the offline filter (first: online #{unreplaced[0] + 1})")


@dataclass(frozen=True)
class Alignment:
    """How published estimates line up with the offline ones (see ``align``)."""

    #: How many offline estimates, from the first, found their online estimate.
    matched: int
    #: Indices of online estimates that equal no offline one in their place.
    superseded: list[int]
    #: Index of the last online estimate that matched (-1: none).
    last_match: int
    #: Largest difference of a matched pair.
    worst: float
    #: For each matched offline estimate, the index of the online one that settled it.
    settled: list[int]


def align(online: list, offline: list, tolerance: float) -> Alignment:
    """Walk the online estimates: each equals the next offline one, or starts the estimator's
    republication of earlier steps after a late event, or is neither (a provisional
    estimate, superseded by what follows).

    A republication goes from the step it starts at on to every step applied before it,
    published one after another: an estimate that equals an earlier step is taken as one
    only when the estimates after it go on with that step's successors up to where the
    walk was. Alone, the equality can be chance: a provisional belief made of readings
    without their moves (a restarted estimator's) can equal an earlier step's, and taking
    it for a republication left every later step unmatched.
    """
    offline_arrays = [np.asarray(value, float) for value in offline]
    online_arrays = [np.asarray(value, float) for value in online]

    def equal(online_index: int, step: int) -> bool:
        return _difference(online_arrays[online_index], offline_arrays[step]) <= tolerance

    def republishes(index: int, step: int, expected: int) -> bool:
        run = range(step + 1, expected)
        return index + len(run) < len(online_arrays) and all(
            equal(index + offset, later) for offset, later in enumerate(run, start=1))

    expected, last_match, worst = 0, -1, 0.0
    superseded: list[int] = []
    settled: list[int] = []
    for index, value in enumerate(online_arrays):
        if expected < len(offline_arrays) and equal(index, expected):
            step = expected
        else:
            step = next((earlier for earlier in range(expected - 1, -1, -1)
                         if equal(index, earlier) and republishes(index, earlier, expected)),
                        None)
        if step is None:
            superseded.append(index)
            continue
        worst = max(worst, _difference(value, offline_arrays[step]))
        expected, last_match = step + 1, index
        settled[step:] = [index]
    return Alignment(expected, superseded, last_match, worst, settled)


def _difference(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b), initial=0.0)) if a.shape == b.shape else float("inf")


def _missing(topic: str, step: int, online: list, offline) -> str:
    """Why offline estimate ``step`` found no online one: the closest shown beside it."""
    if not online:
        return f"{topic} #{step + 1}: computed offline, not recorded"
    target = np.asarray(offline, float)
    error, closest = min(((_difference(np.asarray(v, float), target), np.asarray(v, float))
                          for v in online), key=lambda item: item[0])
    return (f"{topic} #{step + 1}: |online - offline| = {error:.3g} (the closest online "
            f"estimate)\n"
            f"    online  {np.array2string(closest, precision=9, threshold=12)}\n"
            f"    offline {np.array2string(target, precision=9, threshold=12)}")


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
    computed: dict[str, list] = {output: [] for output in recorded}
    # The component kalman_estimate shows as its x (the 1-D filter's position).
    shown = settings.kalman.pose_components[0]

    def check(output: str, offline) -> None:
        computed[output].append(np.array(offline, float))

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
        comparison.compare(output, online, computed[output], tolerance)
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
    if args.recording.is_file() and _is_grid(args.recording):
        sys.exit(_main_grid(args))
    if args.recording.is_file() and _is_landmarks(args.recording):
        sys.exit(_main_landmarks(args))
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
    if not any(comparison.compared.values()):
        # An imported log has none of the estimator's outputs: nothing compared must
        # not read as EQUAL.
        print(f"estimation_replay: {args.recording}: no estimate of the estimator or the "
              f"grid localizer in it, nothing to compare (an imported log has only the "
              f"sensors' messages)", file=sys.stderr)
        sys.exit(2)
    for topic, count in sorted(recording.counts.items()):
        print(f"  {topic}: {plural(count, 'message')}")
    for topic, count in comparison.compared.items():
        superseded = comparison.superseded.get(topic, 0)
        print(f"{topic}: {count} estimates compared, largest difference "
              f"{comparison.worst.get(topic, float('nan')):.3g}"
              + (f"; {superseded} provisional, superseded after a late event"
                 if superseded else ""))
    for line in comparison.differences:
        print(line)
    verdict = "EQUAL" if comparison.equal else f"DIFFERENT ({len(comparison.differences)})"
    print(f"online vs offline to {args.tolerance:g}: {verdict}")
    sys.exit(0 if comparison.equal else 1)


def _is_grid(path: Path) -> bool:
    from estimation_nodes.tools.replay.grid_localizer import is_grid_recording

    try:
        return is_grid_recording(path)
    except Exception:               # not MCAP at all: read_recording says so in one line
        return False


def _is_landmarks(path: Path) -> bool:
    from estimation_nodes.tools.replay.landmarks import is_landmark_recording

    try:
        return is_landmark_recording(path)
    except Exception:               # not MCAP at all: read_recording says so in one line
        return False


def _replayed(replay_function, args: argparse.Namespace):
    """``replay_function(recording, parameters or None, tolerance)``, or None after one line
    on stderr where the recording or the parameters cannot be used."""
    try:
        parameters_yaml = check_params_file(args.params_file).read_text(encoding="utf-8") \
            if args.params_file else None
        return replay_function(args.recording, parameters_yaml, args.tolerance)
    except (RecordingError, ValueError) as error:
        print(f"estimation_replay: {error}", file=sys.stderr)
        return None


def _verdict(comparison, compared: str, notes: list[str], tolerance: float) -> int:
    """Print what was compared, the notes, the differences and the verdict; the exit code."""
    print(f"pose: {compared}, largest differences "
          + ", ".join(f"{k} {v:.3g}" for k, v in comparison.worst.items()))
    for line in notes + comparison.differences[:20]:
        print(line)
    verdict = "EQUAL" if comparison.equal else f"DIFFERENT ({len(comparison.differences)})"
    print(f"online vs offline to {tolerance:g}: {verdict}")
    return 0 if comparison.equal else 1


def _main_landmarks(args: argparse.Namespace) -> int:
    """ekf_localizer's replay (tools/replay/landmarks.py); its exit code."""
    from estimation_nodes.tools.replay.landmarks import replay_landmarks

    comparison = _replayed(replay_landmarks, args)
    if comparison is None:
        return 2
    if not comparison.compared:
        print(f"estimation_replay: {args.recording}: no pose of ekf_localizer in it, "
              f"nothing to compare", file=sys.stderr)
        return 2
    notes = []
    if comparison.provisional:
        notes.append(f"  {plural(comparison.provisional, 'pose')} provisional (an event of "
                     f"its stamp or older may not have been taken yet), not compared")
    if comparison.after_too_late:
        notes.append(f"  {plural(comparison.after_too_late, 'pose')} after an event later "
                     f"than reorder_horizon (applied out of order), not compared")
    if comparison.dropped:
        notes.append(f"  {plural(comparison.dropped, 'input')} the localizer drops (not "
                     f"finite, unstamped or malformed)")
    return _verdict(comparison, f"{comparison.compared} estimates compared", notes,
                    args.tolerance)


def _main_grid(args: argparse.Namespace) -> int:
    """The grid localizer's replay (tools/replay/grid_localizer.py); its exit code."""
    from estimation_nodes.tools.replay.grid_localizer import replay_grid

    comparison = _replayed(replay_grid, args)
    if comparison is None:
        return 2
    notes = []
    others = ", ".join(plural(n, kind) for kind, n in sorted(comparison.others.items()) if n)
    if others:
        notes.append(f"  also compared: {others} (uniform belief or initial pose)")
    if comparison.assumed:
        notes.append(f"  the recording starts after the localizer's first outputs: it was "
                     f"taken to have made {plural(comparison.assumed, 'update')} before them "
                     f"by its rule, with the recorded scans")
    if comparison.left_out:
        notes.append(f"  {plural(comparison.left_out, 'scan')} its update rule takes the "
                     f"localizer left out (superseded, late odometry, or no time); the replay "
                     f"took the scans it took")
    return _verdict(comparison, f"{comparison.compared} updates compared", notes,
                    args.tolerance)

if __name__ == "__main__":
    main()
