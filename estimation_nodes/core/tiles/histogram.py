"""Histogram (discrete Bayes) filter over a cyclic world of cells.

A belief is a probability vector over the N cells of a closed loop. A move of
``u`` cells takes cell j to cell (j + u) mod N; the motion kernel spreads the
landing place around that target. Both steps return new arrays and never
modify their inputs.

Prediction (total probability, Eq. of the book's prediction step)::

    bel'(x) = sum_k kernel[k] * bel(x - u - offset_k)

Correction (Bayes' rule)::

    bel(x | z) = p(z | x) bel(x) / p(z),   p(z) = sum_x p(z | x) bel(x)

Each step checks its arguments (``InvalidInputError`` naming the one that is
wrong) with a numpy reduction or two, no Python loop: a belief is a non-empty
vector of probabilities in [0, 1], a likelihood one of finite numbers >= 0 of
the belief's size, a move an integer. ``HistogramFilter`` (filter.py) checks
its inputs and calls the unchecked steps (underscored here) on the belief it
holds, so a node's step costs no more than before.
"""

from __future__ import annotations

import math
from types import ModuleType

import numpy as np

from estimation_nodes.core.compiled_loader import load_kernels
from estimation_nodes.core.errors import (
    InputSizeError,
    InvalidInputError,
    NonFiniteResultError,
    ZeroEvidenceError,
)
from estimation_nodes.core.tiles.models import MotionKernel
from estimation_nodes.core.validation import (
    FloatArray,
    as_real_array,
    check_integer,
    check_probabilities,
    values_within,
    short,
)

#: Worlds of at least this many cells take the compiled kernels of
#: ``compiled`` (numba) when numba imports: from here on the passes over
#: memory that they save outweigh numba's call overhead, and the import and
#: cached compilation pay back within a few steps. Smaller
#: worlds never import numba, so small nodes start as fast as before.
COMPILED_MIN_CELLS = 1 << 16


def _size(size: int) -> int:
    size = check_integer("size", size)
    if size < 1:
        raise InvalidInputError(f"size: expected at least one cell, got {size}")
    return size


def uniform(size: int) -> FloatArray:
    """The belief of a robot that knows nothing: 1/N in every cell."""
    size = _size(size)
    return np.full(size, 1.0 / size)


def one_hot(size: int, cell: int) -> FloatArray:
    """The belief of a robot that knows it is in ``cell`` (taken modulo the size)."""
    size = _size(size)
    belief = np.zeros(size)
    belief[check_integer("cell", cell) % size] = 1.0
    return belief


def check_belief(value: object) -> FloatArray:
    """A belief for the steps: a non-empty vector of probabilities in [0, 1] (not
    necessarily summing to 1), C-contiguous float64, the caller's own when it is one."""
    array = as_real_array("belief", value)
    if array.ndim != 1:
        raise InputSizeError(f"belief: expected a vector (one value per cell), got shape "
                             f"{array.shape}")
    return check_probabilities("belief", array, array.shape)


def _check_kernel(kernel: object) -> MotionKernel:
    if not isinstance(kernel, MotionKernel):
        raise InvalidInputError(f"kernel: expected a MotionKernel, got {short(kernel)}")
    return kernel


def _compiled_module() -> ModuleType | None:
    return load_kernels("estimation_nodes.core.tiles.compiled")


def compiled_kernels(size: int, allowed: bool = True) -> ModuleType | None:
    """The compiled kernels a world of ``size`` cells uses, or None for numpy's.

    ``allowed=False`` always gives numpy's path (numba and LLVM hold a large
    share of the process's memory once imported; docs/benchmarks.md). The
    first call for a large world imports numba and compiles (or loads from
    cache) the kernels; a caller that minds latency calls this at start-up
    rather than at its first step.
    """
    return _compiled_module() if allowed and size >= COMPILED_MIN_CELLS else None


def _wrapped(belief: FloatArray, shift: int, half_width: int) -> FloatArray:
    """roll(belief, shift) with ``half_width`` cells of cyclic padding on either side.

    ``padded[half_width + i] == belief[(i - shift) mod N]``, so a 'valid'
    convolution of the result with the kernel is the cyclic prediction.
    """
    n = belief.size
    h = half_width
    if h > n:   # a kernel wider than the world wraps more than once
        return belief[(np.arange(-h, n + h) - shift) % n]
    padded = np.empty(n + 2 * h)
    head = n - shift
    padded[h + shift : h + n] = belief[:head]
    padded[h : h + shift] = belief[head:]
    padded[:h] = padded[n : n + h]
    padded[n + h :] = padded[h : 2 * h]
    return padded


def predict(
    belief: FloatArray, u: int, kernel: MotionKernel, *, compiled: bool = True
) -> FloatArray:
    """Belief after a move of ``u`` cells (any integer, either direction).

    Runs in O(N * len(kernel)) time and O(N) memory: no N x N matrix. The
    shift and the wrap-around are one copy into a padded buffer; the kernel
    is then one 'valid' convolution, a single pass in numpy's C code. Large
    worlds (``COMPILED_MIN_CELLS``) do all of it in one compiled pass.

    Parameters
    ----------
    belief : (N,) array
        Probability of each cell before the move.
    u : int
        Commanded move; positive is counter-clockwise (index + u).
    kernel : MotionKernel
        Probabilities of landing at offsets around the target.
    compiled : bool
        Whether a large world may use the compiled kernels (``compiled_kernels``).

    Returns
    -------
    (N,) array
        The predicted belief.
    """
    source = check_belief(belief)
    # Python ints: a huge u wraps exactly instead of overflowing a fixed-width type.
    shift = check_integer("u", u) % source.size
    return _predict(source, shift, _check_kernel(kernel), compiled)


