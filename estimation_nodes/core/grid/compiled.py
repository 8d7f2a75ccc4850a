"""Compiled kernels of the grid filter (numba): motion.py's and laser.py's steps in fewer passes.

numpy's prediction makes some fifty passes over the belief tensor (a shift
per layer and per bilinear weight, two rolls for the headings, padded copies
and a pass per tap for each of the three blurs). Here the motion (bilinear in
x and y, linear in heading) is one scatter pass, and each blur one pass with
its taps in registers; the scan's log likelihood is accumulated row by row,
the output row and the field rows it reads staying in cache. Results equal
numpy's to rounding (sums in another order); tests/unit/test_grid.py checks
both paths against brute force.

Importing this module imports numba; ``warm_up`` compiles the kernels or
loads them from numba's cache (``cache=True``).

The kernels check no index (numba does not): their callers guarantee every one is
in bounds before it calls them. Beliefs are of the model's shape; the shifts
are at most the grid's size plus one (a longer one moves everything off it) and
the turn at most the number of headings, so each becomes an int64 exactly; the
taps of a blur are at most as wide as the axis needs; the field is padded by
more than every beam's end point offset, and those are cut to the map's size.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from estimation_nodes.core.validation import FloatArray

_jit = njit(nogil=True, cache=True)


@_jit
def shift_motion(belief: FloatArray, shift_rows: FloatArray, shift_cols: FloatArray,
                 turn: float, held: np.ndarray, out: FloatArray, made: np.ndarray) -> None:
    """out = belief moved: layer k by (shift_rows[k], shift_cols[k]) cells (bilinear),
    every heading by ``turn`` bins (linear, cyclic); mass leaving the grid is lost.
    ``shift_rows`` and ``shift_cols`` have one value per heading, each within the grid's
    size plus one; |turn| is at most the number of headings. Only the layers ``held``
    (the others are zero) are moved; ``made`` is set where out's may not be zero."""
    bins, rows, cols = belief.shape
    out[:] = 0.0
    made[:] = False
    turn_base = int(np.floor(turn))
    turn_frac = turn - turn_base
    for k in range(bins):
        if not held[k]:
            continue
        k0 = (k + turn_base) % bins
        k1 = (k0 + 1) % bins
        base_r = int(np.floor(shift_rows[k]))
        base_c = int(np.floor(shift_cols[k]))
        fr = shift_rows[k] - base_r
        fc = shift_cols[k] - base_c
        for dr in range(2):
            wr = fr if dr else 1.0 - fr
            if wr == 0.0:
                continue
            for dc in range(2):
                wc = fc if dc else 1.0 - fc
                w = wr * wc
                if w == 0.0:
                    continue
                rs = base_r + dr
                cs = base_c + dc
                i_lo, i_hi = max(0, -rs), min(rows, rows - rs)
                j_lo, j_hi = max(0, -cs), min(cols, cols - cs)
                w0 = w * (1.0 - turn_frac)
                w1 = w * turn_frac
                width = j_hi - j_lo
                made[k0] = True
                if w1 != 0.0:
                    made[k1] = True
                for i in range(i_lo, i_hi):
                    src = belief[k, i, j_lo:j_hi]
                    dst0 = out[k0, i + rs, j_lo + cs:j_hi + cs]
                    for j in range(width):
                        dst0[j] += w0 * src[j]
                    if w1 != 0.0:
                        dst1 = out[k1, i + rs, j_lo + cs:j_hi + cs]
                        for j in range(width):
                            dst1[j] += w1 * src[j]


