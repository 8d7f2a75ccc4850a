"""Faults on real logs: is the grid localizer ever confidently wrong?

    python bench/grid/grid_faults.py [--log intel|aces ...] [--faults NAME ...] [--trials 20]
        [--seed 38] [--details] [--node [--scan-rate 2]]

The localizer of real_buildings.py (grid_localizer's defaults, the map from the log's
corrected poses, its raw odometry and scans, the first corrected pose given; the core,
no DDS) on the shipped CARMEN logs, each pass with one kind of fault injected at PLACES
places spread evenly over the log (each at the first odometry sample from that time on
whose next 3 s of odometry move 0.5 m or more: a fault of a robot that drives):

- ``backwards_3s``, ``backwards_6s``: for that long each odometry increment is applied
  backwards (its inverse: the odometry says the robot drove back where it drove on);
- ``heading_slip``: one odometry increment turned by 30 degrees more than it did (the
  sign alternating from place to place);
- ``frozen_3s``: the odometry stands still for 3 s while the robot moves;
- ``clutter_5s``: for 5 s, 30 % of each scan's beams replaced by short random ranges
  (uniform in 0.2 .. 2 m: people walking by);
- ``no_scans_3s``: no scan for 3 s (the odometry goes on);
- ``kidnap``: ``--trials`` seeded trials, each from the unfaulted run at a scan k drawn
  at random: the robot is carried 4.5 to 5.5 m (to where the log's robot was at a scan m
  at least 60 s from k) while the odometry says nothing: the localizer is then given the
  log from scan m on (re-timed to follow scan k, its odometry continuing from the pose it
  had), for TRIAL_S of log time, and scored against the corrected poses from m on;
- ``none``: the unfaulted log (run with ``kidnap``, whose trials start from it).

After the odometry faults the odometry goes on from where it was left (a rigid offset
from the raw track, as a real odometry's error stays in it). Times are the log's: a
corrected log holds a scan every 3 s or so, so a 3 s fault spans one or two updates.

Per log and fault: the updates, the share within 0.2 m and 5 degrees (real_logs.py's),
the updates said lost (quality below LOST), the share whose error lies inside the
published covariance's 99 % region (squared Mahalanobis distance in x, y, yaw at most
11.34), the confidently wrong updates: off by more than 0.5 m or 30 degrees while the
quality is 0.8 or more or the covariance puts the error beyond its 99.9 % region
(squared distance above 16.27, the chi-square point for 3 degrees of freedom), with the
largest such error, and the largest error. Kidnap: the trials said lost (quality below
LOST) within 5 s of the first scan after the kidnap, and within 0.2 m and 5 degrees again
within 15 s, with the median times. ``--details`` lists every confidently wrong update
with its quality, squared distance, the probability the floor dropped (``last_dropped``)
and its log evidence against the median of the ten updates before it.

With ``--node`` each faulted log goes through the running executables instead, as
real_log_node.py runs a log (the kidnap's trials each a run of its own: from the
corrected pose LEAD_SCANS scans before scan k, then carried as above): written as a
CARMEN log (the truth as the laser's pose, the faulted odometry as the odometry),
imported, mapped from the unfaulted log, played at ``--scan-rate`` scans a second (2:
on a loaded 2-core machine 5 left the node no time for every scan; the bench says when
the node received fewer scans than were played) into
``grid_localizer`` (ROS domain NODE_DOMAIN, loopback); each published pose is scored with
its covariance and the quality published before it.

Seeded and deterministic: the same command prints the same figures (but the time; the
node's, as the node's own run, may leave out a scan it had no time for).
"""

from __future__ import annotations

import argparse
import copy
import math
import sys
import tempfile
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

sys.path.insert(1, str(Path(__file__).resolve().parents[2]))  # the repository: bench

from bench.common import confine_ros, table  # noqa: E402
from bench.grid.real_buildings import chosen_logs, localizer, ns, resolve, scan_beams  # noqa: E402
from bench.grid.real_logs import NEAR_M, NEAR_RAD, SURE, WRONG_M, WRONG_RAD  # noqa: E402

from estimation_nodes.core.geometry import compose, relative  # noqa: E402
from estimation_nodes.tools.importers import carmen  # noqa: E402

