"""What the belief says: its most likely state and pose, the spread around a pose, the
mass near it, its picture and its entropy."""

from __future__ import annotations

import numpy as np

from estimation_nodes.core.errors import InvalidInputError, NonFiniteResultError
from estimation_nodes.core.grid.model import (
    GridModel,
    _any_belief,
    _check_model,
    _wrap,
    _wrap_scalar,
    check_belief,
    check_pose,
)
from estimation_nodes.core.validation import FloatArray, check_integer, check_non_negative, short


def most_likely_state(belief: FloatArray) -> tuple[int, int, int]:
    return _most_likely_state(_any_belief(belief))


def _most_likely_state(belief: FloatArray) -> tuple[int, int, int]:
    """The first state of the largest probability (in (k, i, j) order, as np.argmax):
    found a heading layer at a time, so that a belief whose layers are one array
    repeated (a start's uniform belief, ``np.broadcast_to``) is never copied whole."""
    k = int(np.argmax(belief.max(axis=(1, 2))))
    i, j = np.unravel_index(int(np.argmax(belief[k])), belief.shape[1:])
    return k, int(i), int(j)


def pose_of(model: GridModel, state: tuple[int, int, int]) -> tuple[float, float, float]:
    """(x, y, yaw) of a state cell's centre."""
    _check_model(model)
    try:
        k, i, j = (check_integer("state", v) for v in state)
    except (TypeError, ValueError):
        raise InvalidInputError(f"state: expected (k, i, j) integers, got {short(state)}") \
            from None
    if not all(0 <= v < n for v, n in zip((k, i, j), model.shape)):
        raise InvalidInputError(f"state: expected (k, i, j) within {model.shape}, got "
                                f"{(k, i, j)}")
    return _pose_of(model, (k, i, j))


def _centres(model: GridModel,
             box: tuple[int, int, int, int] | None) -> tuple[FloatArray, FloatArray]:
    """The cell centres of the map, or of the window ``box`` (grid/window.py) of it: the
    map's own, so that a window's distances are the dense filter's to the last bit."""
    xs, ys = model.cell_centres()
    if box is None:
        return xs, ys
    r0, r1, c0, c1 = box
    return xs[c0:c1], ys[r0:r1]


def _pose_of(model: GridModel, state: tuple[int, int, int],
             box: tuple[int, int, int, int] | None = None) -> tuple[float, float, float]:
    """With ``box``, ``state`` is of the window's belief."""
    k, i, j = state
    xs, ys = _centres(model, box)
    return float(xs[j]), float(ys[i]), float(_wrap_scalar(k * model.bin_width))


def refined_pose(belief: FloatArray, model: GridModel,
                 state: tuple[int, int, int]) -> tuple[float, float, float]:
    """The belief's mean over ``state`` and its neighbours (one cell and one heading bin
    each way, headings cyclic): a pose finer than the grid, near the mode."""
    _check_model(model)
    pose_of(model, state)     # validates the state
    return _refined_pose(check_belief(belief, model), model, state)


def _refined_pose(belief: FloatArray, model: GridModel, state: tuple[int, int, int],
                  box: tuple[int, int, int, int] | None = None) -> tuple[float, float, float]:
    """With ``box``, ``state`` is of the window's belief. The cell centres of a
    neighbourhood weighted by their probability; a mode whose neighbours have none is its
    own centre."""
    k, i, j = state
    xs, ys = _centres(model, box)
    rows = slice(max(i - 1, 0), i + 2)
    cols = slice(max(j - 1, 0), j + 2)
    bins = (k + np.arange(-1, 2)) % belief.shape[0]
    near = belief[bins][:, rows, cols]
    total = float(near.sum())
    if not total > 0:
        return _pose_of(model, state, box)
    x = float(near.sum(axis=(0, 1)) @ xs[cols]) / total
    y = float(near.sum(axis=(0, 2)) @ ys[rows]) / total
    # Offsets of -1, 0, +1 bins from the mode's heading: no wrap within the neighbourhood.
    shift = float(near.sum(axis=(1, 2)) @ np.arange(-1.0, 2.0)) / total
    return x, y, float(_wrap_scalar((k + shift) * model.bin_width))


