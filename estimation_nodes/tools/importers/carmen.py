"""CARMEN laser logs (plain or gzipped), as the Radish / Freiburg SLAM benchmark keeps them.

``FLASER n r1 .. rn x y theta odom_x odom_y odom_theta t host t_logger``: a scan of n
ranges, beam i at ``-pi/2 + i pi / n`` in the robot frame, with the pose at that scan
(in a "corrected" log, the SLAM-corrected pose: the truth a localizer is scored
against). ``ODOM x y theta tv rv accel t host t_logger``: odometry. In a corrected log
the odometry restarts at each scan's corrected pose (a line with t = 0 right after
the FLASER), so the raw wheel odometry, with its real drift, is rebuilt here by
chaining each scan-to-scan step: (pose[k-1])^-1 (+) (the last ODOM before scan k).

The restart line is the first ODOM after a scan with that scan's pose and a time that is
0 or earlier than the scan's (some logs leave a leftover value there, such as 1e-42 or
1.13, rather than 0): it takes its scan's time. The odometry is rebuilt in the log's
order and then sorted by time, stably, so that no line is lost when the log's time runs
back; ``odometry_reordered`` counts the lines that sort moved.

``ROBOTLASER1``, the newer format, is read in the layout CARMEN's own logger writes and
reads it (``carmen_logwrite_write_robot_laser`` in ``src/logger/writelog.c`` and
``carmen_string_to_robot_laser_message`` in ``src/logger/readlog.c``, as in the public
copy ``qh-huang/carmen``; the Freiburg robot-mapping course's ``read_robotlaser.m``
agrees: five values between the robot pose and the timestamp)::

    ROBOTLASER1 laser_type start_angle field_of_view angular_resolution maximum_range
        accuracy remission_mode num_readings [range_readings] num_remissions
        [remission_values] laser_pose_x laser_pose_y laser_pose_theta robot_pose_x
        robot_pose_y robot_pose_theta tv rv forward_safety_dist side_safety_dist
        turn_axis timestamp host logger_timestamp

Beam i is at ``start_angle + i angular_resolution`` (field_of_view is not needed), the
remissions are the scan's intensities when there is one per beam, the laser pose is the
scan's pose and the robot pose its odometry pose, with tv and rv. A line whose token
after the timestamp is a number is another layout and is counted as malformed.

A log without ODOM lines (the SLAM benchmark's raw ``.clf`` logs have FLASER lines
only) gives its odometry from the scan lines' own odometry fields (FLASER's ``odom_x
odom_y odom_theta``, ROBOTLASER1's robot pose and velocities) at the scans' times, with
no velocities from FLASER (it has none). A log is raw, not corrected, when nothing in it
says otherwise: no restart line, and on every scan line the laser pose equal to the
odometry pose moved by one fixed mount (none for a laser at the robot's centre, as the
FLASER logs have it), to ``SAME_POSE_M`` and ``SAME_POSE_RAD`` (what a log prints);
``corrected`` is then False, ``mount`` that offset, and the log has no truth.

Times that do not advance: some corrected logs print every time with six significant
digits (``1.13486e+09``), so that a whole log has one stamp or a few. A log with fewer
distinct scan times than half its scans (``STALLED_FRACTION``) is refused, naming
``--scan-rate``; given a rate, ``read_log`` places the scans at it in the log's order from
the first scan's time, and the odometry lines between two scans evenly between them
(those before the first scan in the period before it, from 0 at the earliest, those
after the last in the period after it). A time a ROS stamp cannot hold (below 0, beyond
2^31 - 1 s) is refused in one line.
"""

from __future__ import annotations

import gzip
import math
from bisect import bisect_right
from collections import Counter
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from estimation_nodes.core.geometry import compose, relative

Pose = tuple[float, float, float]

#: A log whose distinct scan times are fewer than this share of its scans has times that
#: do not advance (printed with too few digits): refused unless a scan rate is given.
STALLED_FRACTION = 0.5
#: The laser pose and the odometry pose of a scan line count as the same within these.
SAME_POSE_M, SAME_POSE_RAD = 0.005, 0.005
#: The latest time a ROS stamp holds (builtin_interfaces/Time's sec is an int32).
MAX_TIME_S = 2**31 - 1


