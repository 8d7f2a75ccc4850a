"""The Kalman filter's models: the scalar system of Algorithm 4, the linear Gaussian
system and a Gaussian state.

The book's symbols: F is the noise-input matrix (not the transition matrix,
which filterpy calls F and the book calls A). The filter steps are in
:mod:`estimation_nodes.core.kalman.linear`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from estimation_nodes.core.errors import InputSizeError, InvalidInputError
from estimation_nodes.core.validation import (
    FloatArray,
    as_finite_array,
    check_covariance,
    check_finite,
    check_positive,
    short,
)


@dataclass(frozen=True)
class ScalarKalmanModel:
    """The scalar filter of the book's Algorithm 4: x' = x + u, z = x + v.

    ``var_u`` is the variance of the executed move, ``var_z`` that of a measurement.
    """

    var_u: float
    var_z: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "var_u", check_positive("var_u", self.var_u))
        object.__setattr__(self, "var_z", check_positive("var_z", self.var_z))


@dataclass(frozen=True)
class LinearGaussianModel:
    """x(k+1) = A x(k) + B u(k) + F w(k),  z(k) = C x(k) + v(k),  Q = cov(w), R = cov(v).

    The book's symbols: F is the noise-input matrix (not the transition matrix,
    which filterpy calls F and the book calls A).
    """

    A: FloatArray
    B: FloatArray
    C: FloatArray
    F: FloatArray
    Q: FloatArray
    R: FloatArray
    #: F Q F', the process noise in state space.
    process_noise: FloatArray = field(init=False, repr=False, compare=False)
    #: The n x n identity, for the Joseph form.
    identity: FloatArray = field(init=False, repr=False, compare=False)
    #: A' / 2, contiguous: the prediction's symmetric product (see kalman.predict).
    half_A_transposed: FloatArray = field(init=False, repr=False, compare=False)
    #: C', contiguous, for the gain.
    C_transposed: FloatArray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        A = as_finite_array("A", self.A, ndim=2)
        n = A.shape[0]
        if A.shape != (n, n) or n == 0:
            raise InputSizeError(f"A: expected a square matrix of at least one state, got "
                                 f"shape {A.shape}")
        B = as_finite_array("B", self.B, ndim=2)
        C = as_finite_array("C", self.C, ndim=2)
        F = as_finite_array("F", self.F, ndim=2)
        for name, matrix in (("B", B), ("F", F)):
            if matrix.shape[0] != n:
                raise InputSizeError(
                    f"{name}: expected {n} rows to match A ({n}x{n}), got shape {matrix.shape}"
                )
        if C.shape[1] != n or C.shape[0] == 0:
            raise InputSizeError(
                f"C: expected {n} columns to match A ({n}x{n}) and at least one row (a "
                f"measurement), got shape {C.shape}"
            )
        Q = check_covariance("Q", self.Q, F.shape[1])
        R = check_covariance("R", self.R, C.shape[0])
        for name, matrix in (("A", A), ("B", B), ("C", C), ("F", F), ("Q", Q), ("R", R)):
            object.__setattr__(self, name, matrix)
        # Fixed per model, so computed once rather than at every step.
        with np.errstate(over="ignore", invalid="ignore"):
            process_noise = F @ Q @ F.T
            process_noise = 0.5 * (process_noise + process_noise.T)
        if not np.isfinite(process_noise).all():
            raise InvalidInputError(f"F, Q: the process noise F Q F' overflows: F = {short(F)}, "
                                    f"Q = {short(Q)}")
        process_noise.setflags(write=False)
        identity = np.eye(n)
        identity.setflags(write=False)
        object.__setattr__(self, "process_noise", process_noise)
        object.__setattr__(self, "identity", identity)
        # Halving is exact in binary floating point, so products with A'/2 are
        # bit for bit half the products with A'.
        for name, matrix in (("half_A_transposed", 0.5 * A.T), ("C_transposed", C.T)):
            matrix = np.ascontiguousarray(matrix)
            matrix.setflags(write=False)
            object.__setattr__(self, name, matrix)

    @property
    def state_size(self) -> int:
        """Dimension of the state x."""
        return int(self.A.shape[0])

    @property
    def input_size(self) -> int:
        """Dimension of the input u."""
        return int(self.B.shape[1])

    @property
    def measurement_size(self) -> int:
        """Dimension of the measurement z."""
        return int(self.C.shape[0])

    @classmethod
    def scalar(cls, var_u: float, var_z: float) -> LinearGaussianModel:
        """A = B = C = F = 1: the matrix form of Algorithm 4."""
        one = np.ones((1, 1))
        var_u, var_z = check_finite("var_u", var_u), check_finite("var_z", var_z)
        return cls(one, one, one, one, np.array([[var_u]]), np.array([[var_z]]))


@dataclass(frozen=True)
class GaussianState:
    """A mean and its covariance, checked: finite, matching shapes, P symmetric PSD."""

    x: FloatArray
    P: FloatArray

    def __post_init__(self) -> None:
        x = as_finite_array("x0", self.x, ndim=1)
        if x.size == 0:
            raise InputSizeError("x0: expected at least one state value, got none")
        P = check_covariance("P0", self.P, x.size)
        object.__setattr__(self, "x", x)
        object.__setattr__(self, "P", P)
