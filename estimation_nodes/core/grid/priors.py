"""Priors over the grid's states: not knowing where the robot is, or a pose and its covariance."""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import numpy as np

from estimation_nodes.core.errors import InvalidInputError, NonFiniteResultError
from estimation_nodes.core.grid.model import GridModel, _check_model, _wrap, check_pose
from estimation_nodes.core.validation import FloatArray, as_real_array, check_covariance, short


def _covariance_3x3(covariance: Any) -> FloatArray:
    """A 3 x 3 covariance over (x, y, yaw), given as 3 x 3 or as 9 values (row-major)."""
    matrix = as_real_array("covariance", covariance)
    if matrix.size == 9:
        matrix = matrix.reshape(3, 3)
    return check_covariance("covariance", matrix, 3)


def uniform_over_free(model: GridModel, out: FloatArray | None = None) -> FloatArray:
    """Not knowing where the robot is: equal probability on every free cell and heading.
    ``out``: a float array of the model's shape to write it in (a building's belief is
    hundreds of MB: the localizer's own is reused, not a second one made)."""
    _check_model(model)
    layer = model.free / float(np.count_nonzero(model.free) * model.shape[0])
    belief = _belief_array(model, out)
    belief[:] = layer     # one tensor, no temporary of its size
    return belief


def _belief_array(model: GridModel, out: FloatArray | None) -> FloatArray:
    if out is None:
        return np.empty(model.shape)
    if out.shape != model.shape or out.dtype != np.float64 or not out.flags.c_contiguous:
        raise InvalidInputError(f"out: expected a C-contiguous float array of shape "
                                f"{model.shape}, got {out.dtype} {out.shape}")
    return out


def gaussian_prior(model: GridModel, x: float, y: float, yaw: float,
                   covariance: FloatArray, out: FloatArray | None = None) -> FloatArray:
    """A prior from a pose and its 3 x 3 covariance over (x, y, yaw), as RViz's "2D Pose
    Estimate" sends one, restricted to free cells; never all zero (the free states
    nearest in the Gaussian's metric take the mass when it covers none). A pose so far
    from the map that its distance to it overflows is refused (``NonFiniteResultError``),
    ``out`` (as ``uniform_over_free``'s) then untouched."""
    _check_model(model)
    x, y, yaw = check_pose("pose", (x, y, yaw))
    cov = _covariance_3x3(covariance)
    floor = np.diag([(model.resolution / 2) ** 2] * 2 + [(model.bin_width / 2) ** 2])
    try:
        information = np.linalg.inv(cov + floor)
    except np.linalg.LinAlgError:
        raise InvalidInputError(f"covariance: singular to rounding once the grid's own "
                                f"spread is added: {short(cov)}") from None
    # The lowest exponent over the free states first, a layer at a time: a refused prior
    # writes nothing.
    lowest = min(float(np.min(layer, where=model.free, initial=np.inf))
                 for layer in _prior_layers(model, (x, y, yaw), information))
    if not math.isfinite(lowest):   # NaN or inf anywhere: min is NaN, or inf everywhere
        raise NonFiniteResultError(f"x, y, covariance: the pose ({x:g}, {y:g}) is too far "
                                   f"from the map (or the covariance too extreme) for a "
                                   f"finite prior")
    exponent = _belief_array(model, out)
    for k, layer in enumerate(_prior_layers(model, (x, y, yaw), information)):
        exponent[k] = layer
    # Walls and unknown space out: inf there, exp() makes them 0.
    exponent[:, ~model.free] = np.inf
    # In place, one tensor: a real building's prior is hundreds of MB. The most likely
    # free state gets exp(0) = 1, so the sum is never 0: where the Gaussian covers no free
    # cell, the free states nearest in its metric take the mass.
    exponent -= lowest
    exponent *= -0.5
    belief = np.exp(exponent, out=exponent)
    belief /= belief.sum()
    return belief


def _prior_layers(model: GridModel, pose: tuple[float, float, float],
                  information: np.ndarray) -> Iterator[FloatArray]:
    """The Gaussian's exponent d' I d for every state, a heading layer at a time (the
    temporaries are of one layer, not of the whole belief)."""
    x, y, yaw = pose
    xs, ys = model.cell_centres()
    with np.errstate(over="ignore", invalid="ignore"):
        dx = (xs - x)[None, :]
        dy = (ys - y)[:, None]
        planar = (information[0, 0] * dx * dx + information[1, 1] * dy * dy
                  + 2 * information[0, 1] * dx * dy)
        across = 2 * information[0, 2] * dx + 2 * information[1, 2] * dy
        for dyaw in _wrap(model.headings() - yaw):
            yield planar + dyaw * (information[2, 2] * dyaw + across)