class LogError(Exception):
    """A log that cannot be read at all: the message says why in one line."""


@dataclass(frozen=True)
class Scan:
    t: float
    ranges: np.ndarray
    #: Beam i at ``angle_min + i angle_increment`` in the laser's frame.
    angle_min: float
    angle_increment: float
    #: The laser's pose the log gives with the scan (FLASER's x y theta, ROBOTLASER1's
    #: laser pose): the SLAM-corrected one in a corrected log.
    pose: Pose
    #: The odometry pose on the scan line (FLASER's odom_x odom_y odom_theta,
    #: ROBOTLASER1's robot pose).
    odom_pose: Pose
    #: The velocities on the scan line (FLASER has none: 0).
    tv: float = 0.0
    rv: float = 0.0
    #: The laser's own maximum range (ROBOTLASER1; FLASER gives none).
    range_max: float | None = None
    #: One remission (intensity) per beam, or none.
    remissions: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.float32))


@dataclass(frozen=True)
class OdometrySample:
    t: float
    #: The raw odometry pose, chained from the log's start.
    pose: Pose
    tv: float
    rv: float


@dataclass
class CarmenLog:
    scans: list[Scan]
    odometry: list[OdometrySample]
    #: Lines left out by kind ("malformed FLASER", ...), and other notes with counts.
    left_out: Counter[str] = field(default_factory=Counter)
    #: Odometry lines out of time order in the log, put in their place by the sort: the
    #: fewest lines that, moved, leave the others in order (all lines minus the longest
    #: subsequence in time order).
    odometry_reordered: int = 0
    #: The rate the scans were placed at (``read_log``'s ``scan_rate``), if one was given.
    scan_rate: float | None = None
    #: False for a raw log (see the module's docstring): its scan poses are no truth.
    corrected: bool = True
    #: The odometry came from the scan lines' odometry fields: the log has no ODOM line.
    odometry_from_scans: bool = False
    #: A raw log's fixed laser pose in the odometry pose's frame (0, 0, 0: at its centre).
    mount: Pose | None = None

    @property
    def max_reading(self) -> float:
        return max(float(scan.ranges.max()) for scan in self.scans)

    @property
    def laser_range_max(self) -> float | None:
        """The least maximum range the scan lines give, if every one gives one."""
        limits = [scan.range_max for scan in self.scans]
        return None if None in limits else min(limit for limit in limits if limit is not None)


def _lines(path: Path) -> list[str]:
    try:
        raw = path.read_bytes()
        text = gzip.decompress(raw) if raw[:2] == b"\x1f\x8b" else raw
        return text.decode("ascii").splitlines()
    except FileNotFoundError:
        raise LogError(f"{path}: no such file") from None
    except (OSError, EOFError, gzip.BadGzipFile, UnicodeDecodeError) as error:
        raise LogError(f"{path}: cannot be read: {error}") from None


def _numbers(tokens: list[str]) -> list[float] | None:
    try:
        values = [float(v) for v in tokens]
    except ValueError:
        return None
    return values if all(math.isfinite(v) for v in values) else None


def _flaser(tokens: list[str]) -> Scan | None:
    if len(tokens) < 2 or not tokens[1].isdigit():
        return None
    n = int(tokens[1])
    values = _numbers(tokens[2:2 + n + 7])
    if n == 0 or values is None or len(values) != n + 7 or any(r < 0 for r in values[:n]):
        return None
    x, y, theta, odom_x, odom_y, odom_theta = values[n:n + 6]
    return Scan(values[n + 6], np.array(values[:n], dtype=np.float32), -math.pi / 2,
                math.pi / n, (x, y, theta), (odom_x, odom_y, odom_theta))


