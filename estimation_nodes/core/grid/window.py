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
from typing import NamedTuple

import numpy as np
from scipy import ndimage

from estimation_nodes.core.grid import failure
from estimation_nodes.core.errors import ZeroEvidenceError
from estimation_nodes.core.grid.correction import _weighted
from estimation_nodes.core.grid.laser import (
    _scan_log_likelihood,
    ScanReads,
    _scan_log_likelihood_cells,
    _scan_reads,
)
from estimation_nodes.core.grid.model import GridModel
from estimation_nodes.core.grid.motion import (
    OdometryNoise,
    _bounded_shifts,
    _motion_noise,
    _reaching_taps,
)
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
#: At most this many windows: more groups of supports are joined with their nearest
#: (``support_boxes``).
MAX_WINDOWS = 12


def support_boxes(footprint: np.ndarray) -> list[Box]:
    """Disjoint boxes holding every True cell of ``footprint`` (H, W): one per group of
    cells within JOIN_CELLS of each other; empty when there is none.

    More groups than MAX_WINDOWS (a global start's belief after its first scans, a kidnap
    lattice's many kept states) are joined with their nearest, the distance that joins
    two groups doubled until at most MAX_WINDOWS are left: the windows then hold the
    groups and what lies between near ones, not the building's box."""
    whole = support_box(footprint[None])
    if whole is None:
        return []
    reach = JOIN_CELLS // 2
    # The groups within the support's box grown by the reach: the same as over the grid,
    # at the cost of the box (a tracked robot's few metres, not the building).
    rows, cols = footprint.shape
    r0, c0 = max(whole[0] - reach, 0), max(whole[2] - reach, 0)
    near = footprint[r0:min(whole[1] + reach, rows), c0:min(whole[3] + reach, cols)]
    joined = ndimage.binary_dilation(near, iterations=reach)
    labels, count = ndimage.label(joined, structure=np.ones((3, 3)))
    if count > MAX_WINDOWS:
        # The dilation's reach as a distance (taxicab: its cross-shaped steps).
        r0 = c0 = 0
        near = footprint
        distance = ndimage.distance_transform_cdt(~footprint, metric="taxicab")
        while count > MAX_WINDOWS:
            reach *= 2
            labels, count = ndimage.label(distance <= reach, structure=np.ones((3, 3)))
    boxes = []
    for found in ndimage.find_objects(labels * near):
        if found is not None:
            box_rows, box_cols = found
            boxes.append((r0 + box_rows.start, r0 + box_rows.stop, c0 + box_cols.start,
                          c0 + box_cols.stop))
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
              noise: OdometryNoise, headings: np.ndarray | None = None) -> Box:
    """Where a prediction with ``delta`` can put the probability now within ``box``; with
    ``headings`` (the heading layers holding it), where those layers' own shifts put it.

    A layer moves by its own heading's shift before the headings are turned and blurred
    (motion.py), so a window holding a few headings (a tracked robot's, a single state
    the kidnap lattice kept) grows in their directions only, not by the motion's length
    every way: a metre's motion grows such a window about 4 times less."""
    rows, cols = model.free.shape
    sigma_cells, _ = _motion_noise(delta, noise, model)
    spread_rows = _reaching_taps(sigma_cells, rows).size // 2
    spread_cols = _reaching_taps(sigma_cells, cols).size // 2
    low_r, high_r, low_c, high_c = _shift_range(model, delta, headings)
    r0, r1, c0, c1 = box
    return (max(0, r0 + low_r - spread_rows), min(rows, r1 + high_r + spread_rows),
            max(0, c0 + low_c - spread_cols), min(cols, c1 + high_c + spread_cols))


def _shift_range(model: GridModel, delta: tuple[float, float, float],
                 headings: np.ndarray | None) -> tuple[int, int, int, int]:
    """The fewest and most rows and columns the layers ``headings`` (all: None) move by
    (0 included), the bilinear split's cell beyond the floor of the longest included."""
    rows, cols = model.free.shape
    if headings is None or headings.size == 0:
        # Every layer's shift is at most trans cells long in rows and in columns.
        reach = delta[1] / model.resolution
        shift = math.ceil(reach) + 1 if reach < rows + cols else rows + cols
        return -shift, shift, -shift, shift
    # The kernels' own shifts (motion._bounded_shifts), floored as they floor them.
    shift_rows, shift_cols = _bounded_shifts(model, delta[0], delta[1])
    floor_rows = np.floor(shift_rows[headings])
    floor_cols = np.floor(shift_cols[headings])
    # The box holds where the probability is too: the prediction runs on the grown box.
    return (min(0, int(floor_rows.min())), max(0, int(floor_rows.max()) + 1),
            min(0, int(floor_cols.min())), max(0, int(floor_cols.max()) + 1))


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
        # Only the states left are written: a zero's memory page need not become resident.
        np.divide(belief, float(belief.sum()), out=belief, where=belief != 0.0)
    return belief, dropped