def _predict(source: FloatArray, shift: int, kernel: MotionKernel,
             compiled: bool = True) -> FloatArray:
    """``predict`` of a checked belief (contiguous float64), the shift in [0, N)."""
    kernels = compiled_kernels(source.size, compiled)
    if kernels is not None:   # shift, wrap and kernel in one compiled pass
        predicted = np.empty(source.size)
        kernels.predict_into(source, shift, kernel.weights, predicted)
        return predicted
    padded = _wrapped(source, shift, kernel.half_width)
    # convolve(padded, w)[i] = sum_k w[k] padded[i + 2h - k] = sum_k w[k] belief[i - u - (k - h)]
    return np.convolve(padded, kernel.weights, mode="valid")


def correct(
    belief: FloatArray,
    likelihood: FloatArray,
    out: FloatArray | None = None,
    *,
    compiled: bool = True,
) -> tuple[FloatArray, float]:
    """Posterior belief and evidence p(z | earlier data) after one observation.

    The posterior is a new array unless ``out`` is given (it may be ``belief``
    itself, for a caller that owns it: large worlds then allocate nothing).
    ``out`` is written only after the evidence is known to be positive, so a
    rejected observation leaves it as it was. ``compiled`` as in ``predict``.

    ``belief``: non-negative weights of the cells (a probability vector, or any prior:
    the posterior is normalized); ``likelihood``: p(z | x) of each cell, finite, >= 0.

    Raises
    ------
    ZeroEvidenceError
        If the observation is impossible in every cell the belief allows
        (p(z) = 0); the caller keeps its belief, nothing is divided by zero.
    InvalidInputError
        If an argument is not of that form (named in the message).
    NonFiniteResultError
        If the evidence overflows (weights too large for the sum of their products).
    """
    belief = np.ascontiguousarray(as_real_array("belief", belief))
    likelihood = np.ascontiguousarray(as_real_array("likelihood", likelihood))
    if belief.ndim != 1 or belief.size == 0:
        raise InputSizeError(f"belief: expected a vector of at least one cell, got shape "
                             f"{belief.shape}")
    if likelihood.shape != belief.shape:
        raise InputSizeError(f"belief, likelihood: expected one likelihood per cell, got "
                             f"shapes {belief.shape} and {likelihood.shape}")
    if out is not None and not (isinstance(out, np.ndarray) and out.dtype == np.float64
                                and out.shape == belief.shape and out.flags.writeable
                                and out.flags.c_contiguous):
        raise InvalidInputError(f"out: expected a writable contiguous float64 array of "
                                f"{belief.size} values, got {short(out)}")
    # NaN or inf in either makes the evidence NaN or inf, which _correct refuses; a
    # negative value has to be looked for.
    if not values_within(belief, 0.0, math.inf):
        raise InvalidInputError(f"belief: expected weights >= 0, got {short(belief)}")
    if not values_within(likelihood, 0.0, math.inf):
        raise InvalidInputError(f"likelihood: expected values >= 0, got {short(likelihood)}")
    return _correct(belief, likelihood, out, compiled=compiled)


def _correct(
    belief: FloatArray,
    likelihood: FloatArray,
    out: FloatArray | None = None,
    *,
    compiled: bool = True,
) -> tuple[FloatArray, float]:
    """``correct`` of a belief and a likelihood of one size, both without negative values."""
    # The evidence as a dot product reads both arrays once, without a temporary.
    evidence = float(np.dot(belief, likelihood))
    if not evidence > 0.0 or not math.isfinite(evidence):
        _refuse(evidence, belief, likelihood)
    scale = 1.0 / evidence
    if not math.isfinite(scale):
        # A subnormal evidence: its reciprocal overflows, but each term is at most
        # the evidence, so dividing by it stays finite.
        posterior = np.multiply(belief, likelihood, out=out)
        np.divide(posterior, evidence, out=posterior)
        return posterior, evidence
    kernels = compiled_kernels(belief.size, compiled)
    if kernels is not None:   # product and scaling fused: the same operations, one pass
        posterior = np.empty(belief.size) if out is None else out
        kernels.scaled_product_into(
            np.ascontiguousarray(belief, dtype=np.float64),
            np.ascontiguousarray(likelihood, dtype=np.float64), scale, posterior)
        return posterior, evidence
    posterior = np.multiply(belief, likelihood, out=out)
    np.multiply(posterior, scale, out=posterior)
    return posterior, evidence


def _refuse(evidence: float, belief: FloatArray, likelihood: FloatArray) -> None:
    """Raise the reason why the evidence is not a positive finite number."""
    for name, values in (("belief", belief), ("likelihood", likelihood)):
        if not np.isfinite(values).all():
            raise InvalidInputError(f"{name}: expected finite numbers, got {short(values)}")
    if math.isinf(evidence):
        raise NonFiniteResultError(
            "belief, likelihood: the evidence sum(belief * likelihood) overflows; belief kept")
    raise ZeroEvidenceError(
        f"observation has evidence {evidence!r}: every cell of the belief rules it out"
    )


def most_likely_cell(belief: FloatArray) -> int:
    """Index of the cell with the highest probability (the first one on a tie)."""
    return int(np.argmax(check_belief(belief)))


def entropy(belief: FloatArray) -> float:
    """Shannon entropy of the belief in bits (0: certain; log2 N: uniform)."""
    belief = check_belief(belief)
    positive = belief[belief > 0.0]
    # abs: a certain belief sums to -0.0, which would print as "-0".
    return abs(float((positive * np.log2(positive)).sum()))
