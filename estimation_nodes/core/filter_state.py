"""Running filter state: the current estimates and the core steps that advance them.

A filter changes its estimate only when a step succeeds, so a rejected input
(unknown class, zero evidence, NaN measurement) leaves it exactly as it was.
The estimator node and the offline replay share this code, so both compute
the same numbers from the same inputs.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from estimation_nodes.core import histogram, kalman
from estimation_nodes.core.models import (
    FloatArray,
    GaussianState,
    HistogramModel,
    LinearGaussianModel,
    ScalarKalmanModel,
)


class HistogramFilter:
    """The histogram belief over the world's cells."""

    def __init__(
        self, model: HistogramModel, initial_belief: FloatArray, allow_compiled: bool = True
    ) -> None:
        self._model = model
        self._initial_belief = initial_belief
        self._allow_compiled = allow_compiled
        self.belief: FloatArray = initial_belief.copy()
        self.last_evidence = float("nan")
        self.compiled = self._prepare_kernels()

    def _prepare_kernels(self) -> bool:
        """Load a large world's compiled kernels now, so the first step is not the one
        that waits for numba. True when the steps run compiled."""
        return histogram.compiled_kernels(self._model.size, self._allow_compiled) is not None

    def reconfigure(self, model: HistogramModel, initial_belief: FloatArray) -> bool:
        """Take new models; the belief restarts only when the world size or prior changed.

        Returns True when the belief was reset.
        """
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

    def predict(self, u: int) -> FloatArray:
        self.belief = histogram.predict(self.belief, u, self._model.kernel, compiled=self.compiled)
        return self.belief

    def correct(self, observed: str) -> FloatArray:
        """Correct with a tile observation; raises ValueError (unknown class, zero evidence)."""
        likelihood = self._model.likelihood(observed)
        # In place: the belief is this filter's own array (predict and reset make new
        # ones, and publishing copies it), and correct() leaves it alone on an error.
        self.belief, self.last_evidence = histogram.correct(
            self.belief, likelihood, out=self.belief, compiled=self.compiled)
        return self.belief


class PositionEstimate(NamedTuple):
    """What the estimator publishes of the Kalman filter: position and its variance."""

    x: float
    var: float


class KalmanFilter:
    """The Kalman estimate: scalar (Algorithm 4) or matrix, as the model's type says."""

    def __init__(
        self, initial: GaussianState, model: ScalarKalmanModel | LinearGaussianModel
    ) -> None:
        self._initial = initial
        self._model = model
        self.last_nis = float("nan")
        self.reset()

    def reconfigure(
        self, initial: GaussianState, model: ScalarKalmanModel | LinearGaussianModel
    ) -> None:
        """New noise models apply from the next step; the initial state only on reset."""
        self._initial, self._model = initial, model

    def reset(self) -> None:
        self.x = self._initial.x.copy()
        self.P = self._initial.P.copy()
        self.last_nis = float("nan")

    @property
    def estimate(self) -> PositionEstimate:
        return PositionEstimate(float(self.x[0]), float(self.P[0, 0]))

    def predict(self, u: float) -> PositionEstimate:
        model = self._model
        if isinstance(model, ScalarKalmanModel):
            x, var = kalman.predict_scalar(self.x[0], self.P[0, 0], u, model.var_u)
            self.x, self.P = np.array([x]), np.array([[var]])
        else:
            self.x, self.P = kalman.predict(self.x, self.P, [u], model)
        return self.estimate

    def correct(self, z: float) -> PositionEstimate:
        """Correct with a position measurement; raises ValueError for a non-finite z."""
        model = self._model
        if isinstance(model, ScalarKalmanModel):
            x, var = self.x[0], self.P[0, 0]
            x_corrected, var_corrected, _ = kalman.correct_scalar(x, var, z, model.var_z)
            self.last_nis = kalman.normalized_innovation_squared_scalar(x, var, z, model.var_z)
            self.x, self.P = np.array([x_corrected]), np.array([[var_corrected]])
        else:
            nis = kalman.normalized_innovation_squared(self.x, self.P, [z], model)
            self.x, self.P, _ = kalman.correct(self.x, self.P, [z], model)
            self.last_nis = nis
        return self.estimate
