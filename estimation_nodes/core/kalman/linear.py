"""Kalman filters: the scalar form (the book's Algorithm 4), fusion, the matrix form.

Symbols follow the book (Eqs. 6.34 to 6.36)::

    x(k+1) = A x(k) + B u(k) + F w(k),   w ~ N(0, Q)
    z(k)   = C x(k) + v(k),              v ~ N(0, R)

so F is the noise-input matrix, not the transition matrix as in filterpy.
Every function returns new values and leaves its inputs alone.
"""

from __future__ import annotations

import math
from typing import NamedTuple, cast

import numpy as np

from estimation_nodes.core.errors import InputSizeError
from estimation_nodes.core.kalman.models import LinearGaussianModel
from estimation_nodes.core.validation import FloatArray


class ScalarEstimate(NamedTuple):
    """A scalar Gaussian estimate: mean ``x`` and variance ``var``."""

    x: float
    var: float


def fuse(x1: float, var1: float, x2: float, var2: float) -> ScalarEstimate:
    """Combine two independent Gaussian estimates of one quantity (Example 6.15).

    x = (var2 x1 + var1 x2) / (var1 + var2),   var = 1 / (1/var1 + 1/var2)
    """
    total = var1 + var2
    return ScalarEstimate((var2 * x1 + var1 * x2) / total, var1 * var2 / total)


# The scalar steps are the hot path of a 1-D filter and return plain tuples:
# building a NamedTuple costs more than the whole step's arithmetic
# (docs/benchmarks.md).


def predict_scalar(x: float, var: float, u: float, var_u: float) -> tuple[float, float]:
    """Prediction of Algorithm 4: the move adds its mean and its variance.

    Returns ``(x, var)``; raises ``ValueError`` for a NaN or infinite ``u``.
    """
    if not math.isfinite(u):
        raise ValueError(f"u: expected a finite number, got {u!r}")
    return x + u, var + var_u


def correct_scalar(
    x: float, var: float, z: float, var_z: float
) -> tuple[float, float, float]:
    """Correction of Algorithm 4 with the gain w = var / (var + var_z).

    x' = x + w (z - x),   var' = (1 - w) var

    Returns ``(x, var, gain)``; raises ``ValueError`` for a NaN or infinite
    ``z``, and nothing is changed then.
    """
    if not math.isfinite(z):
        raise ValueError(f"z: expected a finite number, got {z!r}")
    gain = var / (var + var_z)
    return x + gain * (z - x), (1.0 - gain) * var, gain


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
    vector = np.asarray(value, dtype=np.float64).reshape(-1)
    if vector.size != size:
        raise InputSizeError(f"{name}: expected {size} values, got {vector.size}")
    # Python's isfinite over the few values of a small vector beats a numpy ufunc call.
    if not all(map(math.isfinite, vector.tolist())):
        raise ValueError(f"{name}: expected finite numbers, got {vector.tolist()}")
    return vector


def _small_inverse(S: FloatArray) -> FloatArray | None:
    """S^-1 in closed form for the symmetric positive definite S = C P C' + R of one or two
    measurements, the common cases (a LAPACK call's overhead outweighs the arithmetic
    on a 2 x 2); None for a larger S, or a nearly singular one, where the closed form
    loses accuracy: those go to a LAPACK solve."""
    size = S.shape[0]
    if size == 1:
        return 1.0 / S
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
    # H = A P A' / 2 (exactly: halving is exact), then H + H' is A P A' made
    # exactly symmetric, without a separate averaging pass.
    P_pred = model.A.dot(P).dot(model.half_A_transposed)
    P_pred += P_pred.T
    P_pred += model.process_noise
    return P_pred


def predicted_mean(x: FloatArray, u: object, model: LinearGaussianModel) -> FloatArray:
    """x' = A x + B u of the prediction (Eq. 6.35); raises ValueError for a ``u`` of the
    wrong size (InputSizeError) or with NaN or inf."""
    u_vec = _as_vector("u", u, model.input_size)
    x_pred = model.A.dot(x)
    x_pred += model.B.dot(u_vec)
    return x_pred


def predict(
    x: FloatArray, P: FloatArray, u: object, model: LinearGaussianModel
) -> tuple[FloatArray, FloatArray]:
    """Prediction (Eq. 6.35): x' = A x + B u,  P' = A P A' + F Q F'."""
    return predicted_mean(x, u, model), predicted_covariance(P, model)


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
    """
    C, R = model.C, model.R
    PCt = P.dot(model.C_transposed)
    innovation_cov = C.dot(PCt)
    innovation_cov += R
    S_inv = _small_inverse(innovation_cov)
    if S_inv is not None:
        K = PCt.dot(S_inv)
    else:   # S and P are symmetric, so K' = S^-1 (C P)
        K = cast(FloatArray, np.linalg.solve(innovation_cov, PCt.T).T)
    I_KC = model.identity - K.dot(C)
    P_new = I_KC.dot(P).dot(I_KC.T)
    P_new += K.dot(R).dot(K.T)
    return CorrectionGain(K, _symmetric(P_new), innovation_cov, S_inv)


def corrected_mean(
    x: FloatArray, z: object, gain: CorrectionGain, model: LinearGaussianModel
) -> tuple[FloatArray, float]:
    """x' = x + K (z - C x) of Eq. 6.36 and the normalized innovation squared
    y' S^-1 y of y = z - C x; raises ValueError for a ``z`` of the wrong size
    (InputSizeError) or with NaN or inf."""
    return _corrected_mean(x, _as_vector("z", z, model.measurement_size), gain, model)


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
    z_vec = _as_vector("z", z, model.measurement_size)   # a bad z raises before any work
    gain = correction_gain(P, model)
    x_new, nis = _corrected_mean(x, z_vec, gain, model)
    return x_new, gain.P, gain.K, nis


def normalized_innovation_squared_scalar(x: float, var: float, z: float, var_z: float) -> float:
    """NIS of a scalar measurement: (z - x)^2 / (var + var_z), chi-square with 1 dof.

    inf (not OverflowError, as ``**`` would raise) when the square overflows.
    """
    innovation = z - x
    return innovation * innovation / (var + var_z)


def normalized_innovation_squared(
    x: FloatArray, P: FloatArray, z: object, model: LinearGaussianModel
) -> float:
    """NIS = y' S^-1 y with y = z - C x, S = C P C' + R: chi-square with dim(z) dof."""
    z_vec = _as_vector("z", z, model.measurement_size)
    innovation = z_vec - model.C.dot(x)
    innovation_cov = model.C.dot(P).dot(model.C_transposed)
    innovation_cov += model.R
    return float(innovation.dot(np.linalg.solve(innovation_cov, innovation)))