Pose = tuple[float, float, float]
ORIGIN: Pose = (0.0, 0.0, 0.0)
PLACES = 5
#: Squared Mahalanobis distances in (x, y, yaw): chi-square, 3 degrees of freedom, at
#: 99.9 % (beyond: the covariance rules the error out) and 99 %.
CHI2_999, CHI2_99 = 16.27, 11.34
#: A quality below this says lost.
LOST = 0.5
#: A fault's place starts where the next MOVING_S of odometry move MOVING_M or more.
MOVING_S, MOVING_M = 3.0, 0.5
SLIP_RAD = math.radians(30.0)
CLUTTER_SHARE, CLUTTER_M = 0.3, (0.2, 2.0)
#: Kidnap trials: how far the robot is carried, how far apart in time its two scans are
#: at least, how long (s of the log) each trial runs after the kidnap, and the goals.
KIDNAP_M, KIDNAP_APART_S, TRIAL_S = (4.5, 5.5), 60.0, 30.0
#: --node: a trial's run starts this many scans before its kidnap, from the corrected pose.
LEAD_SCANS = 10
LOST_WITHIN_S, FOUND_WITHIN_S = 5.0, 15.0
#: fault -> (duration s, what it does): odometry (each increment changed) or scans.
FAULTS = {
    "backwards_3s": (3.0, "odometry"), "backwards_6s": (6.0, "odometry"),
    "heading_slip": (0.0, "odometry"), "frozen_3s": (3.0, "odometry"),
    "clutter_5s": (5.0, "scans"), "no_scans_3s": (3.0, "scans"),
}
ALL = ["none", *FAULTS, "kidnap"]
#: --node: the ROS domain of the localizer, the play and the bench's node (common.py).
NODE_DOMAIN = 95


@dataclass(frozen=True)
class Odometry:
    t: float
    pose: Pose


@dataclass(frozen=True)
class Reading:
    """A scan and the corrected pose at it (the truth)."""

    t: float
    ranges: np.ndarray
    truth: Pose


@dataclass
class Update:
    t: float
    truth: Pose
    pose: Pose
    quality: float
    covariance: np.ndarray
    log_evidence: float
    dropped: float

    @property
    def error_m(self) -> float:
        return math.hypot(self.pose[0] - self.truth[0], self.pose[1] - self.truth[1])

    @property
    def error_rad(self) -> float:
        return abs(math.remainder(self.pose[2] - self.truth[2], 2 * math.pi))

    @property
    def distance2(self) -> float:
        """The error's squared Mahalanobis distance under the published covariance."""
        error = np.array([self.pose[0] - self.truth[0], self.pose[1] - self.truth[1],
                          math.remainder(self.pose[2] - self.truth[2], 2 * math.pi)])
        try:
            return float(error @ np.linalg.solve(self.covariance, error))
        except np.linalg.LinAlgError:
            return math.inf

    @property
    def off(self) -> bool:
        return self.error_m > WRONG_M or self.error_rad > WRONG_RAD

    @property
    def near(self) -> bool:
        return self.error_m <= NEAR_M and self.error_rad <= NEAR_RAD

    @property
    def confidently_wrong(self) -> bool:
        return self.off and (self.quality >= SURE or self.distance2 > CHI2_999)


@dataclass
class Trial:
    """A kidnap trial: its scans k (carried from) and m (carried to), its updates."""

    k: int
    m: int
    updates: list[Update] = field(default_factory=list)
    start_t: float = 0.0

    def first(self, condition) -> float | None:
        """Seconds from the first scan after the kidnap to the first update that meets
        ``condition``; None: none did."""
        for update in self.updates:
            if condition(update):
                return update.t - self.start_t
        return None


def events_of(log: carmen.CarmenLog) -> list[Odometry | Reading]:
    """The log as the localizer takes it: each scan after the odometry up to its time."""
    events: list[Odometry | Reading] = []
    odometry = iter(log.odometry)
    pending = next(odometry, None)
    for scan in log.scans:
        while pending is not None and pending.t <= scan.t:
            events.append(Odometry(pending.t, pending.pose))
            pending = next(odometry, None)
        events.append(Reading(scan.t, scan.ranges, scan.pose))
    return events