def _robotlaser(tokens: list[str]) -> Scan | None:
    """A ROBOTLASER1 line in CARMEN's layout (the module's docstring)."""
    head = _numbers(tokens[1:8])
    if head is None or len(head) != 7 or len(tokens) < 10 or not tokens[8].isdigit():
        return None
    _type, start, _fov, resolution, max_range, _accuracy, _mode = head
    n = int(tokens[8])
    at = 9 + n                           # num_remissions
    if n == 0 or len(tokens) <= at or not tokens[at].isdigit():
        return None
    m = int(tokens[at])
    tail = at + 1 + m                    # laser_pose_x
    values = _numbers(tokens[9:at] + tokens[at + 1:tail + 12])
    host = tokens[tail + 12] if len(tokens) > tail + 12 else None
    if values is None or len(values) != n + m + 12 or host is None \
            or _numbers([host]) is not None or resolution == 0 or max_range <= 0 \
            or any(r < 0 for r in values[:n]):
        return None
    remissions = values[n:n + m] if m == n else []
    laser_x, laser_y, laser_theta, robot_x, robot_y, robot_theta, tv, rv = \
        values[n + m:n + m + 8]
    return Scan(values[n + m + 11], np.array(values[:n], dtype=np.float32), start,
                resolution, (laser_x, laser_y, laser_theta), (robot_x, robot_y, robot_theta),
                tv, rv, max_range, np.array(remissions, dtype=np.float32))


#: The scan lines read, by kind.
SCAN_LINES = {"FLASER": _flaser, "ROBOTLASER1": _robotlaser}


def _odom(tokens: list[str]) -> tuple[Pose, float, float, float] | None:
    values = _numbers(tokens[1:8])
    if values is None or len(values) != 7:
        return None
    x, y, theta, tv, rv, _accel, t = values
    return (x, y, theta), tv, rv, t


@dataclass(frozen=True)
class _OdomLine:
    t: float
    pose: Pose
    tv: float
    rv: float
    #: The corrected log's restart at the scan before it (see the module's docstring).
    restart: bool


def read_log(path: Path, scan_rate: float | None = None) -> CarmenLog:
    """A CARMEN log's scans and its raw odometry, sorted by time (stably); malformed lines
    are counted in ``left_out``, never silently dropped. ``scan_rate`` (Hz): the scans and
    odometry placed at that rate in the log's order, whatever times the log gives."""
    records, left_out = _records(Path(path))
    scans = [r for r in records if isinstance(r, Scan)]
    if not scans:
        malformed = sum(left_out[f"malformed {kind} lines"] for kind in SCAN_LINES)
        if malformed:
            raise LogError(f"{path}: no scan line could be read ({malformed} malformed "
                           f"FLASER or ROBOTLASER1 lines)")
        raise LogError(f"{path}: no FLASER or ROBOTLASER1 line: not a CARMEN laser log")
    if scan_rate is not None:
        records = _placed_at(records, scan_rate)
    else:
        distinct = len({scan.t for scan in scans})
        if distinct < STALLED_FRACTION * len(scans):
            raise LogError(f"{path}: the times do not advance: {len(scans)} scans at "
                           f"{distinct} distinct times (printed with too few digits?); "
                           f"give the laser's rate with --scan-rate HZ")
    log = CarmenLog([], [], left_out, scan_rate=scan_rate)
    raw_at_scan: Pose | None = None      # the raw odometry at the last scan
    restart: Pose | None = None          # the pose the log's odometry restarted at
    last_raw: Pose = (0.0, 0.0, 0.0)
    for record in records:
        if isinstance(record, Scan):
            log.scans.append(record)
            continue
        pose, t = record.pose, record.t
        if record.restart:
            # A corrected log's odometry from here on is since this scan, from its pose.
            raw_at_scan, restart, t = last_raw, log.scans[-1].pose, log.scans[-1].t
        if restart is not None and raw_at_scan is not None:
            pose = compose(raw_at_scan, relative(restart, pose))
        last_raw = pose
        log.odometry.append(OdometrySample(t, pose, record.tv, record.rv))
    if not any(isinstance(r, _OdomLine) for r in records):
        log.odometry_from_scans = True
        log.odometry = [OdometrySample(s.t, s.odom_pose, s.tv, s.rv) for s in log.scans]
    mount = relative(log.scans[0].odom_pose, log.scans[0].pose)
    if any(isinstance(r, _OdomLine) and r.restart for r in records) \
            or not all(_same_pose(relative(s.odom_pose, s.pose), mount) for s in log.scans):
        log.corrected = True
    else:
        log.corrected, log.mount = False, mount
    _check_times(Path(path), log)
    log.odometry_reordered = _out_of_order(log.odometry)
    log.odometry.sort(key=lambda sample: sample.t)
    return log


