"""Histogram (discrete Bayes) filter over a cyclic world of cells.

A belief is a probability vector over the N cells of a closed loop. A move of
``u`` cells takes cell j to cell (j + u) mod N; the motion kernel spreads the
landing place around that target. Both steps return new arrays and never
modify their inputs.

Prediction (total probability, Eq. of the book's prediction step)::

    bel'(x) = sum_k kernel[k] * bel(x - u - offset_k)

Correction (Bayes' rule)::

    bel(x | z) = p(z | x) bel(x) / p(z),   p(z) = sum_x p(z | x) bel(x)
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from estimation_nodes.core.config import FloatArray, MotionKernel


class ZeroEvidenceError(ValueError):
    """An observation that every cell of the belief rules out: p(z) = 0."""


def uniform(size: int) -> FloatArray:
    """The belief of a robot that knows nothing: 1/N in every cell."""
    if size < 1:
        raise ValueError(f"size: expected at least one cell, got {size}")
    return np.full(size, 1.0 / size)


def one_hot(size: int, cell: int) -> FloatArray:
    """The belief of a robot that knows it is in ``cell``."""
    belief = np.zeros(size)
    belief[cell % size] = 1.0
    return belief


def _add_rolled(
    out: FloatArray, source: FloatArray, shift: int, weight: float, scratch: FloatArray
) -> None:
    """out += weight * roll(source, shift), in place, without allocating.

    ``shift`` is in [0, N). Splitting at the wrap point gives two contiguous
    slices, so each tap is one multiply and one add streaming over N doubles.
    """
    n = source.size
    head = n - shift
    np.multiply(source[:head], weight, out=scratch[shift:])
    np.multiply(source[head:], weight, out=scratch[:shift])
    np.add(out, scratch, out=out)


def predict(belief: FloatArray, u: int, kernel: MotionKernel) -> FloatArray:
    """Belief after a move of ``u`` cells (any integer, either direction).

    Runs in O(N * len(kernel)) time and O(N) memory: no N x N matrix.

    Parameters
    ----------
    belief : (N,) array
        Probability of each cell before the move.
    u : int
        Commanded move; positive is counter-clockwise (index + u).
    kernel : MotionKernel
        Probabilities of landing at offsets around the target.

    Returns
    -------
    (N,) array
        The predicted belief.
    """
    source = np.asarray(belief, dtype=np.float64)
    n = source.size
    predicted = np.zeros(n)
    scratch = np.empty(n)
    # Python ints: a huge u wraps exactly instead of overflowing a fixed-width type.
    for offset, weight in zip(kernel.offsets.tolist(), kernel.weights.tolist()):
        if weight != 0.0:
            _add_rolled(predicted, source, (int(u) + offset) % n, weight, scratch)
    return predicted


def correct(belief: FloatArray, likelihood: FloatArray) -> tuple[FloatArray, float]:
    """Posterior belief and evidence p(z | earlier data) after one observation.

    Raises
    ------
    ZeroEvidenceError
        If the observation is impossible in every cell the belief allows
        (p(z) = 0); the caller keeps its belief, nothing is divided by zero.
    """
    unnormalized = np.multiply(belief, likelihood)
    evidence = float(unnormalized.sum())
    if not evidence > 0.0 or not np.isfinite(evidence):
        raise ZeroEvidenceError(
            f"observation has evidence {evidence!r}: every cell of the belief rules it out"
        )
    unnormalized /= evidence
    return unnormalized, evidence


def most_likely_cell(belief: FloatArray) -> int:
    """Index of the cell with the highest probability (the first one on a tie)."""
    return int(np.argmax(belief))


def entropy(belief: FloatArray) -> float:
    """Shannon entropy of the belief in bits (0: certain; log2 N: uniform)."""
    positive = belief[belief > 0.0]
    return float(-(positive * np.log2(positive)).sum())


def sample_offset(kernel: MotionKernel, rng: np.random.Generator) -> int:
    """Draw where a real move lands relative to its target, as the kernel says."""
    return int(rng.choice(kernel.offsets, p=kernel.weights))


def sample_observation(
    probabilities: npt.NDArray[np.float64], true_class: int, rng: np.random.Generator
) -> int:
    """Draw an observed class index for a tile of class ``true_class``."""
    return int(rng.choice(probabilities.shape[1], p=probabilities[true_class]))