def places(events: list[Odometry | Reading]) -> list[float]:
    """PLACES times spread evenly over the log, each moved on to where the odometry
    moves MOVING_M within MOVING_S."""
    odometry = [e for e in events if isinstance(e, Odometry)]
    times = np.array([e.t for e in odometry])
    span = times[-1] - times[0]
    found = []
    for i in range(PLACES):
        start = int(np.searchsorted(times, times[0] + span * (i + 0.5) / PLACES))
        for index in range(start, len(odometry)):
            end = int(np.searchsorted(times, times[index] + MOVING_S, side="right")) - 1
            pose, later = odometry[index].pose, odometry[end].pose
            if math.hypot(later[0] - pose[0], later[1] - pose[1]) >= MOVING_M:
                found.append(float(times[index]))
                break
    return found


def inverse(pose: Pose) -> Pose:
    return relative(pose, ORIGIN)


def with_odometry_fault(events: list, fault: str, starts: list[float]) -> list:
    """The events with the odometry increments inside each fault's window changed, the
    odometry after it going on from where the fault left it."""
    duration = FAULTS[fault][0]
    out: list[Odometry | Reading] = []
    previous: Pose | None = None        # the raw odometry before this sample
    faulty: Pose | None = None          # the faulty odometry before it
    offset = ORIGIN                     # faulty = offset (+) raw outside the windows
    slipped = 0
    for event in events:
        if not isinstance(event, Odometry):
            out.append(event)
            continue
        window = next((i for i, t0 in enumerate(starts)
                       if t0 <= event.t <= t0 + duration), None)
        if previous is None or faulty is None or window is None:
            pose = compose(offset, event.pose)
        else:
            step = relative(previous, event.pose)
            if fault.startswith("backwards"):
                step = inverse(step)
            elif fault.startswith("frozen"):
                step = ORIGIN
            elif slipped <= window:     # the slip: the window's first increment only
                turn = SLIP_RAD if window % 2 == 0 else -SLIP_RAD
                step = (step[0], step[1], math.remainder(step[2] + turn, 2 * math.pi))
                slipped = window + 1
            pose = compose(faulty, step)
            offset = compose(pose, inverse(event.pose))
        previous, faulty = event.pose, pose
        out.append(replace(event, pose=pose))
    return out


def with_scan_fault(events: list, fault: str, starts: list[float],
                    rng: np.random.Generator) -> list:
    """The events with each scan inside a fault's window cluttered or left out."""
    duration = FAULTS[fault][0]
    out = []
    for event in events:
        inside = isinstance(event, Reading) and any(
            t0 <= event.t <= t0 + duration for t0 in starts)
        if not inside:
            out.append(event)
        elif fault.startswith("clutter"):
            ranges = event.ranges.copy()
            chosen = rng.choice(ranges.size, round(CLUTTER_SHARE * ranges.size),
                                replace=False)
            ranges[chosen] = rng.uniform(*CLUTTER_M, size=chosen.size)
            out.append(replace(event, ranges=ranges))
    return out


