"""The belief's support: the grid filter's steps over the box of states with probability.

A tracked robot's belief is zero on all but a few square metres of a building,
and a step never moves probability further than its motion and its noise
reach. So the filter runs over a window of (rows, columns), all headings:

- ``support_boxes``: disjoint boxes holding every state of nonzero probability,
  one per group of cells near each other: a second hypothesis across the
  building is a second small window, not one window over the building;
- ``grown_box``: a box after a prediction: grown by the motion's reach (the
  longest shift of any heading layer, plus the bilinear split's cell) and the
  blur's taps either side, cut to the grid; grown boxes that overlap are joined
  (``disjoint``), so each window's prediction gets all that can reach it, and
  the predictions are normalized together;
- the prediction runs on the window's crop of the belief and the map
  (``crop``), the correction scores the scan over the window only
  (``laser._scan_log_likelihood(..., box=)``).

This is exact: outside the grown box the dense filter's prediction is zero
(a blur or a shift of zeros), so its posterior is zero there as well, and
inside it the window's steps do the same arithmetic on the same numbers, the
grid's real edges included (a window's side that is not the grid's edge is
further from the support than anything spreads). Only sums run in another
order: the two agree to rounding (tests/unit/test_grid_window.py).

What makes the window small is ``drop_below``: the states whose probability
is below a floor are set to zero after a correction (the belief's far tails,
which the dense filter keeps as 1e-200 and the like). That is the one
approximation: at most floor x states of probability per update, reported.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from estimation_nodes.core.grid import failure
from estimation_nodes.core.errors import ZeroEvidenceError
from estimation_nodes.core.grid.correction import _weighted
from estimation_nodes.core.grid.laser import _scan_log_likelihood, _scan_log_likelihood_strided
from estimation_nodes.core.grid.model import GridModel
from estimation_nodes.core.grid.motion import OdometryNoise, _motion_noise, _reaching_taps
from estimation_nodes.core.validation import FloatArray

#: (first row, row past the last, first column, column past the last).
Box = tuple[int, int, int, int]
#: Single states: arrays of their headings, rows, columns and probabilities.
States = tuple[np.ndarray, np.ndarray, np.ndarray, FloatArray]


def full_box(model: GridModel) -> Box:
    rows, cols = model.free.shape
    return 0, rows, 0, cols


def support_box(belief: FloatArray) -> Box | None:
    """The box of every (row, column) with probability at some heading; None when the
    belief is zero everywhere."""
    layer = np.any(belief, axis=0)
    rows = np.flatnonzero(layer.any(axis=1))
    if rows.size == 0:
        return None
    cols = np.flatnonzero(layer.any(axis=0))
    return int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1


#: Supports closer than this many cells share a window: a window of its own costs a pass
#: of each step, worth it only for a mode apart from the rest.
JOIN_CELLS = 8
#: More separate supports than this are held in one window (their bounding box).
MAX_WINDOWS = 12


def support_boxes(footprint: np.ndarray) -> list[Box]:
    """Disjoint boxes holding every True cell of ``footprint`` (H, W): one per group of
    cells within JOIN_CELLS of each other (at most MAX_WINDOWS, else one box of all);
    empty when there is none."""
    if not footprint.any():
        return []
    joined = ndimage.binary_dilation(footprint, iterations=JOIN_CELLS // 2)
    labels, count = ndimage.label(joined, structure=np.ones((3, 3)))
    if count > MAX_WINDOWS:
        box = support_box(footprint[None])
        assert box is not None
        return [box]
    boxes = []
    for found in ndimage.find_objects(labels * footprint):
        if found is not None:
            rows, cols = found
            boxes.append((rows.start, rows.stop, cols.start, cols.stop))
    return disjoint(boxes)


def disjoint(boxes: list[Box]) -> list[Box]:
    """``boxes`` with every two that overlap replaced by the box of both, until none
    does: a state is then in one window only, and a window's steps see all the
    probability that can reach it."""
    boxes = list(boxes)
    merged = True
    while merged:
        merged = False
        for a in range(len(boxes)):
            for b in range(a + 1, len(boxes)):
                if _overlap(boxes[a], boxes[b]):
                    boxes[a] = _union(boxes[a], boxes[b])
                    del boxes[b]
                    merged = True
                    break
            if merged:
                break
    return boxes


def _overlap(a: Box, b: Box) -> bool:
    return a[0] < b[1] and b[0] < a[1] and a[2] < b[3] and b[2] < a[3]


def _union(a: Box, b: Box) -> Box:
    return min(a[0], b[0]), max(a[1], b[1]), min(a[2], b[2]), max(a[3], b[3])


def grown_box(box: Box, model: GridModel, delta: tuple[float, float, float],
              noise: OdometryNoise) -> Box:
    """Where a prediction with ``delta`` can put the probability now within ``box``."""
    rows, cols = model.free.shape
    trans = delta[1]
    # Every layer's shift is at most trans cells long in rows and in columns; the
    # bilinear split reaches one cell beyond its floor.
    reach = trans / model.resolution
    shift = math.ceil(reach) + 1 if reach < rows + cols else rows + cols
    sigma_cells, _ = _motion_noise(delta, noise, model)
    spread_rows = _reaching_taps(sigma_cells, rows).size // 2
    spread_cols = _reaching_taps(sigma_cells, cols).size // 2
    r0, r1, c0, c1 = box
    return (max(0, r0 - shift - spread_rows), min(rows, r1 + shift + spread_rows),
            max(0, c0 - shift - spread_cols), min(cols, c1 + shift + spread_cols))


def crop(model: GridModel, box: Box) -> GridModel:
    """The map within ``box``: its free cells and field, its origin at the box's corner."""
    r0, r1, c0, c1 = box
    origin = (model.origin[0] + c0 * model.resolution, model.origin[1] + r0 * model.resolution)
    # Contiguous copies: the compiled kernels were compiled for those (warm_up), and a view
    # would make numba compile another version mid-run, where a Ctrl-C cannot stop it
    # cleanly (core/compiled_loader.py).
    return GridModel(np.ascontiguousarray(model.free[r0:r1, c0:c1]),
                     np.ascontiguousarray(model.log_field[r0:r1, c0:c1]),
                     model.log_outside, model.resolution, origin, model.heading_bins,
                     model.laser_pose)


