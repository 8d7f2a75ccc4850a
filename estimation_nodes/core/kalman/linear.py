"""Kalman filters: the scalar form (the book's Algorithm 4), fusion, the matrix form.

Symbols follow the book (Eqs. 6.34 to 6.36)::

    x(k+1) = A x(k) + B u(k) + F w(k),   w ~ N(0, Q)
    z(k)   = C x(k) + v(k),              v ~ N(0, R)

so F is the noise-input matrix, not the transition matrix as in filterpy.
Every function returns new values and leaves its inputs alone.

Every function checks its arguments (finite numbers of the model's sizes, a
variance >= 0) and raises ``InvalidInputError`` naming the one that is wrong,
or ``NonFiniteResultError`` when the result would not be finite (an extreme
input overflows, an innovation covariance is singular): a result is never NaN
or inf. P is taken as the covariance it is meant to be (symmetric positive
semi-definite: GaussianState checks it, the steps keep it so); only its shape
and finiteness are checked here, where an eigenvalue check would cost more
than the step. An overflow warns (numpy's
RuntimeWarning) before it is refused; KalmanFilter silences those.
"""

from __future__ import annotations

import math
from typing import NamedTuple, cast

import numpy as np

from estimation_nodes.core.errors import (
    EstimationError,
    InputSizeError,
    InvalidInputError,
    NonFiniteResultError,
)
from estimation_nodes.core.kalman.models import LinearGaussianModel
from estimation_nodes.core.validation import (
    FloatArray,
    as_finite_vector,
    as_real_array,
    check_finite,
    check_non_negative,
    short,
)


class ScalarEstimate(NamedTuple):
    """A scalar Gaussian estimate: mean ``x`` and variance ``var``."""

    x: float
    var: float


def fuse(x1: float, var1: float, x2: float, var2: float) -> ScalarEstimate:
    """Combine two independent Gaussian estimates of one quantity (Example 6.15).

    x = (var2 x1 + var1 x2) / (var1 + var2),   var = 1 / (1/var1 + 1/var2)

    The variances are >= 0, not both 0 (two certain estimates that may disagree).
    """
    x1, x2 = check_finite("x1", x1), check_finite("x2", x2)
    var1, var2 = check_non_negative("var1", var1), check_non_negative("var2", var2)
    total = var1 + var2
    if not total > 0.0:
        raise InvalidInputError("var1, var2: expected at least one variance > 0, got two 0s")
    estimate = ScalarEstimate((var2 * x1 + var1 * x2) / total, var1 * var2 / total)
    if not (math.isfinite(estimate.x) and math.isfinite(estimate.var)):
        # A product overflowed on the way, not the answer: the same as a weighted step.
        weight = var1 / total
        estimate = ScalarEstimate(x1 + weight * (x2 - x1), weight * var2)
    if not (math.isfinite(estimate.x) and math.isfinite(estimate.var)):
        raise NonFiniteResultError(f"x1, var1, x2, var2: the fused estimate overflows ({x1!r}, "
                                   f"{x2!r} with variances {var1!r}, {var2!r})")
    return estimate


# The scalar steps are the hot path of a 1-D filter and return plain tuples:
# building a NamedTuple costs more than the whole step's arithmetic
# (docs/benchmarks.md).


def predict_scalar(x: float, var: float, u: float, var_u: float) -> tuple[float, float]:
    """Prediction of Algorithm 4: the move adds its mean and its variance.

    Returns ``(x, var)``; raises ``ValueError`` for a NaN or infinite ``u`` (or x, or a
    variance not finite and >= 0), ``NonFiniteResultError`` when the sum overflows.
    """
    # One comparison chain on the hot path; the error path finds the culprit.
    try:
        x_new, var_new = x + u, var + var_u
        ok = (math.isfinite(u) and math.isfinite(x_new) and var >= 0.0 and var_u >= 0.0
              and math.isfinite(var_new))
    except (TypeError, ValueError):   # not numbers, or arrays (no truth value)
        ok = False
    if not ok:
        _refuse_scalar(("u", u), ("x", x), ("var", var), ("var_u", var_u))
        raise NonFiniteResultError(f"x, u, var, var_u: x + u ({x!r} + {u!r}) or var + var_u "
                                   f"({var!r} + {var_u!r}) overflows; estimate kept")
    return x_new, var_new