def zero_below(belief: FloatArray, threshold: float) -> float:
    """Set the states below ``threshold`` to 0, in place; their probability."""
    small = belief < threshold
    # Summed where small, not as belief[small]: that copy is most of a building's belief.
    dropped = float(np.sum(belief, where=small))
    small &= belief != 0.0    # zeros left unwritten: their memory need not become resident
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
                  increment: failure.Increment | None = None) -> Correction:
    """The correction of a belief held in disjoint ``boxes`` (``priors``: each box's part,
    zero elsewhere). With ``share`` > 0 the prior is (1 - share) x that belief plus
    ``share`` spread evenly over the free states of a coarse lattice's part ``phase``
    (every KIDNAP_STEP-th heading, row and column, then one cell in KIDNAP_PHASES of
    those: ``lattice_cells``), so that a kidnapped robot is found by its scans at the
    cost of scoring that part, not every state. (The next prediction's blur spreads
    what the lattice finds.)

    A window's heading layers without probability are not scored (their posterior is 0
    whatever the scan), and the lattice's states are scored as a list
    (``laser._scan_log_likelihood_cells``): the passes follow the states that can hold
    probability, not the boxes' and the lattice's tensors.

    The lattice's posterior within the boxes joins theirs; outside them its states of
    probability ``floor`` or more are kept (``Correction.kept``) and the rest, all below
    the floor, left out (``Correction.left_out``, the whole renormalized over the rest).

    With the odometry's ``increment`` (the last update's pose and the predicted one) the
    lattice's states around it also give the posterior of the odometry failing
    (``failure.astray_in``: ``Correction.astray``).
    """
    reads = _scan_reads(model, ranges, angles)
    held = [_held_headings(prior) for prior in priors]
    lls = [_scan_log_likelihood(model, ranges, angles, compiled, box, headings, reads,
                                free_only=_mostly_not_free(model, box))
           for box, headings in zip(boxes, held)]
    held_priors = [prior if headings is None else prior[headings]
                   for prior, headings in zip(priors, held)]
    for ll in lls:
        if weight != 1.0:
            np.multiply(ll, weight, out=ll)
    peak = max((float(np.max(ll, where=prior > 0, initial=-math.inf))
                for ll, prior in zip(lls, held_priors)), default=-math.inf)
    parts = _weighted_parts(lls, held_priors, priors, held, peak, 1.0 - share)
    total = sum(float(part.sum()) for part in parts)
    lattice = _lattice_weights(model, reads, boxes, phase, weight, share, floor, peak, total,
                               compiled, increment)
    if lattice is not None and lattice.peak > peak:
        # A lattice state beats the windows' best: every weight relative to it.
        scale = math.exp(peak - lattice.peak) if math.isfinite(peak) else 0.0
        for part in parts:
            part *= scale
        total *= scale
        peak = lattice.peak
    if not math.isfinite(peak):
        raise ZeroEvidenceError("every state with probability rules the scan out")
    astray = None
    if lattice is not None:
        lattice.relative_to(peak)
        total += float(lattice.weights.sum())
        if lattice.reach is not None and total > 0.0:
            astray = lattice.astray(model, total)
    if not total > 0.0:
        raise ZeroEvidenceError("every state with probability rules the scan out")
    log_evidence = peak + math.log(total)
    for part in parts:
        part /= total
    if lattice is None:
        return Correction(parts, boxes, _no_states(), log_evidence, 0.0)
    kept, left_out, kidnapped = _lattice_into(parts, boxes, lattice, lattice.weights / total,
                                              floor)
    # The states not scored to the end, at their bounds: neither probability is understated.
    unscored = lattice.unscored / total
    left_out += unscored
    kidnapped += unscored
    if left_out > 0.0:
        remaining = sum(float(part.sum()) for part in parts) + float(kept[3].sum())
        for part in parts:
            part /= remaining
        kept = (kept[0], kept[1], kept[2], kept[3] / remaining)
    return Correction(parts, boxes, kept, log_evidence, left_out, kidnapped, astray)


