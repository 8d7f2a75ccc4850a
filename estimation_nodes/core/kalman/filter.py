"""The running Kalman estimate: the current state and the core steps that advance it.

A filter changes its estimate only when a step succeeds, so a rejected input
(a NaN measurement, a result that would not be finite) leaves it exactly as it was.
The estimator node and the offline replay share this code, so both compute
the same numbers from the same inputs.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple, cast

import numpy as np

from estimation_nodes.core import errors
from estimation_nodes.core.kalman import linear as kalman
from estimation_nodes.core.kalman.models import (
    GaussianState,
    LinearGaussianModel,
    ScalarKalmanModel,
)
from estimation_nodes.core.validation import FloatArray, as_finite_vector, check_finite, short


def _overflow_checked_by_commit() -> np.errstate:
    """numpy's overflow warnings are noise here: ``_commit`` refuses any non-finite result."""
    return np.errstate(over="ignore", invalid="ignore")


class PositionEstimate(NamedTuple):
    """What the estimator publishes of the Kalman filter: position and its variance."""

    x: float
    var: float


class _PreparedSteps:
    """What the matrix steps give from ``P`` under ``model`` (which they are for: by
    identity, since steps replace P and never modify it), each computed when first asked
    for: the predicted covariance and the correction's gain and covariance."""

    __slots__ = ("P", "model", "predicted_P", "gain")

    def __init__(self, P: FloatArray, model: LinearGaussianModel) -> None:
        self.P, self.model = P, model
        self.predicted_P: FloatArray | None = None
        self.gain: kalman.CorrectionGain | None = None


