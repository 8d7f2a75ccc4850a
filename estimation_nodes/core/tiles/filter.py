"""The running histogram belief: the current estimate and the steps that advance it.

A filter changes its belief only when a step succeeds, so a rejected input
(unknown class, zero evidence) leaves it exactly as it was. The estimator node
and the offline replay share this code, so both compute the same numbers from
the same inputs.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from estimation_nodes.core.errors import InputSizeError, InvalidInputError
from estimation_nodes.core.tiles import histogram
from estimation_nodes.core.tiles.models import HistogramModel
from estimation_nodes.core.validation import FloatArray, check_integer, short


class HistogramFilter:
    """The histogram belief over the world's cells."""

    def __init__(
        self,
        model: HistogramModel,
        initial_belief: FloatArray,
        allow_compiled: bool = True,
        in_place: bool = True,
    ) -> None:
        model, initial_belief = _checked(model, initial_belief)
        self._model = model
        self._initial_belief = initial_belief
        self._allow_compiled = allow_compiled
        # A correction in place saves an allocation per step on large worlds; a filter
        # whose snapshots are kept (causal_order.py) makes a new array each step instead.
        self._in_place = in_place
        self.belief: FloatArray = initial_belief.copy()
        self.last_evidence = float("nan")
        self.compiled = self._prepare_kernels()

    def _prepare_kernels(self) -> bool:
        """Load a large world's compiled kernels now, so the first step is not the one
        that waits for numba. True when the steps run compiled."""
        return histogram.compiled_kernels(self._model.size, self._allow_compiled) is not None

    def reconfigure(self, model: HistogramModel, initial_belief: FloatArray) -> bool:
        """Take new models; the belief restarts only when the world size or prior changed.

        Returns True when the belief was reset; refuses a model or belief that is not one
        (``InvalidInputError``), and then nothing changes.
        """
        model, initial_belief = _checked(model, initial_belief)
        restart = model.size != self._model.size or not np.array_equal(
            initial_belief, self._initial_belief
        )
        self._model, self._initial_belief = model, initial_belief
        if restart:
            self.compiled = self._prepare_kernels()
            self.reset()
        return restart

    def reset(self) -> None:
        self.belief = self._initial_belief.copy()
        self.last_evidence = float("nan")

    def snapshot(self) -> tuple[FloatArray, float]:
        """The belief and last evidence; valid while steps make new arrays (in_place False)."""
        return self.belief, self.last_evidence

    def restore(self, state: tuple[FloatArray, float]) -> None:
        self.belief, self.last_evidence = state

    def predict(self, u: int) -> FloatArray:
        """Predict with a move of ``u`` cells (an integer)."""
        shift = check_integer("u", u) % self._model.size
        self.belief = histogram._predict(self.belief, shift, self._model.kernel,
                                         compiled=self.compiled)
        return self.belief

    def correct(self, observed: str) -> FloatArray:
        """Correct with a tile observation; raises ValueError (unknown class, zero evidence)."""
        likelihood = self._model.likelihood(observed)
        # In place: the belief is this filter's own array (predict and reset make new
        # ones, and publishing copies it), and correct() leaves it alone on an error.
        self.belief, self.last_evidence = histogram._correct(
            self.belief, likelihood, out=self.belief if self._in_place else None,
            compiled=self.compiled)
        return self.belief


def _checked(model: Any, initial_belief: Any) -> tuple[HistogramModel, FloatArray]:
    """A model and a belief over its cells (values in [0, 1] with a positive sum), checked
    as they are: the belief is not normalized again (``check_belief`` in models.py did)."""
    if not isinstance(model, HistogramModel):
        raise InvalidInputError(f"model: expected a HistogramModel, got {short(model)}")
    try:
        belief = histogram.check_belief(initial_belief)
    except InvalidInputError as error:
        raise InvalidInputError(f"initial_{error}") from None
    if belief.size != model.size:
        raise InputSizeError(f"initial_belief: expected {model.size} values (one per cell), "
                             f"got {belief.size}")
    if not belief.sum() > 0.0:
        raise InvalidInputError("initial_belief: expected a positive sum, got all zeros")
    return model, belief