@_jit
def blur_headings(source: FloatArray, taps: FloatArray, held: np.ndarray, out: FloatArray,
                  made: np.ndarray) -> None:
    """out[k] = sum_t taps[t] * source[(k + t - half) % K] (cyclic), over the source layers
    ``held`` (the others are zero); ``made`` is set where out's may not be zero."""
    bins = source.shape[0]
    half = taps.size // 2
    out[:] = 0.0
    made[:] = False
    for k in range(bins):
        target = out[k].ravel()
        for t in range(taps.size):
            index = (k + t - half) % bins
            if not held[index]:
                continue
            made[k] = True
            layer = source[index].ravel()
            weight = taps[t]
            for n in range(target.size):
                target[n] += weight * layer[n]


@_jit
def blur_rows(source: FloatArray, taps: FloatArray, held: np.ndarray, out: FloatArray) -> None:
    """out[k, i] = sum_t taps[t] * source[k, i + t - half] (rows, along y; zero outside),
    over the layers ``held`` (the others are zero)."""
    bins, rows, cols = source.shape
    half = taps.size // 2
    out[:] = 0.0
    for k in range(bins):
        if not held[k]:
            continue
        for i in range(rows):
            target = out[k, i]
            for t in range(taps.size):
                r = i + t - half
                if 0 <= r < rows:
                    row = source[k, r]
                    weight = taps[t]
                    for j in range(cols):
                        target[j] += weight * row[j]


@_jit
def blur_cols_masked(source: FloatArray, taps: FloatArray, free: np.ndarray,
                     held: np.ndarray, out: FloatArray) -> float:
    """out[k, i, j] = free[i, j] * sum_t taps[t] * source[k, i, j + t - half] (along x),
    over the layers ``held`` (the others are zero); returns the total, for the
    normalization. Each row is copied into a zero-padded buffer, so the taps run over
    plain slices without bounds checks."""
    bins, rows, cols = source.shape
    half = taps.size // 2
    buffer = np.zeros(cols + 2 * half)
    mask = free.astype(np.float64)
    total = 0.0
    for k in range(bins):
        if not held[k]:
            out[k] = 0.0
            continue
        for i in range(rows):
            buffer[half:half + cols] = source[k, i]
            target = out[k, i]
            first = buffer[0:cols]
            weight = taps[0]
            for j in range(cols):
                target[j] = weight * first[j]
            for t in range(1, taps.size):
                segment = buffer[t:t + cols]
                weight = taps[t]
                for j in range(cols):
                    target[j] += weight * segment[j]
            keep = mask[i]
            for j in range(cols):
                target[j] *= keep[j]
                total += target[j]
    return total


@_jit
def scan_log_likelihood(padded: FloatArray, pad_rows: int, pad_cols: int, offsets: np.ndarray,
                        bins: int, rows: int, cols: int, out: FloatArray) -> None:
    """out[k, i, j] = sum_b padded[pad_rows + i + dr[k, b], pad_cols + j + dc[k, b]].

    Unchecked: the caller (laser.py) pads by more than every |dr| and |dc|."""
    beams = offsets.shape[1]
    for k in range(bins):
        for i in range(rows):
            target = out[k, i]
            target[:] = 0.0
            for b in range(beams):
                start = pad_cols + offsets[k, b, 1]
                segment = padded[pad_rows + i + offsets[k, b, 0], start:start + cols]
                for j in range(cols):
                    target[j] += segment[j]


@_jit
def scan_log_likelihood_runs(padded: FloatArray, pad_rows: int, pad_cols: int,
                             offsets: np.ndarray, bins: int, rows: int, row_runs: np.ndarray,
                             run_starts: np.ndarray, run_stops: np.ndarray,
                             out: FloatArray) -> None:
    """``scan_log_likelihood`` over the runs of cells listed (row i's: columns
    run_starts[n]:run_stops[n] for n in row_runs[i]:row_runs[i + 1]; the free cells),
    the same sums in the same order (the same bits); -inf at every other cell, which a
    belief never holds. Unchecked, as ``scan_log_likelihood``."""
    beams = offsets.shape[1]
    for k in range(bins):
        for i in range(rows):
            target = out[k, i]
            target[:] = -np.inf
            for n in range(row_runs[i], row_runs[i + 1]):
                first, stop = run_starts[n], run_stops[n]
                run = target[first:stop]
                run[:] = 0.0
                for b in range(beams):
                    start = pad_cols + offsets[k, b, 1] + first
                    segment = padded[pad_rows + i + offsets[k, b, 0], start:start + stop - first]
                    for j in range(stop - first):
                        run[j] += segment[j]