def _refuse_scalar(*named: tuple[str, float]) -> None:
    """Raise InvalidInputError for the first argument that is not a finite number (a
    variance, one whose name starts with var, also >= 0)."""
    for name, value in named:
        number = check_finite(name, value)
        if name.startswith("var"):
            check_non_negative(name, number)


#: Above this gain the scalar correction's variance is w var_z rather than (1 - w) var.
_GAIN_NEAR_ONE = 1.0 - 1e-8


def correct_scalar(
    x: float, var: float, z: float, var_z: float
) -> tuple[float, float, float]:
    """Correction of Algorithm 4 with the gain w = var / (var + var_z).

    x' = x + w (z - x),   var' = (1 - w) var   (= w var_z, taken so for w within 1e-8 of 1)

    Returns ``(x, var, gain)``; raises ``ValueError`` for a NaN or infinite
    ``z`` (or x, or variances not finite and >= 0, or both 0), and nothing is
    changed then; ``NonFiniteResultError`` when z - x overflows.
    """
    try:
        total = var + var_z
        ok = (math.isfinite(z) and var >= 0.0 and var_z >= 0.0 and 0.0 < total < math.inf)
        if ok:
            gain = var / total
            x_new = x + gain * (z - x)
            if not math.isfinite(x_new):   # z - x overflowed, perhaps not the answer
                x_new = (1.0 - gain) * x + gain * z
            ok = math.isfinite(x_new)
    except (TypeError, ValueError):   # not numbers, or arrays (no truth value)
        ok = False
    if not ok:
        _refuse_scalar(("z", z), ("x", x), ("var", var), ("var_z", var_z))
        if not 0.0 < float(var) + float(var_z) < math.inf:
            raise InvalidInputError(f"var, var_z: expected a finite sum > 0, got {var!r} + "
                                    f"{var_z!r}")
        raise NonFiniteResultError(f"x, z: z - x overflows ({z!r} - {x!r}); estimate kept")
    if gain > _GAIN_NEAR_ONE:
        # (1 - w) var loses its digits as w nears 1 (a prior far wider than the measurement:
        # from var / var_z ~ 1e16 on w is 1 exactly and var' would be 0, a filter certain
        # for ever); w var_z is the same quantity without the cancellation.
        return x_new, gain * var_z, gain
    return x_new, (1.0 - gain) * var, gain


# The matrix steps below are small-matrix code: a 4-state step is a few dozen
# numpy calls on 4 x 4 arrays, so the cost is per call, not per flop.
# ndarray.dot calls BLAS directly and takes about half the time of `@`
# (numpy 2's matmul gufunc) on such sizes, hence .dot throughout.


def _symmetric(matrix: FloatArray) -> FloatArray:
    """Remove the rounding asymmetry that products of matrices leave behind."""
    # A new sum: adding matrix.T into matrix itself makes numpy copy the overlapping
    # operand first, which costs more than the sum on small matrices.
    result = matrix + matrix.T
    result *= 0.5
    return result


def _as_vector(name: str, value: object, size: int) -> FloatArray:
    return as_finite_vector(name, value, size)


def _check_model(model: object) -> LinearGaussianModel:
    if not isinstance(model, LinearGaussianModel):
        raise InvalidInputError(f"model: expected a LinearGaussianModel, got {short(model)}")
    return model


# x and P are checked for their shapes up front and for finiteness through the result:
# a NaN or inf in x or P makes every value it touches NaN or inf (IEEE arithmetic, 0 * inf
# included), so a finite result means finite inputs, and a refused result looks at the
# inputs to name the one to blame. That keeps the filter's steps on its own state at the
# cost of one check of what they produce.


