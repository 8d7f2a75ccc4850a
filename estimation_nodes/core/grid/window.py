"""The belief's support: the steps of grid/steps.py over the box of states with probability.

A tracked robot's belief is zero on all but a few square metres of a building,
and a step never moves probability further than its motion and its noise
reach. So the filter runs over a window of (rows, columns), all headings:

- ``support_box``: the smallest box holding every state of nonzero probability;
- ``grown_box``: that box after a prediction: grown by the motion's reach (the
  longest shift of any heading layer, plus the bilinear split's cell) and the
  blur's taps either side, cut to the grid;
- the prediction runs on the window's crop of the belief and the map
  (``crop``), the correction scores the scan over the window only
  (``steps._scan_log_likelihood(..., box=)``).

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

import numpy as np

from estimation_nodes.core.grid import steps as grid
from estimation_nodes.core.validation import FloatArray

#: (first row, row past the last, first column, column past the last).
Box = tuple[int, int, int, int]


def full_box(model: grid.GridModel) -> Box:
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


def grown_box(box: Box, model: grid.GridModel, delta: tuple[float, float, float],
              noise: grid.OdometryNoise) -> Box:
    """Where a prediction with ``delta`` can put the probability now within ``box``."""
    rows, cols = model.free.shape
    trans = delta[1]
    # Every layer's shift is at most trans cells long in rows and in columns; the
    # bilinear split reaches one cell beyond its floor.
    reach = trans / model.resolution
    shift = math.ceil(reach) + 1 if reach < rows + cols else rows + cols
    sigma_cells, _ = grid._motion_noise(delta, noise, model)
    spread_rows = grid._reaching_taps(sigma_cells, rows).size // 2
    spread_cols = grid._reaching_taps(sigma_cells, cols).size // 2
    r0, r1, c0, c1 = box
    return (max(0, r0 - shift - spread_rows), min(rows, r1 + shift + spread_rows),
            max(0, c0 - shift - spread_cols), min(cols, c1 + shift + spread_cols))


def crop(model: grid.GridModel, box: Box) -> grid.GridModel:
    """The map within ``box``: its free cells and field, its origin at the box's corner."""
    r0, r1, c0, c1 = box
    origin = (model.origin[0] + c0 * model.resolution, model.origin[1] + r0 * model.resolution)
    # Contiguous copies: the compiled kernels were compiled for those (warm_up), and a view
    # would make numba compile another version mid-run, where a Ctrl-C cannot stop it
    # cleanly (core/compiled_loader.py).
    return grid.GridModel(np.ascontiguousarray(model.free[r0:r1, c0:c1]),
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
    small = belief < min(floor, float(belief.max()))
    # Summed where small, not as belief[small]: that copy is most of a building's belief.
    dropped = float(np.sum(belief, where=small))
    if dropped > 0.0:
        belief[small] = 0.0
        belief /= float(belief.sum())
    return belief, dropped


#: The kidnap share goes on one state in KIDNAP_STEP^3: every other heading, row and column.
KIDNAP_STEP = 2


def correct_with_kidnap(belief: FloatArray, model: grid.GridModel, box: Box,
                        ranges: FloatArray, angles: FloatArray, weight: float, share: float,
                        floor: float, compiled: bool = True
                        ) -> tuple[FloatArray, Box, float, float]:
    """The correction of the prior (1 - share) x ``belief`` (the window ``box``'s) plus
    ``share`` spread evenly over the free states of a coarse lattice (every
    KIDNAP_STEP-th heading, row and column, a fraction 1 / KIDNAP_STEP^3 of the states),
    so that a kidnapped robot is found by its scans at the cost of scoring the lattice,
    not every state. (The next prediction's blur spreads what the lattice finds.)

    Returns the posterior over the box that holds the window and every lattice state of
    probability ``floor`` or more, that box, the log evidence, and the probability of
    the lattice states left outside it (all below the floor)."""
    step = KIDNAP_STEP
    lattice_free = model.free[::step, ::step]
    free_states = int(lattice_free.sum()) * -(-model.heading_bins // step)
    window_ll = grid._scan_log_likelihood(model, ranges, angles, compiled, box)
    if free_states == 0:
        share, lattice_ll = 0.0, None
    else:
        lattice_ll = grid._scan_log_likelihood_strided(model, ranges, angles, step, compiled)
    if weight != 1.0:
        np.multiply(window_ll, weight, out=window_ll)
        if lattice_ll is not None:
            np.multiply(lattice_ll, weight, out=lattice_ll)
    peak = _peak(window_ll, belief > 0, lattice_ll, lattice_free)
    weighted, _ = grid._weighted(window_ll, peak, belief)
    weighted *= 1.0 - share
    total = float(weighted.sum())
    if lattice_ll is not None:
        lattice, _ = grid._weighted(lattice_ll, peak, lattice_free)
        lattice *= share / free_states
        total += float(lattice.sum())
    if not total > 0.0:
        raise grid.ZeroEvidenceError("every state with probability rules the scan out")
    log_evidence = peak + math.log(total)
    weighted /= total
    if lattice_ll is None:
        return weighted, box, log_evidence, 0.0
    lattice /= total
    merged, merged_box, left_out = _merged(weighted, box, lattice, floor)
    return merged, merged_box, log_evidence, left_out


def _peak(window_ll: FloatArray, possible: np.ndarray, lattice_ll: FloatArray | None,
          lattice_free: np.ndarray) -> float:
    """The largest log likelihood among the states the prior allows, so that the most
    likely of them never underflows."""
    peak = float(window_ll[possible].max(initial=-math.inf))
    if lattice_ll is not None:
        peak = max(peak, float(lattice_ll[:, lattice_free].max(initial=-math.inf)))
    if not math.isfinite(peak):
        raise grid.ZeroEvidenceError("every state with probability rules the scan out")
    return peak


def _merged(weighted: FloatArray, box: Box, lattice: FloatArray,
            floor: float) -> tuple[FloatArray, Box, float]:
    """The window's posterior and the lattice's over the box holding the window and the
    lattice states of at least ``floor``; and the lattice's probability outside it."""
    step = KIDNAP_STEP
    kept = np.argwhere(lattice >= floor)
    r0, r1, c0, c1 = box
    if kept.size:
        r0, r1 = min(r0, step * int(kept[:, 1].min())), max(r1, step * int(kept[:, 1].max()) + 1)
        c0, c1 = min(c0, step * int(kept[:, 2].min())), max(c1, step * int(kept[:, 2].max()) + 1)
    merged = np.zeros((weighted.shape[0], r1 - r0, c1 - c0))
    b0, b1, d0, d1 = box
    merged[:, b0 - r0:b1 - r0, d0 - c0:d1 - c0] = weighted
    # The lattice rows and columns within the merged box, and where they fall in it.
    i0, i1 = -(-r0 // step), -(-r1 // step)
    j0, j1 = -(-c0 // step), -(-c1 // step)
    inside = lattice[:, i0:i1, j0:j1]
    merged[::step, step * i0 - r0::step, step * j0 - c0::step] += inside
    left_out = max(float(lattice.sum()) - float(inside.sum()), 0.0)
    if left_out > 0.0:
        merged /= float(merged.sum())
    return merged, (r0, r1, c0, c1), left_out
