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


def gaussian_prior_window(model: GridModel, x: float, y: float, yaw: float,
                          covariance: FloatArray, cut: float
                          ) -> tuple[tuple[int, int, int, int], FloatArray, float]:
    """``gaussian_prior`` within the box of the states whose unnormalized value (1 at the
    most likely state) is at least ``cut``: that box (first row, row past the last, first
    column, column past the last), the prior within it, and the probability of the states
    left out, each of which is below ``cut`` (a floor of that size would drop them).
    Normalized over every state, as ``gaussian_prior``, which refuses what this refuses;
    nothing the building's size is made."""
    _check_model(model)
    x, y, yaw = check_pose("pose", (x, y, yaw))
    information = _information(model, covariance)
    lowest = _lowest_exponent(model, (x, y, yaw), information)
    near = np.zeros(model.free.shape, dtype=bool)
    total = 0.0
    for values in _prior_values(model, (x, y, yaw), information, lowest):
        total += float(values.sum())
        near |= values >= cut
    rows, cols = np.flatnonzero(near.any(axis=1)), np.flatnonzero(near.any(axis=0))
    r0, r1, c0, c1 = int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1
    part = np.empty((model.heading_bins, r1 - r0, c1 - c0))
    for k, values in enumerate(_prior_values(model, (x, y, yaw), information, lowest)):
        part[k] = values[r0:r1, c0:c1]
    written = float(part.sum())
    part /= total
    return (r0, r1, c0, c1), part, max(0.0, (total - written) / total)


def _information(model: GridModel, covariance: FloatArray) -> FloatArray:
    """The Gaussian's information matrix, the grid's own spread (half a cell, half a
    heading bin) added to its covariance."""
    cov = _covariance_3x3(covariance)
    floor = np.diag([(model.resolution / 2) ** 2] * 2 + [(model.bin_width / 2) ** 2])
    try:
        information = np.asarray(np.linalg.inv(cov + floor), dtype=np.float64)
    except np.linalg.LinAlgError:
        raise InvalidInputError(f"covariance: singular to rounding once the grid's own "
                                f"spread is added: {short(cov)}") from None
    return information


def _lowest_exponent(model: GridModel, pose: tuple[float, float, float],
                     information: FloatArray) -> float:
    """The lowest exponent over the free states, a layer at a time; a pose too far from
    the map for a finite prior refused (``NonFiniteResultError``)."""
    lowest = min(float(np.min(layer, where=model.free, initial=np.inf))
                 for layer in _prior_layers(model, pose, information))
    if not math.isfinite(lowest):   # NaN or inf anywhere: min is NaN, or inf everywhere
        raise NonFiniteResultError(f"x, y, covariance: the pose ({pose[0]:g}, {pose[1]:g}) "
                                   f"is too far from the map (or the covariance too "
                                   f"extreme) for a finite prior")
    return lowest


def gaussian_prior(model: GridModel, x: float, y: float, yaw: float,
                   covariance: FloatArray, out: FloatArray | None = None) -> FloatArray:
    """A prior from a pose and its 3 x 3 covariance over (x, y, yaw), as RViz's "2D Pose
    Estimate" sends one, restricted to free cells; never all zero (the free states
    nearest in the Gaussian's metric take the mass when it covers none). A pose so far
    from the map that its distance to it overflows is refused (``NonFiniteResultError``),
    ``out`` (as ``uniform_over_free``'s) then untouched."""
    _check_model(model)
    x, y, yaw = check_pose("pose", (x, y, yaw))
    information = _information(model, covariance)
    # The lowest exponent over the free states first: a refused prior writes nothing.
    lowest = _lowest_exponent(model, (x, y, yaw), information)
    # Written a layer at a time, no temporary of the belief's size: a real building's
    # prior is hundreds of MB.
    belief = _belief_array(model, out)
    for k, values in enumerate(_prior_values(model, (x, y, yaw), information, lowest)):
        belief[k] = values
    belief /= belief.sum()
    return belief


def _prior_values(model: GridModel, pose: tuple[float, float, float],
                  information: FloatArray, lowest: float) -> Iterator[FloatArray]:
    """Each heading layer's prior before it is normalized: exp(-(d' I d - lowest) / 2) on
    the free cells, 0 on walls and unknown space. The most likely free state gets exp(0)
    = 1, so the sum is never 0: where the Gaussian covers no free cell, the free states
    nearest in its metric take the mass."""
    for layer in _prior_layers(model, pose, information):
        layer -= lowest
        layer *= -0.5
        yield np.exp(layer, where=model.free, out=np.zeros_like(layer))


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