def _state(x: object, model: LinearGaussianModel) -> FloatArray:
    """x: the model's n numbers, as a flat float array (finiteness: see above)."""
    if isinstance(x, np.ndarray) and x.dtype == np.float64 and x.ndim == 1:
        vector = x
    else:
        vector = as_real_array("x", x).reshape(-1)
    if vector.size != model.state_size:
        raise InputSizeError(f"x: expected {model.state_size} values, got {vector.size}")
    return vector


def _covariance(P: object, model: LinearGaussianModel) -> FloatArray:
    """P: an n x n array (symmetry and definiteness are not checked, finiteness above)."""
    matrix = P if isinstance(P, np.ndarray) and P.dtype == np.float64 else as_real_array("P", P)
    n = model.state_size
    if matrix.shape != (n, n):
        raise InputSizeError(f"P: expected shape ({n}, {n}), got {matrix.shape}")
    return matrix


def _finite(*arrays: FloatArray) -> bool:
    # Python's isfinite over the few values of small matrices beats numpy ufunc calls.
    values: list[float] = []
    for array in arrays:
        values += array.ravel().tolist()
    return all(map(math.isfinite, values))


def _overflows(what: str, **inputs: FloatArray) -> EstimationError:
    """The error for a result that is not finite: an input with NaN or inf (named), or
    else an overflow."""
    for name, value in inputs.items():
        if not _finite(value):
            return InvalidInputError(f"{name}: expected finite numbers, got {short(value)}")
    return NonFiniteResultError(f"{what} would not be finite (an input too extreme for the "
                                f"estimate); nothing changed")


def _small_inverse(S: FloatArray) -> FloatArray | None:
    """S^-1 in closed form for the symmetric positive definite S = C P C' + R of one or two
    measurements, the common cases (a LAPACK call's overhead outweighs the arithmetic
    on a 2 x 2); None for a larger S, or a nearly singular one, where the closed form
    loses accuracy: those go to a LAPACK solve."""
    size = S.shape[0]
    if size == 1:
        return 1.0 / S if S[0, 0] > 0.0 else None
    if size == 2:
        (a, b), (c, d) = S.tolist()
        determinant = a * d - b * c
        if determinant > 1e-8 * (a * d) and math.isfinite(determinant):
            return np.array([[d, -b], [-c, a]]) / determinant
    return None


# Neither step's covariance depends on u or z: P' and the gain follow from P and the
# model alone. So each step is split into that part and the part that uses the input,
# and a filter can compute the first ahead, while it waits for the input
# (filter_state.KalmanFilter.prepare): the step is then a few vector operations.


def predicted_covariance(P: FloatArray, model: LinearGaussianModel) -> FloatArray:
    """P' = A P A' + F Q F' of the prediction (Eq. 6.35), exactly symmetric."""
    model = _check_model(model)
    P = _covariance(P, model)
    P_pred = _predicted_covariance(P, model)
    if not _finite(P_pred):
        raise _overflows("P: the predicted covariance A P A' + F Q F'", P=P)
    return P_pred


def _predicted_covariance(P: FloatArray, model: LinearGaussianModel) -> FloatArray:
    # H = A P A' / 2 (exactly: halving is exact), then H + H' is A P A' made
    # exactly symmetric, without a separate averaging pass.
    P_pred = model.A.dot(P).dot(model.half_A_transposed)
    P_pred += P_pred.T
    P_pred += model.process_noise
    return P_pred


def predicted_mean(x: FloatArray, u: object, model: LinearGaussianModel) -> FloatArray:
    """x' = A x + B u of the prediction (Eq. 6.35); raises ValueError for a ``u`` (or x)
    of the wrong size (InputSizeError) or with NaN or inf."""
    model = _check_model(model)
    x = _state(x, model)
    x_pred = _predicted_mean(x, _as_vector("u", u, model.input_size), model)
    if not _finite(x_pred):
        raise _overflows("x, u: the predicted mean A x + B u", x=x)
    return x_pred