#: How many beams a lattice state's sum takes between two looks at its bound.
CHECK_EVERY = 2


@_jit
def scan_log_likelihood_cells(field: FloatArray, starts: np.ndarray, offsets: np.ndarray,
                              below: FloatArray, most: float, order: np.ndarray,
                              out: FloatArray, scored: np.ndarray) -> None:
    """out[k, n] = sum_b field[starts[n] + offsets[k, b]]: the log field flattened, a
    state cell's position in it and each heading's beam end points as offsets from it;
    the sums in the order of ``scan_log_likelihood``'s (the same bits).

    Where below[n] > -inf the beams are first summed in ``order`` (spread over the scan:
    the first few already tell most states apart), and the sum stops once it is less
    than below[n] even with every beam left scoring ``most`` (the field's largest
    value): out[k, n] is then that bound and scored[k, n] False. A state that never
    stops is summed again in the beams' order. Unchecked, as ``scan_log_likelihood``."""
    bins, beams = offsets.shape
    count = starts.size
    # Each heading's offsets in the bound's order, and the bound's allowance for the
    # beams left after the m-th (its value, as (beams - 1 - m) * most, to the bit).
    ordered = np.empty(beams, dtype=np.int64)
    allowance = np.empty(beams)
    for m in range(beams):
        allowance[m] = (beams - 1 - m) * most
    for k in range(bins):
        offset = offsets[k]
        for m in range(beams):
            ordered[m] = offset[order[m]]
        for n in range(count):
            start = starts[n]
            floor = below[n]
            if floor > -np.inf:
                total = 0.0
                stopped = False
                for m in range(beams):
                    total += field[start + ordered[m]]
                    if m % CHECK_EVERY == CHECK_EVERY - 1 and total + allowance[m] < floor:
                        out[k, n] = total + allowance[m]
                        stopped = True
                        break
                if stopped:
                    scored[k, n] = False
                    continue
            total = 0.0
            for b in range(beams):
                total += field[start + offset[b]]
            out[k, n] = total
            scored[k, n] = True


def warm_up() -> None:
    """Compile (or load from numba's cache) every kernel on a tiny input."""
    belief = np.full((2, 3, 3), 1.0 / 18)
    out = np.empty_like(belief)
    held, made = np.ones(2, dtype=np.bool_), np.empty(2, dtype=np.bool_)
    shift_motion(belief, np.zeros(2), np.zeros(2), 0.0, held, out, made)
    taps = np.array([0.25, 0.5, 0.25])
    blur_headings(belief, taps, held, out, made)
    blur_rows(belief, taps, held, out)
    blur_cols_masked(belief, taps, np.ones((3, 3), dtype=np.bool_), held, out)
    offsets = np.zeros((2, 1, 2), dtype=np.int64)
    scan_log_likelihood(np.zeros((5, 5)), 1, 1, offsets, 2, 3, 3, out)
    runs = np.array([0, 1, 1, 2], dtype=np.int64)
    scan_log_likelihood_runs(np.zeros((5, 5)), 1, 1, offsets, 2, 3, runs,
                             np.array([0, 1], dtype=np.int64), np.array([2, 3], dtype=np.int64),
                             out)
    scan_log_likelihood_cells(np.zeros(25), np.array([6, 8]), np.zeros((2, 1), dtype=np.int64),
                              np.zeros(2), 0.0, np.zeros(1, dtype=np.int64), np.empty((2, 2)),
                              np.empty((2, 2), dtype=np.bool_))