def _weighted_parts(lls: list[FloatArray], held_priors: list[FloatArray],
                    priors: list[FloatArray], held: list[np.ndarray | None], peak: float,
                    scale: float) -> list[FloatArray]:
    """Each window's prior x exp(log likelihood - peak) x scale, over all its headings
    (0 at those not scored), written over the log likelihoods; zeros where ``peak`` is
    -inf (no state with probability explains the scan at all)."""
    parts = []
    for ll, prior, whole, headings in zip(lls, held_priors, priors, held):
        if not math.isfinite(peak):
            parts.append(np.zeros(whole.shape))
            continue
        weighted, _ = _weighted(ll, peak, prior)
        if scale != 1.0:
            weighted *= scale
        if headings is not None:
            part = np.zeros(whole.shape)
            part[headings] = weighted
            weighted = part
        parts.append(weighted)
    return parts


#: A lattice state outside the windows is scored beam by beam only while its bound (the
#: beams so far, every beam left a perfect hit) could give it belief_floor x this share of
#: the posterior: below that it would be dropped, and its bound is what it may hold.
UNSCORED_SHARE = 1e-3


@dataclass
class LatticeWeights:
    """The kidnap lattice's part of a correction: its listed cells (rows, columns), the
    states scored to the end (``scored_states``: flat indices into (heading, cell), the
    lattice's every KIDNAP_STEP-th heading by its cells) with their weights share /
    states x exp(log likelihood) (``weights``, one per scored state: a few in a thousand
    of the lattice's, the rest 0 with their sum at most ``unscored``), and the largest
    log likelihood among them (the weights relative to ``peak`` once ``relative_to``
    ran)."""

    rows: np.ndarray
    cols: np.ndarray
    scored_states: np.ndarray
    #: The scored states' log likelihoods, weights once ``relative_to`` ran.
    weights: FloatArray
    #: How many states were not scored to the end, and the largest of their bounds.
    unscored_count: int
    unscored_peak: float
    per_state: float
    peak: float
    #: The cells within the odometry-failure component's reach, where it is asked for.
    reach: failure.Reach | None = None
    unscored: float = 0.0

    def states(self) -> tuple[np.ndarray, np.ndarray]:
        """The scored states' lattice heading indices and cell indices."""
        return np.divmod(self.scored_states, self.rows.size)

    def astray(self, model: GridModel, tracked: float) -> failure.Astray:
        """The odometry-failure component, once ``relative_to`` ran (``tracked``: the rest
        of the mixture's evidence): from the states scored to the end, the only ones
        with a weight."""
        assert self.reach is not None
        k, n = self.states()
        headings = model.headings()[::KIDNAP_STEP]
        return failure.astray_in(headings, k, n, self.weights, tracked, self.reach,
                                 1.0 / self.per_state)

    def relative_to(self, peak: float) -> None:
        """Weights relative to ``peak``: the scored states' from their log likelihoods, the
        others' sum bounded by their count x their largest bound."""
        values = self.weights
        np.subtract(values, peak, out=values)
        np.exp(values, out=values)
        values *= self.per_state
        if self.unscored_count:
            self.unscored = self.per_state * self.unscored_count * math.exp(
                self.unscored_peak - peak)


class LatticeList(NamedTuple):
    """The cells of a lattice part: rows and columns of the grid, and their centres (m)."""

    rows: np.ndarray
    cols: np.ndarray
    x: FloatArray
    y: FloatArray


#: The lattice parts' cells of the maps in use: (free, phase) -> (free, their list).
_lattice_lists: dict[tuple[int, int], tuple[np.ndarray, LatticeList]] = {}


def _lattice_list(model: GridModel, phase: int) -> LatticeList:
    """The cells of ``lattice_cells(model, phase)``: made once per map and part, not at
    every update."""
    key = (id(model.free), phase % KIDNAP_PHASES)
    cached = _lattice_lists.get(key)
    if cached is None or cached[0] is not model.free:
        if len(_lattice_lists) >= 4 * KIDNAP_PHASES:
            _lattice_lists.clear()
        rows, cols = (KIDNAP_STEP * index for index in np.nonzero(lattice_cells(model, phase)))
        xs, ys = model.cell_centres()
        listed = LatticeList(rows, cols, xs[cols], ys[rows])
        for array in listed:
            array.flags.writeable = False     # shared by the updates
        cached = _lattice_lists[key] = (model.free, listed)
    return cached[1]