def covariance_around(belief: FloatArray, model: GridModel,
                      pose: tuple[float, float, float]) -> FloatArray:
    """The 3 x 3 second moment of (x, y, yaw) about ``pose`` under the belief (yaw
    differences wrapped to (-pi, pi]), plus the grid's own quantization variance."""
    _check_model(model)
    pose = check_pose("pose", pose)
    cov = _covariance_around(check_belief(belief, model), model, pose)
    if not np.isfinite(cov).all():
        raise NonFiniteResultError(f"pose: {pose} is too far from the map for a finite "
                                   f"second moment")
    return cov


def _covariance_around(belief: FloatArray, model: GridModel,
                       pose: tuple[float, float, float],
                       box: tuple[int, int, int, int] | None = None) -> FloatArray:
    xs, ys = _centres(model, box)
    px = belief.sum(axis=(0, 1))
    py = belief.sum(axis=(0, 2))
    pk = belief.sum(axis=(1, 2))
    dx, dy = xs - pose[0], ys - pose[1]
    dyaw = _wrap(model.headings() - pose[2])
    pxy = belief.sum(axis=0)
    cov = np.empty((3, 3))
    with np.errstate(over="ignore", invalid="ignore"):
        cov[0, 0] = px @ (dx * dx)
        cov[1, 1] = py @ (dy * dy)
        cov[2, 2] = pk @ (dyaw * dyaw)
        cov[0, 1] = cov[1, 0] = float(dy @ pxy @ dx)
        cov[0, 2] = cov[2, 0] = float(dyaw @ belief.sum(axis=1) @ dx)
        cov[1, 2] = cov[2, 1] = float(dyaw @ belief.sum(axis=2) @ dy)
    quantization = np.diag([model.resolution ** 2 / 12] * 2 + [model.bin_width ** 2 / 12])
    return cov + quantization


def mass_near(belief: FloatArray, model: GridModel, pose: tuple[float, float, float],
              radius: float, angle: float) -> float:
    """The belief's probability within ``radius`` (m) and ``angle`` (rad) of ``pose``:
    how sure the robot is of that pose (1: certain, near 0: lost)."""
    _check_model(model)
    pose = check_pose("pose", pose)
    radius, angle = check_non_negative("radius", radius), check_non_negative("angle", angle)
    return _mass_near(check_belief(belief, model), model, pose, radius, angle)


def _mass_near(belief: FloatArray, model: GridModel, pose: tuple[float, float, float],
               radius: float, angle: float,
               box: tuple[int, int, int, int] | None = None) -> float:
    xs, ys = _centres(model, box)
    dx, dy = xs[None, :] - pose[0], ys[:, None] - pose[1]
    if radius < 1e150:
        with np.errstate(over="ignore"):   # a pose that far is near no cell: inf > r^2
            near_xy = (dx ** 2 + dy ** 2) <= radius ** 2
    else:   # r^2 would overflow (an OverflowError of Python's floats): compare distances
        near_xy = np.hypot(dx, dy) <= radius
    near_k = np.abs(_wrap(model.headings() - pose[2])) <= angle
    return float(belief[near_k][:, near_xy].sum())


def belief_map(belief: FloatArray) -> np.ndarray:
    """The belief's maximum over headings scaled to 0..100 (int8), the largest 100: the
    picture an OccupancyGrid display draws."""
    return _belief_map(_any_belief(belief))


def _belief_map(belief: FloatArray) -> np.ndarray:
    top = belief.max(axis=0)
    peak = top.max()
    scaled = np.rint(100.0 * top / peak) if peak > 0 else np.zeros_like(top)
    return scaled.astype(np.int8)


def entropy_bits(belief: FloatArray) -> float:
    return _entropy_bits(_any_belief(belief, ndim=None))


def _entropy_bits(belief: FloatArray) -> float:
    """Summed a heading layer at a time (as ``_most_likely_state``: the temporaries are a
    layer's)."""
    layers = belief.reshape(-1, *belief.shape[-2:]) if belief.ndim > 2 else belief[None]
    total = 0.0
    for layer in layers:
        positive = layer[layer > 0]
        total -= float((positive * np.log2(positive)).sum())
    return total + 0.0
