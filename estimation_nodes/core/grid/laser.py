"""The likelihood-field sensor model over the grid (Probabilistic Robotics 6.4): a laser
scan's log likelihood for every state, and the correction by a scan. The field it reads
is made from the map by likelihood_field.py.

- ``scan_log_likelihood``: for each beam and heading the end point is the
  same cell offset from every state cell, so the log likelihood of a beam
  over one heading layer is a shifted view of the log likelihood field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from estimation_nodes.core.errors import InputSizeError, InvalidInputError
from estimation_nodes.core.grid.correction import _correct_in
from estimation_nodes.core.grid.model import (
    GridModel,
    _check_model,
    _states,
    check_belief,
    compiled_kernels,
)
from estimation_nodes.core.validation import FloatArray, as_real_array, check_integer

#: A scan's sum of log likelihoods stays within this (beams x the largest |log likelihood|
#: of the model), so it never overflows.
LOG_SUM_LIMIT = 1e300


def check_scan(ranges: Any, angles: Any) -> tuple[FloatArray, FloatArray]:
    """The beams of a scan to score, checked: (ranges, angles), one angle (rad, from the
    robot's heading) per range (m), as float arrays.

    Every range given is scored as a reading that hit something at that distance. A
    laser's "no return" is not such a reading: REP 117's +inf (nothing within
    range_max), -inf (closer than range_min) and NaN (no valid measurement), a negative
    value, and a reading at or beyond the sensor's range_max (which the core does not
    know). The caller leaves those beams out first, as the nodes' ``scan_beams``
    (nodes/grid_messages.py) does; given one anyway, a NaN, infinite or negative range
    is refused (``InvalidInputError`` naming ``ranges`` and the beam) rather than
    silently dropped, so a caller that forgot to select its beams learns it at once
    instead of scoring fewer beams than it thinks. A finite range longer than the map
    ends off the map from every state cell (``log_outside``); the work and the memory
    do not grow with it. No beams at all are a scan that says nothing: the correction
    leaves the belief as it was.
    """
    r = as_real_array("ranges", ranges)
    a = as_real_array("angles", angles)
    if r.ndim != 1 or a.ndim != 1:
        raise InputSizeError(f"ranges and angles: expected two lists of numbers, got shapes "
                             f"{r.shape} and {a.shape}")
    if r.size != a.size:
        raise InputSizeError(f"ranges and angles: expected one angle per range, got "
                             f"{r.size} ranges and {a.size} angles")
    if r.size and not (r.min() >= 0.0 and r.max() < math.inf):   # NaN fails both
        beam = int(np.flatnonzero(~(r >= 0.0) | ~(r < math.inf))[0])
        raise InvalidInputError(
            f"ranges: expected finite readings >= 0, got {float(r[beam])!r} at beam {beam} "
            f"(leave out the beams of no return: NaN, inf, negative, at or beyond range_max)")
    if a.size and not np.isfinite(a).all():
        beam = int(np.flatnonzero(~np.isfinite(a))[0])
        raise InvalidInputError(
            f"angles: expected finite numbers, got {float(a[beam])!r} at beam {beam}")
    return r, a


def beam_endpoints(model: GridModel, ranges: FloatArray, angles: FloatArray) -> np.ndarray:
    """(K, beams, 2) integer (row, column) offsets of each beam's end point from the
    state cell, for each heading bin: the cell the end point falls in, measured from
    the state cell's centre. Offsets are cut to the map's size (rows, columns): an end
    point that far is off the map from every state cell, however far it is."""
    return _beam_endpoints(_check_model(model), *check_scan(ranges, angles))


def _beam_endpoints(model: GridModel, ranges: FloatArray, angles: FloatArray) -> np.ndarray:
    rows, cols = model.free.shape
    headings = model.headings()
    mount_x, mount_y, mount_yaw = model.laser_pose
    theta = (headings + mount_yaw)[:, None] + angles[None, :]
    # Where the laser sits, in cells from the state cell's centre, for each heading (0 for
    # a laser at the centre: the sums below are then the same bits as without it).
    mount_rows = ((mount_x * np.sin(headings) + mount_y * np.cos(headings))
                  / model.resolution)[:, None]
    mount_cols = ((mount_x * np.cos(headings) - mount_y * np.sin(headings))
                  / model.resolution)[:, None]
    # A beam of rows + cols cells or more is longer than the map's diagonal: it ends off
    # the map from every state cell, as it does at that length, which keeps the products
    # finite (a range of 1e300 m in cells may overflow, and inf * sin(0) is NaN).
    with np.errstate(over="ignore"):
        r = np.minimum(ranges[None, :] / model.resolution, float(rows + cols))
    ends = np.stack([np.clip(np.floor(0.5 + (mount_rows + r * np.sin(theta))), -rows, rows),
                     np.clip(np.floor(0.5 + (mount_cols + r * np.cos(theta))), -cols, cols)],
                    axis=-1)
    return ends.astype(np.int64)


def scan_log_likelihood(model: GridModel, ranges: FloatArray, angles: FloatArray,
                        compiled: bool = True) -> FloatArray:
    """Sum over the beams of log p(beam | state), for every state: (K, H, W).

    ``ranges`` and ``angles`` are the beams to use, without the readings of no return
    (``check_scan`` says which and what happens to them).
    """
    _check_model(model)
    return _scan_log_likelihood(model, *check_scan(ranges, angles), compiled)


@dataclass(frozen=True)
class ScanReads:
    """Where a scan's beams read the log field: each heading's end point offsets (K,
    beams, 2) from the state cell, and the field padded by ``log_outside`` for them
    (``_padded_field``). Made once per scan, read by the windows' and the lattice's
    scores alike."""

    offsets: np.ndarray
    padded: FloatArray
    pad_rows: int
    pad_cols: int


def _scan_reads(model: GridModel, ranges: FloatArray, angles: FloatArray) -> ScanReads:
    if ranges.size * model.log_bound > LOG_SUM_LIMIT:
        raise InvalidInputError(f"ranges: {ranges.size} beams over log likelihoods as large "
                                f"as {model.log_bound:g} would overflow their sum")
    offsets = _beam_endpoints(model, ranges, angles)
    return ScanReads(offsets, *_padded_field(model, offsets))


def _scan_log_likelihood(model: GridModel, ranges: FloatArray, angles: FloatArray,
                         compiled: bool = True,
                         box: tuple[int, int, int, int] | None = None,
                         headings: np.ndarray | None = None,
                         reads: ScanReads | None = None,
                         free_only: bool = False) -> FloatArray:
    """The scan's log likelihood over every state, or over the states of the window
    ``box`` (first row, row past the last, first column, column past the last; see
    grid/window.py): (K, rows, columns) of the box; with ``headings`` (bin indices) at
    those heading layers only, in that order. The compiled kernels or numpy's are
    chosen by the grid's states, not the box's: numpy's cost a pass per heading and
    beam, whatever the box's size. ``reads``: the scan's, when already made.
    ``free_only``: scored on the free cells alone (the same bits), -inf elsewhere: a
    belief is zero there, and a building's box is mostly walls and unknown space."""
    reads = reads if reads is not None else _scan_reads(model, ranges, angles)
    offsets = reads.offsets if headings is None else \
        np.ascontiguousarray(reads.offsets[headings])
    r0, r1, c0, c1 = box if box is not None else (0, model.free.shape[0], 0,
                                                  model.free.shape[1])
    # The window's cell (i, j) is the map's (r0 + i, c0 + j): the same field, read
    # from further in.
    padded, pad_rows, pad_cols = reads.padded, reads.pad_rows + r0, reads.pad_cols + c0
    rows, cols = r1 - r0, c1 - c0
    shape = (offsets.shape[0], rows, cols)
    kernels = compiled_kernels(_states(model), compiled)
    if kernels is not None:
        out = np.empty(shape)      # the kernel writes every element
        if free_only:
            kernels.scan_log_likelihood_runs(padded, pad_rows, pad_cols, offsets, shape[0],
                                             rows, *_free_runs(model.free[r0:r1, c0:c1]), out)
        else:
            kernels.scan_log_likelihood(padded, pad_rows, pad_cols, offsets, shape[0],
                                        rows, cols, out)
        return out
    total = np.zeros(shape)
    for k in range(shape[0]):
        layer = total[k]
        for dr, dc in offsets[k]:
            layer += padded[pad_rows + dr:pad_rows + dr + rows, pad_cols + dc:pad_cols + dc + cols]
    if free_only:
        total[:, ~model.free[r0:r1, c0:c1]] = -np.inf
    return total