class Runner:
    """One log's localizer runs: each from the first corrected pose."""

    def __init__(self, log: carmen.CarmenLog) -> None:
        self.log = log
        self.fresh, self.settings = localizer(log, 0.1, 72, belief_floor=self._floor())
        self.events = events_of(log)

    @staticmethod
    def _floor() -> float:
        from estimation_nodes.params.specs import GRID_LOCALIZER_SPECS, spec_defaults

        return spec_defaults(GRID_LOCALIZER_SPECS)["belief_floor"]

    def step(self, localization, event: Odometry | Reading) -> Update | None:
        """Give ``event`` to the localizer; the update it made, if it made one."""
        if isinstance(event, Odometry):
            localization.on_odometry(event.pose, ns(event.t))
            return None
        stamp = ns(event.t)
        if not localization.due(stamp):
            return None
        localization.update(*scan_beams(event.ranges, self.settings.max_beams), stamp)
        estimate = localization.estimate(self.settings.quality_radius,
                                         self.settings.quality_angle)
        return Update(event.t, event.truth, estimate.pose, estimate.quality,
                      estimate.covariance, localization.log_evidence,
                      localization.last_dropped)

    def run(self, events: list, trials: list[Trial] | None = None) -> list[Update]:
        """A pass over ``events`` from the first corrected pose; ``trials`` (sorted by k)
        each branch off it after its scan k."""
        localization = copy.deepcopy(self.fresh)
        updates, scans, last_odometry = [], 0, ORIGIN
        pending = list(trials or [])
        for event in events:
            update = self.step(localization, event)
            if update is not None:
                updates.append(update)
            if isinstance(event, Odometry):
                last_odometry = event.pose
                continue
            while pending and pending[0].k == scans:
                self.kidnap(localization, pending.pop(0), event.t, last_odometry)
            scans += 1
        return updates

    def kidnap(self, localization, trial: Trial, t_k: float, odometry_k: Pose) -> None:
        """Branch off at scan k: the updates of TRIAL_S after the kidnap
        (``carried``)."""
        branch = copy.deepcopy(localization)
        for moved in self.carried(trial, t_k, odometry_k):
            update = self.step(branch, moved)
            if update is not None:
                trial.updates.append(update)

    def carried(self, trial: Trial, t_k: float, odometry_k: Pose) -> list:
        """What follows scan k (at ``t_k``, the odometry then at ``odometry_k``) once the
        robot is carried: the log from scan m on, re-timed to follow t_k, its odometry
        going on from ``odometry_k``, for TRIAL_S (and ``trial.start_t`` set)."""
        scans = self.log.scans
        t_before = scans[trial.m - 1].t
        raw = [s for s in self.log.odometry if s.t <= t_before]
        offset = compose(odometry_k, inverse(raw[-1].pose if raw else ORIGIN))
        shift = t_k - t_before
        trial.start_t = scans[trial.m].t + shift
        events: list[Odometry | Reading] = []
        for event in self.events:
            if event.t <= t_before:
                continue
            t = event.t + shift
            if t > trial.start_t + TRIAL_S:
                break
            events.append(Odometry(t, compose(offset, event.pose))
                          if isinstance(event, Odometry) else replace(event, t=t))
        return events

    def lead_up(self, k: int) -> tuple[list, float, Pose]:
        """The log's events from LEAD_SCANS scans before scan k to scan k, the time of
        scan k and the odometry then: a trial through the node starts there, from the
        corrected pose (the node's run is a run of its own, not a branch of one)."""
        readings = [i for i, e in enumerate(self.events) if isinstance(e, Reading)]
        first, last = readings[max(k - LEAD_SCANS, 0)], readings[k]
        before = [e for e in self.events[:last] if isinstance(e, Odometry)]
        return self.events[first:last + 1], self.events[last].t, \
            before[-1].pose if before else ORIGIN


def node_kidnaps(name: str, runner: Runner, trials: list[Trial], scan_rate: float) -> None:
    """Each trial through the running node: the lead-up to scan k then the robot carried
    (``Runner.carried``), a play of its own; its updates after the kidnap."""
    with tempfile.TemporaryDirectory() as folder:
        map_yaml = None
        for index, trial in enumerate(trials):
            events, t_k, odometry_k = runner.lead_up(trial.k)
            events = events + runner.carried(trial, t_k, odometry_k)
            work = Path(folder) / f"trial_{index}"
            work.mkdir()
            updates, map_yaml = through_node(name, events, work, scan_rate, map_yaml)
            trial.updates = [u for u in updates if u.t >= trial.start_t]


def write_carmen(events: list, path: Path) -> None:
    """The events as a CARMEN log the importer reads back as they are: FLASER lines with
    the truth as the laser's pose and the odometry then as its odometry, ODOM lines with
    the odometry's own poses (no restart line: the poses are the raw track's)."""
    lines, odometry = [], ORIGIN
    for event in events:
        if isinstance(event, Odometry):
            odometry = event.pose
            lines.append("ODOM " + " ".join(map(repr, event.pose)) + f" 0 0 0 {event.t!r} "
                         f"bench {event.t!r}")
        else:
            lines.append(f"FLASER {event.ranges.size} "
                         + " ".join(repr(float(r)) for r in event.ranges) + " "
                         + " ".join(map(repr, (*event.truth, *odometry)))
                         + f" {event.t!r} bench {event.t!r}")
    path.write_text("\n".join(lines) + "\n")


