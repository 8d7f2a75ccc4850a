"""Random draws of the simulated world: where a move lands, what a sensor reports.

The tile sensor node uses these with a seeded generator, so a seeded run is
repeatable; the filters never draw.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from estimation_nodes.core.kalman.models import LinearGaussianModel
from estimation_nodes.core.tiles.models import MotionKernel
from estimation_nodes.core.validation import FloatArray


def sample_offset(kernel: MotionKernel, rng: np.random.Generator) -> int:
    """Draw where a real move lands relative to its target, as the kernel says."""
    return int(rng.choice(kernel.offsets, p=kernel.weights))


def sample_observation(
    probabilities: npt.NDArray[np.float64], true_class: int, rng: np.random.Generator
) -> int:
    """Draw an observed class index for a tile of class ``true_class``."""
    return int(rng.choice(probabilities.shape[1], p=probabilities[true_class]))


def linear_system_step(
    x: FloatArray, u: FloatArray, model: LinearGaussianModel, rng: np.random.Generator
) -> tuple[FloatArray, FloatArray]:
    """One step of the book's Eq. 6.34 with noise drawn from its Q and R.

    x(k+1) = A x(k) + B u(k) + F w(k),  w ~ N(0, Q);  z(k+1) = C x(k+1) + v,  v ~ N(0, R).
    Returns the next true state and its measurement.
    """
    w = rng.multivariate_normal(np.zeros(model.Q.shape[0]), model.Q)
    x_next = model.A @ x + model.B @ u + model.F @ w
    v = rng.multivariate_normal(np.zeros(model.R.shape[0]), model.R)
    return x_next, model.C @ x_next + v