def window_of(belief: FloatArray, box: Box) -> FloatArray:
    r0, r1, c0, c1 = box
    return np.ascontiguousarray(belief[:, r0:r1, c0:c1])


def drop_below(belief: FloatArray, floor: float) -> tuple[FloatArray, float]:
    """The belief without the states of probability below ``floor``, renormalized, and
    the probability dropped (at most floor x the states). The largest state is never
    dropped, so the result is a belief whatever the floor."""
    if floor <= 0.0:
        return belief, 0.0
    dropped = zero_below(belief, min(floor, float(belief.max())))
    if dropped > 0.0:
        belief /= float(belief.sum())
    return belief, dropped


def zero_below(belief: FloatArray, threshold: float) -> float:
    """Set the states below ``threshold`` to 0, in place; their probability."""
    small = belief < threshold
    # Summed where small, not as belief[small]: that copy is most of a building's belief.
    dropped = float(np.sum(belief, where=small))
    belief[small] = 0.0
    return dropped


#: The kidnap lattice: every KIDNAP_STEP-th heading, row and column...
KIDNAP_STEP = 2
#: ...of which each update takes one of KIDNAP_PHASES interleaved parts, in turn: the
#: lattice's cells (i, j) with (i + j) % KIDNAP_PHASES == the update's phase.
KIDNAP_PHASES = 2


def lattice_cells(model: GridModel, phase: int) -> np.ndarray:
    """The free cells of the kidnap lattice's part ``phase`` (mod KIDNAP_PHASES), as a
    mask over the lattice's rows and columns (model.free[::KIDNAP_STEP, ::KIDNAP_STEP]).

    Over KIDNAP_PHASES updates in a row the parts cover the lattice once: a kidnapped
    robot is scored from a lattice cell within KIDNAP_STEP cells of it every update,
    and from the nearest one every KIDNAP_PHASES updates, at 1 / KIDNAP_PHASES of the
    cost of scoring the whole lattice with every scan (half of a tracked update's time
    on a building the size of the Intel lab's, bench/grid/real_buildings.py --profile).
    """
    free = model.free[::KIDNAP_STEP, ::KIDNAP_STEP]
    rows = np.arange(free.shape[0])[:, None]
    columns = np.arange(free.shape[1])[None, :]
    return free & ((rows + columns) % KIDNAP_PHASES == phase % KIDNAP_PHASES)