def _records(path: Path) -> tuple[list[Scan | _OdomLine], Counter[str]]:
    """The log's scans and odometry lines in the log's order, and what was left out."""
    records: list[Scan | _OdomLine] = []
    left_out: Counter[str] = Counter()
    last_scan: Scan | None = None        # the last scan, until an ODOM line follows it
    for line in _lines(path):
        tokens = line.split()
        if not tokens or tokens[0].startswith("#") or tokens[0] in ("PARAM", "NEFF", "SYNC"):
            continue
        if tokens[0] in SCAN_LINES:
            scan = SCAN_LINES[tokens[0]](tokens)
            if scan is None:
                left_out[f"malformed {tokens[0]} lines"] += 1
                continue
            records.append(scan)
            last_scan = scan
        elif tokens[0] == "ODOM":
            parsed = _odom(tokens)
            if parsed is None:
                left_out["malformed ODOM lines"] += 1
                continue
            pose, tv, rv, t = parsed
            restart = last_scan is not None and _restarts(last_scan, pose, t)
            records.append(_OdomLine(t, pose, tv, rv, restart))
            last_scan = None
        else:
            left_out[f"{tokens[0]} lines (not used)"] += 1
    return records, left_out


def _placed_at(records: list[Scan | _OdomLine], rate: float) -> list[Scan | _OdomLine]:
    """The records with the scans ``1 / rate`` apart in the log's order from the first
    scan's time, and the odometry lines between two scans evenly between them."""
    period = 1.0 / rate
    start = next(r.t for r in records if isinstance(r, Scan))
    placed: list[Scan | _OdomLine] = []
    between: list[_OdomLine] = []        # the odometry lines since the last scan
    scans = 0

    def spread(low: float, high: float) -> None:
        step = (high - low) / (len(between) + 1)
        placed.extend(replace(line, t=low + (i + 1) * step)
                      for i, line in enumerate(between))
        between.clear()

    for record in records:
        if isinstance(record, Scan):
            t = start + scans * period
            # Before the first scan: the period before it, but no time below 0.
            spread(max(t - period, 0.0) if scans == 0 else t - period, t)
            placed.append(replace(record, t=t))
            scans += 1
        elif record.restart:
            placed.append(record)            # takes its scan's time when rebuilt
        else:
            between.append(record)
    last = start + (scans - 1) * period
    spread(last, last + period)
    return placed


def _check_times(path: Path, log: CarmenLog) -> None:
    """Every time is one a ROS stamp holds (its seconds are an int32 from 0)."""
    for what, times in (("a scan", [s.t for s in log.scans]),
                        ("an odometry line", [o.t for o in log.odometry])):
        bad = next((t for t in times if not 0 <= t <= MAX_TIME_S), None)
        if bad is not None:
            raise LogError(f"{path}: {what} at {bad:g} s, outside what a ROS stamp holds "
                           f"(0 to {MAX_TIME_S} s)")


def _same_pose(a: Pose, b: Pose) -> bool:
    return math.hypot(a[0] - b[0], a[1] - b[1]) <= SAME_POSE_M \
        and abs(math.remainder(a[2] - b[2], math.tau)) <= SAME_POSE_RAD


def _restarts(scan: Scan, pose: Pose, t: float) -> bool:
    """Whether the first ODOM line after ``scan`` is a corrected log's restart at it."""
    return pose == scan.pose and (t <= 0 or t < scan.t)


def _out_of_order(odometry: list[OdometrySample]) -> int:
    """The lines a stable sort by time moves: all minus the longest subsequence in order."""
    ends: list[float] = []               # the least end of an ordered subsequence, by length
    for sample in odometry:
        index = bisect_right(ends, sample.t)
        if index == len(ends):
            ends.append(sample.t)
        else:
            ends[index] = sample.t
    return len(odometry) - len(ends)
