"""``smooth_lagged_data``: a late measurement put in its place, as if it had come in time.

The peer keeps the filter's state after each measurement for ``history_length``; when a
measurement older than the filter's time comes, it goes back to the last state before
it and processes the measurements since again. Here the filter's steps are the events of
the package's ``CausalOrder`` (core/causal_order.py), with the state before each kept
(references: the steps return new arrays):

- each measurement, at its stamp;
- each prediction the periodic step makes to its time (after ``sensor_timeout`` without
  input, or with ``predict_to_current_time``), at that time (``PredictTo``);
- each velocity command (``use_control``), at its stamp (``Command``).

A late measurement is applied in its place and every later event runs again, so the
estimate is what the same events give applied in time order: the filter run over them
sorted, exactly. The peer differs in two ways: its history holds no periodic
prediction, so a revert drops the predictions made since and its replay predicts over
their span in one step; and a command enters its replay as the latest one when each
measurement arrived, not at the command's own time.

A measurement older than everything the history holds (``history_length`` back from the
newest event, or ``MAX_EVENTS`` events) cannot be put in its place: it is corrected at
the filter's time, as without smoothing, and counted.
"""

from __future__ import annotations

from dataclasses import dataclass

from estimation_nodes.core.fusion.steps import Measurement
from estimation_nodes.core.validation import FloatArray

#: Events at one instant: a command first (it moves what follows), then the
#: measurements, then the periodic prediction to that instant (a no-op after them).
RANK_COMMAND, RANK_MEASUREMENT, RANK_PREDICTION = 0, 1, 2
#: The most events the history keeps, whatever ``history_length`` says: some 2 kB each
#: (the state before it), so 20 MB at most; 10,000 is 20 s of an IMU at 500 Hz.
MAX_EVENTS = 10_000


@dataclass
class Taken:
    """A measurement as an event, with what it was counted as the last time it ran
    (None before the first): a replay that takes one rejected before, or the reverse,
    moves its count rather than adding one."""

    measurement: Measurement
    accepted: bool | None = None


@dataclass(frozen=True)
class PredictTo:
    """The periodic step's prediction to ``stamp_ns``."""

    stamp_ns: int


@dataclass(frozen=True)
class Command:
    """A velocity command (vx, vy, vz, vroll, vpitch, vyaw) given at ``stamp_ns``."""

    command: FloatArray
    stamp_ns: int


@dataclass(frozen=True)
class Snapshot:
    """The filter's state before an event: what a step reads and writes."""

    x: FloatArray
    p: FloatArray
    #: The UKF's propagated sigma points (None: draw new ones).
    points: FloatArray | None
    initialized: bool
    last_time_ns: int
    #: The control term's (command, its time), None without ``use_control``.
    command: tuple[FloatArray, int] | None