def correct_boxes(priors: list[FloatArray], boxes: list[Box], model: GridModel,
                  ranges: FloatArray, angles: FloatArray, weight: float, share: float,
                  floor: float, compiled: bool = True, phase: int = 0,
                  predicted: failure.Pose | None = None) -> Correction:
    """The correction of a belief held in disjoint ``boxes`` (``priors``: each box's part,
    zero elsewhere). With ``share`` > 0 the prior is (1 - share) x that belief plus
    ``share`` spread evenly over the free states of a coarse lattice's part ``phase``
    (every KIDNAP_STEP-th heading, row and column, then one cell in KIDNAP_PHASES of
    those: ``lattice_cells``), so that a kidnapped robot is found by its scans at the
    cost of scoring that part, not every state. (The next prediction's blur spreads
    what the lattice finds.)

    The lattice's posterior within the boxes joins theirs; outside them its states of
    probability ``floor`` or more are kept (``Correction.kept``) and the rest, all below
    the floor, left out (``Correction.left_out``, the whole renormalized over the rest).

    With ``predicted`` (the predicted pose) the lattice's states around it also give the
    posterior of the odometry failing (``failure.astray_in``: ``Correction.astray``).
    """
    step = KIDNAP_STEP
    lattice_free = lattice_cells(model, phase)
    free_states = int(lattice_free.sum()) * -(-model.heading_bins // step)
    lls = [_scan_log_likelihood(model, ranges, angles, compiled, box) for box in boxes]
    lattice_ll = None
    if share > 0.0 and free_states > 0:
        lattice_ll = _scan_log_likelihood_strided(model, ranges, angles, step, compiled,
                                                  cells=lattice_free)
    for ll in [*lls, *([lattice_ll] if lattice_ll is not None else [])]:
        if weight != 1.0:
            np.multiply(ll, weight, out=ll)
    peak = max(float(ll[prior > 0].max(initial=-math.inf)) for ll, prior in zip(lls, priors))
    if lattice_ll is not None:
        peak = max(peak, float(np.max(lattice_ll, where=lattice_free[None],
                                      initial=-math.inf)))
    if not math.isfinite(peak):
        raise ZeroEvidenceError("every state with probability rules the scan out")
    parts = []
    for ll, prior in zip(lls, priors):
        weighted, _ = _weighted(ll, peak, prior)
        if share > 0.0:
            weighted *= 1.0 - share
        parts.append(weighted)
    total = sum(float(part.sum()) for part in parts)
    astray = None
    if lattice_ll is not None:
        lattice, found = _weighted(lattice_ll, peak, lattice_free)
        total += found * share / free_states
        if predicted is not None and total > 0.0:
            astray = failure.astray_in(model, lattice, step, lattice_free, total,
                                      predicted)
        lattice *= share / free_states
    if not total > 0.0:
        raise ZeroEvidenceError("every state with probability rules the scan out")
    log_evidence = peak + math.log(total)
    for part in parts:
        part /= total
    if lattice_ll is None:
        return Correction(parts, boxes, _no_states(), log_evidence, 0.0)
    lattice /= total
    kept, left_out, kidnapped = _lattice_into(parts, boxes, lattice, floor)
    if left_out > 0.0:
        remaining = sum(float(part.sum()) for part in parts) + float(kept[3].sum())
        for part in parts:
            part /= remaining
        kept = (kept[0], kept[1], kept[2], kept[3] / remaining)
    return Correction(parts, boxes, kept, log_evidence, left_out, kidnapped, astray)


@dataclass
class Correction:
    """A posterior held in windows: each box's part, and single states outside them
    (``kept``: arrays of headings, rows, columns and probabilities)."""

    parts: list[FloatArray]
    boxes: list[Box]
    kept: States
    log_evidence: float
    #: The probability of the lattice states left out (each below the floor).
    left_out: float
    #: The posterior probability of the kidnap share (0 without one): that the scan was
    #: explained by a place the robot was carried to, not by the tracked belief.
    kidnapped: float = 0.0
    #: The odometry-failure component's posterior (grid/failure.py), where asked for.
    astray: failure.Astray | None = None


def _no_states() -> States:
    empty = np.zeros(0, dtype=np.int64)
    return empty, empty, empty, np.zeros(0)


def _lattice_into(parts: list[FloatArray], boxes: list[Box], lattice: FloatArray,
                  floor: float) -> tuple[States, float, float]:
    """Add the lattice's posterior within each box to that box's part; of the rest, the
    states of ``floor`` or more (headings, rows, columns, probabilities) and the
    probability of those left out; and the lattice's whole posterior probability."""
    step = KIDNAP_STEP
    covered = np.zeros(lattice.shape[1:], dtype=bool)
    inside = 0.0
    for part, (r0, r1, c0, c1) in zip(parts, boxes):
        # The lattice rows and columns within the box, and where they fall in it.
        i0, i1 = -(-r0 // step), -(-r1 // step)
        j0, j1 = -(-c0 // step), -(-c1 // step)
        within = lattice[:, i0:i1, j0:j1]
        part[::step, step * i0 - r0::step, step * j0 - c0::step] += within
        inside += float(within.sum())
        covered[i0:i1, j0:j1] = True
    # Passes over the lattice (an eighth of the building's states) kept to two: a sum and
    # a comparison.
    chosen = lattice >= floor if floor > 0 else lattice > 0
    chosen &= ~covered[None]
    k, i, j = np.nonzero(chosen)
    values = lattice[k, i, j]
    everything = float(lattice.sum())
    left_out = max(everything - inside - float(values.sum()), 0.0)
    return (step * k, step * i, step * j, values), left_out, everything