def _predicted_mean(x: FloatArray, u_vec: FloatArray, model: LinearGaussianModel) -> FloatArray:
    x_pred = model.A.dot(x)
    x_pred += model.B.dot(u_vec)
    return x_pred


def predict(
    x: FloatArray, P: FloatArray, u: object, model: LinearGaussianModel
) -> tuple[FloatArray, FloatArray]:
    """Prediction (Eq. 6.35): x' = A x + B u,  P' = A P A' + F Q F'."""
    model = _check_model(model)
    x, P = _state(x, model), _covariance(P, model)
    u_vec = _as_vector("u", u, model.input_size)
    x_pred, P_pred = _predicted_mean(x, u_vec, model), _predicted_covariance(P, model)
    if not _finite(x_pred, P_pred):
        raise _overflows("x, P, u: the prediction", x=x, P=P)
    return x_pred, P_pred


class CorrectionGain(NamedTuple):
    """What a correction from covariance P does whatever the measurement is."""

    #: The gain K = P C' S^-1.
    K: FloatArray
    #: The corrected covariance, Joseph form.
    P: FloatArray
    #: The innovation covariance S = C P C' + R, and its inverse when taken in closed form
    #: (None: the NIS solves with S).
    S: FloatArray
    S_inv: FloatArray | None


def correction_gain(P: FloatArray, model: LinearGaussianModel) -> CorrectionGain:
    """The gain and the corrected covariance of Eq. 6.36, Joseph form.

    K = P C' (C P C' + R)^-1,   P' = (I - K C) P (I - K C)' + K R K'

    The Joseph form holds for any gain and keeps P symmetric positive
    semi-definite where the short form P - K C P can lose it to rounding.

    A singular innovation covariance (no measurement noise along a direction P is
    certain of too) has no gain: ``NonFiniteResultError``.
    """
    model = _check_model(model)
    return _correction_gain(_covariance(P, model), model)


def _correction_gain(P: FloatArray, model: LinearGaussianModel) -> CorrectionGain:
    C, R = model.C, model.R
    PCt = P.dot(model.C_transposed)
    innovation_cov = C.dot(PCt)
    innovation_cov += R
    S_inv = _small_inverse(innovation_cov)
    if S_inv is not None:
        K = PCt.dot(S_inv)
    else:   # S and P are symmetric, so K' = S^-1 (C P)
        try:
            K = cast(FloatArray, np.linalg.solve(innovation_cov, PCt.T).T)
        except np.linalg.LinAlgError:
            raise _overflows("P: the gain (the innovation covariance C P C' + R is "
                             "singular)", P=P) from None
    I_KC = model.identity - K.dot(C)
    P_new = I_KC.dot(P).dot(I_KC.T)
    P_new += K.dot(R).dot(K.T)
    P_new = _symmetric(P_new)
    if not _finite(K, P_new):
        raise _overflows("P: the gain or the corrected covariance", P=P)
    return CorrectionGain(K, P_new, innovation_cov, S_inv)


def corrected_mean(
    x: FloatArray, z: object, gain: CorrectionGain, model: LinearGaussianModel
) -> tuple[FloatArray, float]:
    """x' = x + K (z - C x) of Eq. 6.36 and the normalized innovation squared
    y' S^-1 y of y = z - C x; raises ValueError for a ``z`` (or x) of the wrong size
    (InputSizeError) or with NaN or inf."""
    model = _check_model(model)
    x = _state(x, model)
    z_vec = _as_vector("z", z, model.measurement_size)
    if not (isinstance(gain, CorrectionGain) and gain.K.shape == (model.state_size,
                                                                   model.measurement_size)):
        raise InvalidInputError(f"gain: expected the CorrectionGain of this model, got "
                                f"{short(gain)}")
    x_new, nis = _corrected_mean(x, z_vec, gain, model)
    if not (_finite(x_new) and math.isfinite(nis)):
        raise _overflows("x, z: the corrected mean or its NIS", x=x)
    return x_new, nis


