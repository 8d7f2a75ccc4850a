"""The estimator's running state: current estimates plus the core steps that advance them.

A track changes its estimate only when a step succeeds, so a rejected input
(unknown class, zero evidence, NaN measurement) leaves it exactly as it was.
No rclpy here: nodes, offline replay and tests share this code.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from estimation_nodes.core import histogram, kalman
from estimation_nodes.core.config import FloatArray
from estimation_nodes.settings import EstimatorSettings, KalmanSettings


class HistogramTrack:
    """The histogram belief over the world's cells."""

    def __init__(self, settings: EstimatorSettings, allow_compiled: bool = True) -> None:
        self._settings = settings
        self._allow_compiled = allow_compiled
        self.belief: FloatArray = settings.initial_belief.copy()
        self.last_evidence = float("nan")
        self.compiled = self._prepare_kernels()

    def _prepare_kernels(self) -> bool:
        """Load a large world's compiled kernels now, so the first step is not the one
        that waits for numba. True when the steps run compiled."""
        size = self._settings.histogram.size
        return histogram.compiled_kernels(size, self._allow_compiled) is not None

    def reconfigure(self, settings: EstimatorSettings) -> bool:
        """Take new models; the belief restarts only when the world size or prior changed.

        Returns True when the belief was reset.
        """
        old = self._settings
        self._settings = settings
        restart = settings.histogram.size != old.histogram.size or not np.array_equal(
            settings.initial_belief, old.initial_belief
        )
        if restart:
            self.compiled = self._prepare_kernels()
            self.reset()
        return restart

    def reset(self) -> None:
        self.belief = self._settings.initial_belief.copy()
        self.last_evidence = float("nan")

    def predict(self, u: int) -> FloatArray:
        self.belief = histogram.predict(
            self.belief, u, self._settings.histogram.kernel, compiled=self.compiled)
        return self.belief

    def correct(self, observed: str) -> FloatArray:
        """Correct with a tile observation; raises ValueError (unknown class, zero evidence)."""
        likelihood = self._settings.histogram.likelihood(observed)
        # In place: the belief is this track's own array (predict and reset make new
        # ones, and publishing copies it), and correct() leaves it alone on an error.
        self.belief, self.last_evidence = histogram.correct(
            self.belief, likelihood, out=self.belief, compiled=self.compiled)
        return self.belief


class PositionEstimate(NamedTuple):
    """What the estimator publishes of the Kalman filter: position and its variance."""

    x: float
    var: float


class KalmanTrack:
    """The Kalman estimate, scalar (Algorithm 4) or matrix, as the settings say."""

    def __init__(self, settings: KalmanSettings) -> None:
        self._settings = settings
        self.last_nis = float("nan")
        self.reset()

    def reconfigure(self, settings: KalmanSettings) -> None:
        """New noise models apply from the next step; the initial state only on reset."""
        self._settings = settings

    def reset(self) -> None:
        initial = self._settings.initial
        self.x = initial.x.copy()
        self.P = initial.P.copy()
        self.last_nis = float("nan")

    @property
    def estimate(self) -> PositionEstimate:
        return PositionEstimate(float(self.x[0]), float(self.P[0, 0]))

    def predict(self, u: float) -> PositionEstimate:
        scalar, matrix = self._settings.scalar, self._settings.matrix
        if scalar is not None:
            x, var = kalman.predict_scalar(self.x[0], self.P[0, 0], u, scalar.var_u)
            self.x, self.P = np.array([x]), np.array([[var]])
        else:
            assert matrix is not None
            self.x, self.P = kalman.predict(self.x, self.P, [u], matrix)
        return self.estimate

    def correct(self, z: float) -> PositionEstimate:
        """Correct with a position measurement; raises ValueError for a non-finite z."""
        scalar, matrix = self._settings.scalar, self._settings.matrix
        if scalar is not None:
            x, var = self.x[0], self.P[0, 0]
            x_corrected, var_corrected, _ = kalman.correct_scalar(x, var, z, scalar.var_z)
            self.last_nis = (z - x) ** 2 / (var + scalar.var_z)
            self.x, self.P = np.array([x_corrected]), np.array([[var_corrected]])
        else:
            assert matrix is not None
            nis = kalman.normalized_innovation_squared(self.x, self.P, [z], matrix)
            self.x, self.P, _ = kalman.correct(self.x, self.P, [z], matrix)
            self.last_nis = nis
        return self.estimate