def _lattice_weights(model: GridModel, reads: ScanReads, boxes: list[Box], phase: int,
                     weight: float, share: float, floor: float, peak: float,
                     total: float, compiled: bool = True,
                     increment: failure.Increment | None = None) -> LatticeWeights | None:
    """The lattice part ``phase``'s weighted log likelihoods (None without a share or a
    free lattice cell). ``peak`` and ``total``: the windows' largest weighted log
    likelihood and their weights' sum relative to it, which bound the posterior of a
    lattice state from above: the lattice only adds to the sum."""
    step = KIDNAP_STEP
    listed = _lattice_list(model, phase)
    rows, cols = listed.rows, listed.cols
    per_state = share / (rows.size * -(-model.heading_bins // step)) if rows.size else 0.0
    if not (share > 0.0 and rows.size > 0):
        return None
    inside = np.zeros(rows.size, dtype=bool)
    for r0, r1, c0, c1 in boxes:
        inside |= (rows >= r0) & (rows < r1) & (cols >= c0) & (cols < c1)
    below = np.full(rows.size, -math.inf)
    if floor > 0.0 and total > 0.0 and math.isfinite(peak):
        # weight x bound < peak + log(floor x share x total / per_state): the posterior
        # (per_state exp(weight x ll - peak) / total) is below floor x UNSCORED_SHARE.
        below[~inside] = (peak + math.log(floor * UNSCORED_SHARE * total / per_state)) / weight
    reach = None if increment is None else failure.reach_of(listed.x, listed.y, increment)
    if reach is not None:
        # The odometry-failure component weighs the states within its reach far above the
        # kidnap share: scored to the end while they could matter to either.
        log_tracked = peak + math.log(total) if total > 0.0 else -math.inf
        np.minimum(below, failure.astray_bounds(reach, rows.size, log_tracked) / weight,
                   out=below)
    ll, scored = _scan_log_likelihood_cells(model, reads, step, rows, cols, below,
                                            compiled)
    if weight != 1.0:
        np.multiply(ll, weight, out=ll)
    scored_states = np.flatnonzero(scored)
    values = ll.reshape(-1)[scored_states]
    unscored_count = scored.size - scored_states.size
    unscored_peak = float(np.max(ll, where=~scored, initial=-math.inf)) if unscored_count \
        else -math.inf
    return LatticeWeights(rows, cols, scored_states, values, unscored_count, unscored_peak,
                          per_state, float(values.max(initial=-math.inf)), reach)


#: A window with a smaller share of free cells is scored on its free cells alone
#: (``laser._scan_log_likelihood``'s ``free_only``, the same bits): a global start's
#: building-wide window is mostly walls and unknown space (ACES: 80 %), while a tracked
#: robot's, mostly floor, costs less scored whole, in rows the kernel runs straight along.
FREE_ONLY_BELOW = 0.5


def _mostly_not_free(model: GridModel, box: Box) -> bool:
    r0, r1, c0, c1 = box
    return bool(model.free[r0:r1, c0:c1].mean() < FREE_ONLY_BELOW)


def _held_headings(prior: FloatArray) -> np.ndarray | None:
    """The heading layers of ``prior`` with probability, or None when every one has."""
    held = np.flatnonzero(prior.any(axis=(1, 2)))
    return None if held.size == prior.shape[0] else held


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


def _lattice_into(parts: list[FloatArray], boxes: list[Box], lattice: LatticeWeights,
                  weights: FloatArray, floor: float) -> tuple[States, float, float]:
    """Add the lattice's posterior (``weights``: of its scored states, the others' 0)
    within each box to that box's part; of the rest, the states of ``floor`` or more
    (headings, rows, columns, probabilities) and the probability of those left out; and
    the lattice's whole posterior probability."""
    step = KIDNAP_STEP
    k, n = lattice.states()
    rows, cols = lattice.rows[n], lattice.cols[n]
    covered = np.zeros(weights.size, dtype=bool)
    inside = 0.0
    for part, (r0, r1, c0, c1) in zip(parts, boxes):
        within = (rows >= r0) & (rows < r1) & (cols >= c0) & (cols < c1)
        if not within.any():
            continue
        # The states are distinct, so the fancy-indexed += adds each once.
        values = weights[within]
        part[step * k[within], rows[within] - r0, cols[within] - c0] += values
        inside += float(values.sum())
        covered |= within
    chosen = (weights >= floor if floor > 0 else weights > 0) & ~covered
    values = weights[chosen]
    everything = float(weights.sum())
    left_out = max(everything - inside - float(values.sum()), 0.0)
    return (step * k[chosen], rows[chosen], cols[chosen], values), left_out, everything