def _corrected_mean(
    x: FloatArray, z_vec: FloatArray, gain: CorrectionGain, model: LinearGaussianModel
) -> tuple[FloatArray, float]:
    innovation = z_vec - model.C.dot(x)
    x_new = x + gain.K.dot(innovation)
    if gain.S_inv is not None:
        nis = float(innovation.dot(gain.S_inv.dot(innovation)))
    else:
        nis = float(innovation.dot(np.linalg.solve(gain.S, innovation)))
    return x_new, nis


def correct(
    x: FloatArray, P: FloatArray, z: object, model: LinearGaussianModel
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Correction (Eq. 6.36) with the Joseph-form covariance (see ``correction_gain``).

    Returns
    -------
    x, P, K
        Corrected mean, corrected covariance and the gain used.
    """
    x_new, P_new, K, _ = correct_with_nis(x, P, z, model)
    return x_new, P_new, K


def correct_with_nis(
    x: FloatArray, P: FloatArray, z: object, model: LinearGaussianModel
) -> tuple[FloatArray, FloatArray, FloatArray, float]:
    """``correct`` and the normalized innovation squared of ``z``: ``(x, P, K, nis)``."""
    model = _check_model(model)
    z_vec = _as_vector("z", z, model.measurement_size)   # a bad z raises before any work
    x, P = _state(x, model), _covariance(P, model)
    gain = _correction_gain(P, model)
    x_new, nis = _corrected_mean(x, z_vec, gain, model)
    if not (_finite(x_new) and math.isfinite(nis)):
        raise _overflows("x, P, z: the corrected mean or its NIS", x=x)
    return x_new, gain.P, gain.K, nis


def normalized_innovation_squared_scalar(x: float, var: float, z: float, var_z: float) -> float:
    """NIS of a scalar measurement: (z - x)^2 / (var + var_z), chi-square with 1 dof.

    ``NonFiniteResultError`` (not OverflowError, as ``**`` would raise, nor inf) when
    the square overflows.
    """
    try:
        total = var + var_z
        innovation = z - x
        nis = innovation * innovation / total if total > 0.0 else math.nan
        ok = math.isfinite(nis) and var >= 0.0 and var_z >= 0.0 and math.isfinite(total)
    except (TypeError, ValueError):   # not numbers, or arrays (no truth value)
        ok = False
    if not ok:
        _refuse_scalar(("z", z), ("x", x), ("var", var), ("var_z", var_z))
        if not total > 0.0:
            raise InvalidInputError(f"var, var_z: expected a sum > 0, got {var!r} + {var_z!r}")
        raise _overflows(f"x, z, var, var_z: the NIS of z = {z!r} about x = {x!r}")
    return nis


def normalized_innovation_squared(
    x: FloatArray, P: FloatArray, z: object, model: LinearGaussianModel
) -> float:
    """NIS = y' S^-1 y with y = z - C x, S = C P C' + R: chi-square with dim(z) dof."""
    model = _check_model(model)
    z_vec = _as_vector("z", z, model.measurement_size)
    x, P = _state(x, model), _covariance(P, model)
    innovation = z_vec - model.C.dot(x)
    innovation_cov = model.C.dot(P).dot(model.C_transposed)
    innovation_cov += model.R
    try:
        nis = float(innovation.dot(np.linalg.solve(innovation_cov, innovation)))
    except np.linalg.LinAlgError:
        raise _overflows("P: the NIS (the innovation covariance C P C' + R is "
                         "singular)", x=x, P=P) from None
    if not math.isfinite(nis):
        raise _overflows(f"x, P, z: the NIS of {z_vec.tolist()}", x=x, P=P)
    return nis
