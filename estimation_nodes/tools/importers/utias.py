"""The UTIAS Multi-Robot Cooperative Localization and Mapping dataset (Leung et al. 2011).

A dataset folder holds, for each robot N, ``RobotN_Odometry.dat`` (t, v, w),
``RobotN_Measurement.dat`` (t, barcode, range, bearing) and
``RobotN_Groundtruth.dat`` (t, x, y, theta; Vicon), each possibly gzipped, and
``Barcodes.dat`` (subject, barcode) with ``Landmark_Groundtruth.dat`` (subject, x,
y, sd_x, sd_y). Subjects 1 to 5 are the robots, the others landmarks; the
barcode-to-subject mapping differs between datasets, so it is always read.
"""

from __future__ import annotations

import gzip
import io
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

#: Subjects 1 to 5 are robots: a detection of one is no landmark.
ROBOT_SUBJECTS = range(1, 6)


class DatasetError(Exception):
    """A dataset that cannot be read: the message names the file and says why."""


@dataclass
class UtiasRun:
    """One robot's run: odometry (t, v, w), landmark detections (t, subject, range,
    bearing), Vicon truth (t, x, y, theta), the landmarks (subject -> x, y), and what was
    left out of the detections (robots, unknown barcodes) and of the files (bad lines)."""

    odometry: np.ndarray
    detections: np.ndarray
    truth: np.ndarray
    landmarks: dict[int, tuple[float, float]]
    left_out: Counter[str] = field(default_factory=Counter)

    def frames(self) -> list[tuple[float, np.ndarray]]:
        """Detections grouped by time: one camera frame each, in time order."""
        times = self.detections[:, 0]
        starts = np.flatnonzero(np.r_[True, np.diff(times) != 0])
        ends = np.r_[starts[1:], len(times)]
        return [(float(times[a]), self.detections[a:b]) for a, b in zip(starts, ends)]


def _open(directory: Path, stem: str) -> str:
    for name in (f"{stem}.dat", f"{stem}.dat.gz"):
        path = directory / name
        if path.is_file():
            try:
                raw = path.read_bytes()
                return (gzip.decompress(raw) if name.endswith(".gz") else raw).decode("ascii")
            except (OSError, EOFError, UnicodeDecodeError, gzip.BadGzipFile) as error:
                raise DatasetError(f"{path}: cannot be read: {error}") from None
    raise DatasetError(f"{directory}: no {stem}.dat or {stem}.dat.gz")


def _table(directory: Path, stem: str, columns: int, left_out: Counter[str]) -> np.ndarray:
    """The file's rows of ``columns`` numbers; a malformed line is counted, not used."""
    rows, bad = [], 0
    for line in io.StringIO(_open(directory, stem)):
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        try:
            values = [float(v) for v in text.split()]
        except ValueError:
            bad += 1
            continue
        if len(values) != columns or not np.isfinite(values).all():
            bad += 1
            continue
        rows.append(values)
    if bad:
        left_out[f"malformed lines in {stem}"] += bad
    if not rows:
        raise DatasetError(f"{directory}: {stem} has no data line")
    return np.array(rows, dtype=np.float64)


def read_run(directory: Path, robot: int) -> UtiasRun:
    """Robot ``robot``'s run from a dataset folder."""
    directory = Path(directory)
    if robot not in ROBOT_SUBJECTS:
        raise DatasetError(f"--robot: expected 1 to 5, got {robot}")
    left_out: Counter[str] = Counter()
    barcodes = _table(directory, "Barcodes", 2, left_out)
    subject_of = {int(code): int(subject) for subject, code in barcodes}
    landmarks = {int(row[0]): (float(row[1]), float(row[2]))
                 for row in _table(directory, "Landmark_Groundtruth", 5, left_out)}
    odometry = _table(directory, f"Robot{robot}_Odometry", 3, left_out)
    raw = _table(directory, f"Robot{robot}_Measurement", 4, left_out)
    truth = _table(directory, f"Robot{robot}_Groundtruth", 4, left_out)
    subjects = np.array([subject_of.get(int(code), -1) for code in raw[:, 1]])
    is_robot = np.isin(subjects, list(ROBOT_SUBJECTS))
    unknown = ~is_robot & ~np.isin(subjects, list(landmarks))
    left_out["detections of robots"] += int(is_robot.sum())
    left_out["detections of unknown barcodes"] += int(unknown.sum())
    keep = ~is_robot & ~unknown
    detections = np.column_stack([raw[keep, 0], subjects[keep], raw[keep, 2], raw[keep, 3]])
    return UtiasRun(_in_time_order(odometry), _in_time_order(detections),
                    _in_time_order(truth), landmarks, left_out)


def _in_time_order(table: np.ndarray) -> np.ndarray:
    return table[np.argsort(table[:, 0], kind="stable")]