def through_node(name: str, events: list, work: Path, scan_rate: float,
                 map_yaml: Path | None = None) -> tuple[list[Update], Path]:
    """``events`` through the running grid_localizer (real_log_node.py's run at
    ``scan_rate`` scans a second, the map from the unfaulted log, or ``map_yaml`` where
    one was made): its published poses, each with the quality published before it and
    its covariance; and the map it was given."""
    from real_log_node import play

    log_path = work / "faulted.log"
    write_carmen(events, log_path)
    options = argparse.Namespace(scan_rate=scan_rate, resolution=0.1, heading_bins=72,
                                 max_odom_jump=5.0, seconds=0.0, tf=False, record=None)
    played = play(options, log_path, work, map_from=resolve(name), map_yaml=map_yaml)
    watcher = played.watcher
    say_scans_lost(name, events, watcher.diagnostics)
    truth = {ns(e.t): e for e in events if isinstance(e, Reading)}
    return [Update(truth[stamp].t, truth[stamp].truth, pose, watcher.quality_of(stamp),
                   watcher.covariances[stamp], math.nan, math.nan)
            for stamp, pose in sorted(watcher.poses.items()) if stamp in truth], \
        played.map_yaml


def say_scans_lost(name: str, events: list, diagnostics: dict[str, str]) -> None:
    """A line (stderr) when the node received fewer scans than were played: those it
    never saw were the machine's load, not the fault's (lower --scan-rate)."""
    played = sum(1 for e in events if isinstance(e, Reading))
    received = int(diagnostics.get("scans_received", 0))
    if received < played:
        print(f"grid_faults: {name}: the node received {received} of {played} scans "
              f"(missed: {diagnostics.get('scans_missed', '?')}); the figures are partly "
              "the machine's load: lower --scan-rate", file=sys.stderr, flush=True)


def kidnap_trials(log: carmen.CarmenLog, count: int, rng: np.random.Generator) -> list[Trial]:
    """``count`` trials: scans k and m drawn as the module's docstring says, sorted by k."""
    poses = np.array([scan.pose[:2] for scan in log.scans])
    times = np.array([scan.t for scan in log.scans])
    last = int(np.searchsorted(times, times[-1] - TRIAL_S - 10.0))
    trials: list[Trial] = []
    while len(trials) < count:
        k = int(rng.integers(10, last))
        if any(trial.k == k for trial in trials):
            continue        # a trial of its own each: the same k would repeat one
        distance = np.hypot(*(poses - poses[k]).T)
        candidates = np.flatnonzero((distance >= KIDNAP_M[0]) & (distance <= KIDNAP_M[1])
                                    & (np.abs(times - times[k]) >= KIDNAP_APART_S))
        candidates = candidates[(candidates > 0) & (candidates < last)]
        if candidates.size:
            trials.append(Trial(k, int(rng.choice(candidates))))
    return sorted(trials, key=lambda trial: trial.k)


def row(log_name: str, fault: str, updates: list[Update]) -> list[str]:
    wrong = [u for u in updates if u.confidently_wrong]
    largest = max(updates, key=lambda u: u.error_m)
    worst = max(wrong, key=lambda u: u.error_m) if wrong else None
    return [log_name, fault, str(len(updates)),
            f"{100 * np.mean([u.near for u in updates]):.1f} %",
            str(len(wrong)) + (f" (up to {worst.error_m:.1f} m, q {worst.quality:.2f}, "
                               f"d2 {worst.distance2:.3g})" if worst else ""),
            f"{largest.error_m:.2f} m, {math.degrees(max(u.error_rad for u in updates)):.0f}"
            " deg",
            str(sum(u.quality < LOST for u in updates)),
            f"{100 * np.mean([u.distance2 <= CHI2_99 for u in updates]):.1f} %"]


def kidnap_row(log_name: str, trials: list[Trial], suffix: str = "") -> list[str]:
    lost = [t.first(lambda u: u.quality < LOST) for t in trials]
    found = [t.first(lambda u: u.near) for t in trials]
    updates = [u for t in trials for u in t.updates]

    def within(times: list[float | None], limit: float) -> str:
        met = [x for x in times if x is not None and x <= limit]
        median = f", median {np.median(met):.1f} s" if met else ""
        return f"{len(met)} / {len(times)}{median}"

    return [*row(log_name, f"kidnap ({len(trials)} trials){suffix}", updates),
            within(lost, LOST_WITHIN_S), within(found, FOUND_WITHIN_S)]