class KalmanFilter:
    """The Kalman estimate: scalar (Algorithm 4) or matrix, as the model's type says."""

    def __init__(
        self, initial: GaussianState, model: ScalarKalmanModel | LinearGaussianModel
    ) -> None:
        _check(initial, model)
        self._initial = initial
        self._model = model
        self.last_nis = float("nan")
        self._prepared: _PreparedSteps | None = None
        #: The kinds of the last two steps ("predict", "correct"), oldest first: what
        #: prepare() takes the next one to be.
        self._recent_steps: tuple[str, ...] = ()
        self.reset()

    def reconfigure(
        self, initial: GaussianState, model: ScalarKalmanModel | LinearGaussianModel
    ) -> bool:
        """New models apply from the next step; the initial state only on reset, unless the
        state size changed: then the filter restarts from it. True when it restarted.
        A model and state that do not fit each other are refused, and nothing changes."""
        _check(initial, model)
        self._initial, self._model = initial, model
        if initial.x.shape == self.x.shape:
            return False
        self.reset()
        return True

    def reset(self) -> None:
        self.x = self._initial.x.copy()
        self.P = self._initial.P.copy()
        self.last_nis = float("nan")

    def snapshot(self) -> tuple[FloatArray, FloatArray, float]:
        """x, P and the last NIS; steps replace x and P, never modify them."""
        return self.x, self.P, self.last_nis

    def restore(self, state: tuple[FloatArray, FloatArray, float]) -> None:
        self.x, self.P, self.last_nis = state

    @property
    def estimate(self) -> PositionEstimate:
        """State component 0 and its variance: the position of the 1-D examples."""
        return PositionEstimate(float(self.x[0]), float(self.P[0, 0]))

    @property
    def input_size(self) -> int:
        """m: how many values one input (u) has."""
        model = self._model
        return 1 if isinstance(model, ScalarKalmanModel) else model.input_size

    @property
    def measurement_size(self) -> int:
        """p: how many values one measurement (z) has."""
        model = self._model
        return 1 if isinstance(model, ScalarKalmanModel) else model.measurement_size

    def predict(self, u: float | Sequence[float]) -> PositionEstimate:
        """Predict with an input ``u`` (a number, or m values); raises ValueError (wrong
        size, non-finite u, or a result that would not be finite) and then changes nothing."""
        model = self._model
        self._note_step("predict")
        if isinstance(model, ScalarKalmanModel):
            x, var = kalman.predict_scalar(
                float(self.x[0]), float(self.P[0, 0]), _one("u", u), model.var_u)
            self._commit(np.array([x]), np.array([[var]]), name="u")
        else:
            u_vec = as_finite_vector("u", u, model.input_size)
            with _overflow_checked_by_commit():
                x_new = kalman._predicted_mean(self.x, u_vec, model)
                self._commit(x_new, self._predicted_covariance(), name="u")
        return self.estimate

    def correct(self, z: float | Sequence[float]) -> PositionEstimate:
        """Correct with a measurement ``z`` (a number, or p values); raises ValueError (wrong
        size, non-finite z, or a result that would not be finite) and then changes nothing."""
        model = self._model
        self._note_step("correct")
        if isinstance(model, ScalarKalmanModel):
            x, var = float(self.x[0]), float(self.P[0, 0])
            z = _one("z", z)
            x_corrected, var_corrected, _ = kalman.correct_scalar(x, var, z, model.var_z)
            nis = kalman.normalized_innovation_squared_scalar(x, var, z, model.var_z)
            self._commit(np.array([x_corrected]), np.array([[var_corrected]]), nis, name="z")
        else:
            z_vec = as_finite_vector("z", z, model.measurement_size)
            with _overflow_checked_by_commit():
                gain = self._correction_gain()
                x_new, nis = kalman._corrected_mean(self.x, z_vec, gain, model)
                self._commit(x_new, gain.P, nis, name="z")
        return self.estimate

    def prepare(self) -> None:
        """Compute now what the next step will do to P: neither step's covariance depends
        on its input, so that step is then only the update of x. For a node to call
        while it waits for the next input (after publishing): the input's answer goes
        out sooner. The step prepared is the one the last two foretell (the kind before
        the last: inputs and measurements that alternate, or a run of either); before
        two steps, both. A wrong guess costs nothing but the work: the step then
        computes its own covariance, and the results are the same as without it. A
        scalar filter has nothing to prepare, and a failure here is left for the step
        itself to report."""
        if not isinstance(self._model, LinearGaussianModel):
            return
        expected = self._recent_steps[0] if len(self._recent_steps) == 2 else None
        with _overflow_checked_by_commit():
            try:
                if expected != "correct":
                    self._predicted_covariance()
                if expected != "predict":
                    self._correction_gain()
            except ValueError:   # LinAlgError included; the step raises it again
                self._prepared = None

    def _note_step(self, kind: str) -> None:
        """Remember the kind of a step being taken (taken or refused: it came)."""
        self._recent_steps = (*self._recent_steps[-1:], kind)

    def _steps_for_current_state(self) -> _PreparedSteps:
        prepared = self._prepared
        if prepared is None or prepared.P is not self.P or prepared.model is not self._model:
            prepared = self._prepared = _PreparedSteps(
                self.P, cast(LinearGaussianModel, self._model))
        return prepared

    # Called with numpy's overflow warnings off (see _overflow_checked_by_commit).

    def _predicted_covariance(self) -> FloatArray:
        prepared = self._steps_for_current_state()
        if prepared.predicted_P is None:
            prepared.predicted_P = kalman.predicted_covariance(prepared.P, prepared.model)
        return prepared.predicted_P

    def _correction_gain(self) -> kalman.CorrectionGain:
        prepared = self._steps_for_current_state()
        if prepared.gain is None:
            prepared.gain = kalman.correction_gain(prepared.P, prepared.model)
        return prepared.gain

    def _commit(self, x: FloatArray, P: FloatArray, nis: float | None = None, *,
                name: str) -> None:
        """Take a step's result only if every number of it is finite. (P is: the steps
        that make it, kalman.predicted_covariance, correction_gain and the scalar ones,
        refuse one that is not.)"""
        # Python's isfinite over a few values beats a numpy ufunc call.
        if not (all(map(math.isfinite, x.tolist())) and (nis is None or math.isfinite(nis))):
            raise errors.NonFiniteResultError(
                f"{name}: the result would not be finite (the input is too extreme for the "
                f"current estimate); estimate kept")
        self.x, self.P = x, P
        if nis is not None:
            self.last_nis = nis


def _check(initial: object, model: object) -> None:
    """A Gaussian state and a model of one state size (1 for the scalar model)."""
    if not isinstance(initial, GaussianState):
        raise errors.InvalidInputError(f"initial: expected a GaussianState, got {short(initial)}")
    if not isinstance(model, (ScalarKalmanModel, LinearGaussianModel)):
        raise errors.InvalidInputError(f"model: expected a ScalarKalmanModel or a "
                                       f"LinearGaussianModel, got {short(model)}")
    n = 1 if isinstance(model, ScalarKalmanModel) else model.state_size
    if initial.x.size != n:
        raise errors.InputSizeError(f"initial: expected a state of {n} values for this "
                                    f"model, got {initial.x.size}")


def _one(name: str, value: float | Sequence[float]) -> float:
    """A number given alone or as a one-element sequence (or array)."""
    if isinstance(value, (Sequence, np.ndarray)) and not isinstance(value, (str, bytes)):
        return float(as_finite_vector(name, value, 1)[0])
    return check_finite(name, value)
