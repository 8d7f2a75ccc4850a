"""Compiled histogram kernels for large worlds (numba).

numpy needs five passes over the belief for a histogram step: a cyclically
padded copy and a convolution for the prediction, then a dot product, a
product and a scaling for the correction. Here the prediction is one pass
(shift, wrap and kernel together) and the correction two (numpy's dot for
the evidence, then product and scaling fused). The results equal numpy's:
the correction bit for bit (the same operations in the same order), the
prediction to rounding (the kernel's taps summed in another order).

Importing this module imports numba, and ``warm_up`` then compiles the
kernels or loads them from numba's cache; both take a noticeable part of a
second (docs/benchmarks.md). ``histogram`` does both only for worlds large
enough to pay that back.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from estimation_nodes.core.validation import FloatArray

# nogil: a node's other threads keep running during a step over a million cells.
# cache: the machine code is kept beside the module, so only the first run compiles.
_jit = njit(nogil=True, cache=True)


# Outputs per block of _window_sums: the block and its source stay in the
# L1 cache while every tap passes over them.
_BLOCK = 1024


@_jit
def _window_sums(
    source: FloatArray, reversed_weights: FloatArray, out: FloatArray, count: int
) -> None:
    """out[i] = sum_j reversed_weights[j] * source[i + j] for i < count.

    Blocked, and tap by tap inside a block: each inner loop is a plain
    multiply-add over contiguous slices indexed by ``range``, which numba
    compiles without negative-index checks and vectorizes.
    """
    width = reversed_weights.size
    if width == 3:          # the book's kernel: one fused pass, taps unrolled
        r0, r1, r2 = reversed_weights[0], reversed_weights[1], reversed_weights[2]
        s0, s1, s2 = source[:count], source[1 : count + 1], source[2 : count + 2]
        for i in range(count):
            out[i] = r0 * s0[i] + r1 * s1[i] + r2 * s2[i]
        return
    for start in range(0, count, _BLOCK):
        size = min(_BLOCK, count - start)
        block = out[start : start + size]
        first, weight = source[start : start + size], reversed_weights[0]
        for i in range(size):
            block[i] = weight * first[i]
        for j in range(1, width):
            tap, weight = source[start + j : start + j + size], reversed_weights[j]
            for i in range(size):
                block[i] += weight * tap[i]


@_jit
def _wrapped_sum(belief: FloatArray, weights: FloatArray, cell: int) -> float:
    """The unshifted cyclic convolution at one cell, with explicit wrap-around."""
    n = belief.size
    half = weights.size // 2
    total = 0.0
    for k in range(weights.size):
        total += weights[k] * belief[(cell + half - k) % n]
    return total


@_jit
def predict_into(belief: FloatArray, shift: int, weights: FloatArray, out: FloatArray) -> None:
    """out[(t + shift) mod N] = sum_k weights[k] * belief[(t + h - k) mod N] for every t.

    ``shift`` must be in [0, N). The cells whose window does not wrap (all
    but h at either end) are written by ``_window_sums`` in at most two
    runs, split where the shift wraps the output around.
    """
    n = belief.size
    half = weights.size // 2
    reversed_weights = weights[::-1].copy()
    if n <= 2 * half:       # the kernel spans the world: every cell wraps
        for t in range(n):
            out[(t + shift) % n] = _wrapped_sum(belief, weights, t)
        return
    # Interior t in [half, n - half) reads belief[t - half : t + half + 1].
    split = n - shift       # t >= split lands at out[t - split]
    first_stop = min(max(split, half), n - half)
    if first_stop > half:
        _window_sums(belief, reversed_weights, out[half + shift :], first_stop - half)
    if n - half > first_stop:
        _window_sums(
            belief[first_stop - half :], reversed_weights, out[first_stop - split :],
            n - half - first_stop,
        )
    for t in range(half):
        out[(t + shift) % n] = _wrapped_sum(belief, weights, t)
    for t in range(n - half, n):
        out[(t + shift) % n] = _wrapped_sum(belief, weights, t)


@_jit
def scaled_product_into(
    belief: FloatArray, likelihood: FloatArray, scale: float, out: FloatArray
) -> None:
    """out = (belief * likelihood) * scale in one pass; ``out`` may be ``belief``."""
    for i in range(belief.size):
        out[i] = (belief[i] * likelihood[i]) * scale


def warm_up() -> None:
    """Compile (or load from the cache) every kernel now, not at the first step."""
    tiny, weights = np.full(8, 0.125), np.array([0.1, 0.8, 0.1])
    out = np.empty(8)
    for kernel in (weights, np.full(5, 0.2), np.ones(1)):
        predict_into(tiny, 3, kernel, out)
    scaled_product_into(tiny, tiny, 1.0, out)