def details(log_name: str, fault: str, updates: list[Update]) -> list[list[str]]:
    """Each confidently wrong update: what the localizer knew then."""
    rows = []
    for i, u in enumerate(updates):
        if not u.confidently_wrong:
            continue
        before = [v.log_evidence for v in updates[max(0, i - 10):i]]
        usual = float(np.median(before)) if before else math.nan
        rows.append([log_name, fault, f"{u.t - updates[0].t:.1f}", f"{u.error_m:.2f}",
                     f"{math.degrees(u.error_rad):.0f}", f"{u.quality:.3f}",
                     f"{u.distance2:.3g}", f"{u.dropped:.2e}",
                     f"{u.log_evidence - usual:.1f}"])
    return rows


HEADER = ["log", "fault", "updates", "within 0.2 m, 5 deg", "confidently wrong",
          "largest error", "said lost", "error in 99 % region",
          f"lost within {LOST_WITHIN_S:g} s", f"within 0.2 m again in {FOUND_WITHIN_S:g} s"]
DETAILS = ["log", "fault", "t (s)", "error m", "error deg", "quality", "d2",
           "last_dropped", "log evidence - median of 10 before"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--log", action="append", default=[],
                        help="intel, aces or a CARMEN log's path (default: intel and aces)")
    parser.add_argument("--faults", nargs="+", choices=ALL, default=ALL,
                        help="the faults to run (default: all)")
    parser.add_argument("--trials", type=int, default=20, help="kidnap trials (default: 20)")
    parser.add_argument("--seed", type=int, default=38, help="the seed (default: 38)")
    parser.add_argument("--details", action="store_true",
                        help="list every confidently wrong update")
    parser.add_argument("--node", action="store_true",
                        help="through the running grid_localizer (real_log_node.py's run; "
                             "not the kidnap)")
    parser.add_argument("--scan-rate", type=float, default=2.0,
                        help="--node: scans a second the play makes (default: %(default)s)")
    args = parser.parse_args()
    logs = chosen_logs(args.log, "grid_faults")
    if args.node:
        confine_ros(NODE_DOMAIN)
    rows, listed = [], []
    for name in logs:
        log = carmen.read_log(resolve(name))
        runner = Runner(log)
        starts = places(runner.events)
        for fault in [f for f in ALL if f in args.faults]:
            if fault == "none" and "kidnap" in args.faults and not args.node:
                continue        # the kidnap's pass is the unfaulted one
            started = time.monotonic()
            # One stream of random numbers per log and fault, whatever else is run.
            rng = np.random.default_rng([args.seed, ALL.index(fault), len(log.scans)])
            if fault == "kidnap" and args.node:
                trials = kidnap_trials(log, args.trials, rng)
                node_kidnaps(name, runner, trials, args.scan_rate)
                rows.append(kidnap_row(name, trials, " (node)"))
                for trial in trials:
                    listed += details(name, f"kidnap {trial.k} -> {trial.m} (node)",
                                      trial.updates)
            elif fault == "kidnap":
                trials = kidnap_trials(log, args.trials, rng)
                updates = runner.run(runner.events, trials)
                rows.append(row(name, "none", updates) + ["-", "-"])
                rows.append(kidnap_row(name, trials))
                listed += details(name, "none", updates)
                for trial in trials:     # each trial's evidence against its own updates
                    listed += details(name, f"kidnap {trial.k} -> {trial.m}", trial.updates)
            else:
                if fault == "none":
                    events = runner.events
                elif FAULTS[fault][1] == "odometry":
                    events = with_odometry_fault(runner.events, fault, starts)
                else:
                    events = with_scan_fault(runner.events, fault, starts, rng)
                if args.node:
                    with tempfile.TemporaryDirectory() as work:
                        updates, _ = through_node(name, events, Path(work), args.scan_rate)
                else:
                    updates = runner.run(events)
                rows.append(row(name, fault + (" (node)" if args.node else ""), updates)
                            + ["-", "-"])
                listed += details(name, fault, updates)
            print(f"grid_faults: {name} {fault} in {time.monotonic() - started:.0f} s",
                  file=sys.stderr, flush=True)
    print(table(HEADER, rows))
    if args.details and listed:
        print(table(DETAILS, listed))


if __name__ == "__main__":
    main()