def _free_runs(free: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The runs of True along each row of ``free``: row i's are columns starts[n]:stops[n]
    for n in row_runs[i]:row_runs[i + 1]."""
    edges = np.diff(free.astype(np.int8), axis=1, prepend=0, append=0)
    run_rows, starts = np.nonzero(edges == 1)
    _, stops = np.nonzero(edges == -1)
    row_runs = np.zeros(free.shape[0] + 1, dtype=np.int64)
    np.cumsum(np.bincount(run_rows, minlength=free.shape[0]), out=row_runs[1:])
    return row_runs, starts.astype(np.int64), stops.astype(np.int64)


#: How many beams a listed state's sum takes between two looks at its bound (compiled.py's
#: CHECK_EVERY: both paths stop the same sums).
CHECK_EVERY = 2


def _scan_log_likelihood_cells(model: GridModel, reads: ScanReads, step: int,
                               rows: np.ndarray, cols: np.ndarray,
                               below: FloatArray | None = None,
                               compiled: bool = True) -> tuple[FloatArray, np.ndarray]:
    """The scan's log likelihood at every ``step``-th heading and at the cells (rows[n],
    cols[n]) only: (ceil(K / step), n), element [k, n] the state (step k, rows[n],
    cols[n]) of ``_scan_log_likelihood``, in its order of sums (the same bits). The
    kidnap lattice's states, listed: no pass over the cells it leaves out.

    With ``below`` (one log likelihood per cell), a state whose first beams already make
    its sum less than below[n] with every beam left scoring the field's largest value is
    not scored further: its element is that upper bound instead, and False in the second
    array returned (True where the sum is the state's log likelihood)."""
    padded = reads.padded
    width = padded.shape[1]
    offsets = reads.offsets[::step]
    # Offsets and cells as positions in the flattened padded field.
    flat_offsets = np.ascontiguousarray(offsets[..., 0] * width + offsets[..., 1])
    starts = np.ascontiguousarray((reads.pad_rows + rows) * width + reads.pad_cols + cols,
                                  dtype=np.int64)
    below = np.full(starts.size, -math.inf) if below is None else \
        np.ascontiguousarray(below, dtype=np.float64)
    most = max(float(model.log_field.max()), model.log_outside)
    beams = flat_offsets.shape[1]
    order = _spread_order(beams)
    field = padded.ravel()
    out = np.empty((offsets.shape[0], starts.size))
    scored = np.ones(out.shape, dtype=bool)
    kernels = compiled_kernels(_states(model), compiled)   # as the grid's other steps
    if kernels is not None:
        kernels.scan_log_likelihood_cells(field, starts, flat_offsets, below, most, order,
                                          out, scored)
        return out, scored
    bounded = below > -math.inf
    for k in range(out.shape[0]):
        total, going = np.zeros(starts.size), bounded.copy()
        for m, offset in enumerate(flat_offsets[k][order]):
            total[going] += field[starts[going] + offset]
            if m % CHECK_EVERY == CHECK_EVERY - 1:
                stops = going & (total + (beams - 1 - m) * most < below)
                total[stops] += (beams - 1 - m) * most
                going &= ~stops
                scored[k, stops] = False
        summed = scored[k]
        total[summed] = 0.0
        for offset in flat_offsets[k]:
            total[summed] += field[starts[summed] + offset]
        out[k] = total
    return out, scored


#: The beams' order for a bound: every SPREAD-th beam first, then the next of each.
SPREAD = 6


def _spread_order(beams: int) -> np.ndarray:
    """0, SPREAD, 2 SPREAD, ..., 1, 1 + SPREAD, ...: neighbouring beams say much the same,
    so the first few of this order tell a wrong state sooner than the first few of the
    scan."""
    return np.concatenate([np.arange(first, beams, SPREAD) for first in range(SPREAD)]) \
        .astype(np.int64)


#: The padded field's border grows in steps of this many cells, so that the scans of one
#: map mostly share one padded field (``_padded_field``'s cache).
PAD_STEP = 64
#: Padded fields kept: one per map in use (a process may hold several localizers).
PADDED_KEPT = 4
_padded: dict[int, tuple[FloatArray, int, int, FloatArray]] = {}


def _padded_field(model: GridModel, offsets: np.ndarray) -> tuple[FloatArray, int, int]:
    """The log field with a border of ``log_outside`` wide enough for every offset: at
    most (3 H + 2) x (3 W + 2) values, since the offsets are cut to the map's size. Made
    once per map and border (the border rounded up to PAD_STEP cells), not per scan: a
    building's is megabytes."""
    rows, cols = model.log_field.shape
    needed_rows = int(np.abs(offsets[..., 0]).max(initial=0)) + 1
    needed_cols = int(np.abs(offsets[..., 1]).max(initial=0)) + 1
    key = id(model.log_field)
    cached = _padded.get(key)
    if cached is not None and cached[0] is model.log_field and cached[1] >= needed_rows \
            and cached[2] >= needed_cols:
        return cached[3], cached[1], cached[2]
    pad_rows = min(-(-needed_rows // PAD_STEP) * PAD_STEP, rows + 1)
    pad_cols = min(-(-needed_cols // PAD_STEP) * PAD_STEP, cols + 1)
    padded = np.pad(model.log_field, ((pad_rows, pad_rows), (pad_cols, pad_cols)),
                    constant_values=model.log_outside)
    if len(_padded) >= PADDED_KEPT and key not in _padded:
        _padded.pop(next(iter(_padded)))
    _padded[key] = (model.log_field, pad_rows, pad_cols, padded)
    return padded, pad_rows, pad_cols


def correct_scan(belief: FloatArray, model: GridModel, ranges: FloatArray, angles: FloatArray,
                 compiled: bool = True,
                 independent_beams: int | None = None) -> tuple[FloatArray, float]:
    """``correct`` with a scan: posterior and log evidence. (A compiled kernel that also
    weighted each row as soon as its beams were summed measured slower: numba's scalar exp
    costs more than the pass numpy's vectorized one needs.)

    ``independent_beams`` K: the scan counts as K independent beams, not N (see
    ``scan_weight``); None: every beam is independent of the others."""
    _check_model(model)
    belief = check_belief(belief, model)
    ranges, angles = check_scan(ranges, angles)
    weight = 1.0 if independent_beams is None else scan_weight(independent_beams, ranges.size)
    return _correct_scan(belief, model, ranges, angles, compiled, weight)


def scan_weight(independent_beams: int, beams: int) -> float:
    """min(1, K / N): the power the likelihood of N beams is raised to when they carry the
    information of K independent ones (a tempered likelihood). Neighbouring beams' errors
    are correlated (the same grid's heading and position quantization, the same odometry
    error, the same unmapped object), so the product of N beam likelihoods is far sharper
    than what the scan tells; AMCL's beam skipping and Thrun et al.'s advice to use a
    subset of beams are the same remedy."""
    independent_beams = check_integer("independent_beams", independent_beams)
    if independent_beams < 1:
        raise InvalidInputError(f"independent_beams: expected >= 1, got {independent_beams}")
    return min(1.0, independent_beams / beams) if beams else 1.0


def _correct_scan(belief: FloatArray, model: GridModel, ranges: FloatArray, angles: FloatArray,
                  compiled: bool = True, weight: float = 1.0,
                  box: tuple[int, int, int, int] | None = None) -> tuple[FloatArray, float]:
    """``correct_scan`` of arguments already checked; with ``box``, ``belief`` is the
    window's (grid/window.py), zero outside it."""
    def log_likelihood() -> FloatArray:
        total = _scan_log_likelihood(model, ranges, angles, compiled, box)
        if weight != 1.0:
            np.multiply(total, weight, out=total)
        return total

    return _correct_in(log_likelihood(), belief, log_likelihood)
