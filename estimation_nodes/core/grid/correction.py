"""Bayes' rule over the grid: a belief and a log likelihood of its shape give the
posterior and the log evidence.

- ``correct``: posterior and log evidence, as the 1-D filter's ``correct``.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from estimation_nodes.core.errors import InputSizeError, InvalidInputError, ZeroEvidenceError
from estimation_nodes.core.grid.model import _any_belief
from estimation_nodes.core.validation import FloatArray, as_real_array


def _correct_in(log_likelihood: FloatArray, belief: FloatArray,
                again: Callable[[], FloatArray]) -> tuple[FloatArray, float]:
    """``correct``, the posterior written over ``log_likelihood`` (an array of ours): a
    tensor of millions of states allocated anew costs more than the arithmetic.

    The weights are taken relative to the largest log likelihood. When that is of a state
    the belief rules out and so far above the others that every weight underflows, the
    log likelihood is made ``again`` and weighed relative to the largest among the states
    the belief allows: the evidence was not zero, only too small for that scale.
    """
    peak = float(log_likelihood.max())
    if not peak < math.inf:   # NaN anywhere makes the maximum NaN
        raise InvalidInputError(f"log_likelihood: expected numbers below inf, got "
                                f"{'NaN' if math.isnan(peak) else peak}")
    if peak == -math.inf:
        raise ZeroEvidenceError("every state rules the scan out (log likelihood -inf)")
    weighted, total = _weighted(log_likelihood, peak, belief)
    if not total > 0:
        possible = belief > 0
        if possible.any():
            log_likelihood = again()
            log_likelihood[~possible] = -math.inf   # exp(+huge) * 0 would be NaN
            peak = float(log_likelihood.max())
            if peak > -math.inf:
                weighted, total = _weighted(log_likelihood, peak, belief)
    if not total > 0:
        raise ZeroEvidenceError("every state with probability rules the scan out")
    weighted /= total
    return weighted, peak + math.log(total)


def _weighted(log_likelihood: FloatArray, peak: float,
              belief: FloatArray) -> tuple[FloatArray, float]:
    """belief * exp(log_likelihood - peak), written over log_likelihood, and its sum."""
    weighted = np.subtract(log_likelihood, peak, out=log_likelihood)
    np.exp(weighted, out=weighted)
    np.multiply(weighted, belief, out=weighted)
    return weighted, float(weighted.sum())


def correct(belief: FloatArray, log_likelihood: FloatArray) -> tuple[FloatArray, float]:
    """Posterior and log evidence log p(z) = log sum(belief * exp(log_likelihood)).

    ``log_likelihood`` of the belief's shape, below inf (-inf: that state is ruled out).
    """
    belief = _any_belief(belief, ndim=None)
    given = as_real_array("log_likelihood", log_likelihood)
    if given.shape != belief.shape:
        raise InputSizeError(f"belief, log_likelihood: expected one shape, got "
                             f"{belief.shape} and {given.shape}")
    return _correct_in(np.array(given, dtype=np.float64), belief,
                       lambda: np.array(given, dtype=np.float64))
