"""The odometry motion model over the grid (Probabilistic Robotics 5.4): the prediction.

- ``predict``: each heading layer is shifted by the odometry displacement
  rotated into that heading (bilinear weights over the four nearest cells),
  the headings by the rotation (linear weights over the two nearest bins),
  then spread by Gaussian noise growing with the motion (AMCL's alphas);
  mass that lands on an occupied cell or off the map is dropped and the rest
  renormalized. O(states x kernel), no transition matrix.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import ModuleType
from typing import Any

import numpy as np

from estimation_nodes.core.errors import InvalidInputError, NonFiniteResultError, ZeroEvidenceError
from estimation_nodes.core.grid.model import (
    TWO_PI,
    GridModel,
    _check_model,
    _numbers,
    _wrap_scalar,
    check_belief,
    check_pose,
    compiled_kernels,
)
from estimation_nodes.core.validation import FloatArray, check_finite, check_non_negative, short

#: The widest Gaussian kernel listed tap by tap (``gaussian_taps``), in taps either side.
#: A blur along x or y never needs more taps than the axis has cells, nor one over the
#: headings more than the headings (see ``_reaching_taps`` and ``_heading_taps``).
MAX_TAPS_HALF_WIDTH = 1 << 20


@dataclass(frozen=True)
class OdometryNoise:
    """The odometry motion model's noise (Probabilistic Robotics 5.4; AMCL's alpha1..4).

    alpha1: rotation noise from rotation, alpha2: rotation from translation,
    alpha3: translation from translation, alpha4: translation from rotation;
    ``floor_m`` and ``floor_rad`` keep a little spread on every step, so a grid
    of finite resolution can follow a robot whose odometry is slightly off.
    """

    alpha1: float
    alpha2: float
    alpha3: float
    alpha4: float
    floor_m: float = 0.02
    floor_rad: float = 0.02

    def __post_init__(self) -> None:
        for name in ("alpha1", "alpha2", "alpha3", "alpha4", "floor_m", "floor_rad"):
            value = getattr(self, name)
            try:
                number = check_non_negative(name, value)
            except InvalidInputError:
                raise InvalidInputError(
                    f"{name}: expected a finite value >= 0, got {short(value)}") from None
            object.__setattr__(self, name, number)


def check_delta(delta: Any) -> tuple[float, float, float]:
    """(rot1, trans, rot2) of an odometry motion (Table 5.6, as ``odometry_delta`` gives
    it): finite, rot1 and rot2 in [-pi, pi], trans >= 0."""
    rot1, trans, rot2 = _numbers("delta", delta, ("rot1", "trans", "rot2"))
    if not (abs(rot1) <= math.pi and abs(rot2) <= math.pi and trans >= 0.0):
        raise InvalidInputError(f"delta: expected (rot1, trans, rot2) with rot1 and rot2 in "
                                f"[-pi, pi] and trans >= 0, got {short(delta)}")
    return rot1, trans, rot2


def odometry_delta(previous: tuple[float, float, float],
                   current: tuple[float, float, float]) -> tuple[float, float, float]:
    """(rot1, trans, rot2) between two odometry poses (x, y, yaw): Probabilistic
    Robotics Table 5.6. A turn on the spot is all rot1. Poses so far apart that their
    difference overflows are refused (``NonFiniteResultError``)."""
    previous = check_pose("previous", previous)
    current = check_pose("current", current)
    dx, dy = current[0] - previous[0], current[1] - previous[1]
    turn = current[2] - previous[2]
    if not (math.isfinite(dx) and math.isfinite(dy) and math.isfinite(turn)):
        raise NonFiniteResultError("previous, current: their difference overflows: "
                                   f"{current} and {previous}")
    trans = math.hypot(dx, dy)
    rot1 = _wrap_scalar(math.atan2(dy, dx) - previous[2]) if trans > 1e-9 else 0.0
    rot2 = _wrap_scalar(turn - rot1)
    return rot1, trans, rot2


def motion_noise(delta: tuple[float, float, float], noise: OdometryNoise,
                 model: GridModel) -> tuple[float, float]:
    """The spread of a motion: std in cells (x and y) and in heading bins."""
    if not isinstance(noise, OdometryNoise):
        raise InvalidInputError(f"noise: expected an OdometryNoise, got {type(noise).__name__}")
    sigma_cells, sigma_bins = _motion_noise(check_delta(delta), noise, _check_model(model))
    if not (math.isfinite(sigma_cells) and math.isfinite(sigma_bins)):
        raise NonFiniteResultError(f"delta, noise: the spread of {delta} overflows")
    return sigma_cells, sigma_bins


#: Below this translation (m) the direction of travel is odometry's jitter, not a turn:
#: the motion's noise is that of a turn on the spot (nav2_amcl's 0.01 m).
JITTER_M = 0.01


def _motion_noise(delta: tuple[float, float, float], noise: OdometryNoise,
                  model: GridModel) -> tuple[float, float]:
    """``motion_noise``: inf when the motion is so extreme that it overflows (the blurs
    take an infinite sigma as an even spread).

    The rotations' sizes are those of ``noise_rotations``: the motion itself is shifted
    exactly as odometry says, only its noise is AMCL's."""
    turned = noise_rotations(delta)
    trans = delta[1]
    sigma_m = noise.floor_m + noise.alpha3 * trans + noise.alpha4 * turned
    sigma_rad = noise.floor_rad + noise.alpha1 * turned + noise.alpha2 * trans
    return sigma_m / model.resolution, sigma_rad / model.bin_width


def noise_rotations(delta: tuple[float, float, float]) -> float:
    """|rot1| + |rot2| as the motion noise takes them (nav2_amcl's differential model):

    - driving backwards is rot1 near pi, then rot2 near -pi, and is as certain as driving
      forwards: each rotation counts as its distance to 0 or to pi, the nearer;
    - a translation below JITTER_M is jitter (a robot turning on the spot, its odometry
      a few mm off to any side): the motion counts as the turn alone.

    Taken at face value, either made a turn of 0.1 rad count as 2 pi, and the blur spread
    a tracked belief by metres (seen on a steady laser: a wandering robot turning on the
    spot, every scan an update)."""
    rot1, trans, rot2 = delta
    if trans < JITTER_M:
        return abs(math.remainder(rot1 + rot2, TWO_PI))
    return sum(min(abs(rotation), math.pi - abs(rotation)) for rotation in (rot1, rot2))


def layer_shifts(model: GridModel, rot1: float, trans: float) -> tuple[FloatArray, FloatArray]:
    """How far (rows, columns) each heading layer moves: the displacement seen from it."""
    _check_model(model)
    rot1, trans = check_finite("rot1", rot1), check_finite("trans", trans)
    shift_rows, shift_cols = _layer_shifts(model, rot1, trans)
    if not (np.isfinite(shift_rows).all() and np.isfinite(shift_cols).all()):
        raise NonFiniteResultError(f"trans: {trans:g} m overflows in cells of "
                                   f"{model.resolution:g} m")
    return shift_rows, shift_cols


def _layer_shifts(model: GridModel, rot1: float, trans: float) -> tuple[FloatArray, FloatArray]:
    angles = model.headings() + rot1
    with np.errstate(over="ignore"):
        return (trans * np.sin(angles) / model.resolution,
                trans * np.cos(angles) / model.resolution)


def _bounded_shifts(model: GridModel, rot1: float,
                    trans: float) -> tuple[FloatArray, FloatArray]:
    """``layer_shifts`` cut to the grid's size plus one cell: a shift that long already
    moves every cell off the grid, so the result is the same (all lost), and the kernels
    take whole cells as exact int64s."""
    rows, cols = model.free.shape
    shift_rows, shift_cols = _layer_shifts(model, rot1, trans)
    return (np.clip(shift_rows, -(rows + 1), rows + 1),
            np.clip(shift_cols, -(cols + 1), cols + 1))


def predict(belief: FloatArray, model: GridModel, delta: tuple[float, float, float],
            noise: OdometryNoise, compiled: bool = True) -> FloatArray:
    """The belief after a motion (rot1, trans, rot2) measured by odometry (``check_delta``).

    A motion that moves all the belief off the free cells (a long one, off the map) is
    refused with ``ZeroEvidenceError`` naming ``delta``.
    """
    _check_model(model)
    if not isinstance(noise, OdometryNoise):
        raise InvalidInputError(f"noise: expected an OdometryNoise, got {type(noise).__name__}")
    return _predict(check_belief(belief, model), model, check_delta(delta), noise, compiled)


def _predict(belief: FloatArray, model: GridModel, delta: tuple[float, float, float],
             noise: OdometryNoise, compiled: bool = True) -> FloatArray:
    """``predict`` of arguments already checked."""
    return _normalized(*_spread(belief, model, delta, noise, compiled))


def _spread(belief: FloatArray, model: GridModel, delta: tuple[float, float, float],
            noise: OdometryNoise, compiled: bool = True,
            grid_states: int | None = None) -> tuple[FloatArray, float]:
    """The prediction before it is normalized, and its sum (the probability left on free
    cells): a belief held in several windows (grid/window.py) is normalized over all.
    ``grid_states``: the states of the grid a window is cut from, which choose the
    compiled kernels or numpy's (``compiled_kernels``) as for the whole grid."""
    kernels = compiled_kernels(grid_states or belief.size, compiled)
    if kernels is not None:
        return _spread_compiled(kernels, belief, model, delta, noise)
    rot1, trans, rot2 = delta
    shift_rows, shift_cols = _bounded_shifts(model, rot1, trans)
    shifted = np.empty_like(belief)
    for k in range(model.heading_bins):
        shifted[k] = _shift_bilinear(belief[k], shift_cols[k], shift_rows[k])
    turned = _shift_headings(shifted, (rot1 + rot2) / model.bin_width)
    sigma_cells, sigma_bins = _motion_noise(delta, noise, model)
    rows, cols = model.free.shape
    spread = _blur_cyclic(turned, _heading_taps(sigma_bins, model.heading_bins), axis=0)
    spread = _blur(spread, _reaching_taps(sigma_cells, rows), axis=1)
    spread = _blur(spread, _reaching_taps(sigma_cells, cols), axis=2)
    spread *= model.free[None, :, :]
    return spread, float(spread.sum())


def _spread_compiled(kernels: ModuleType, belief: FloatArray, model: GridModel,
                     delta: tuple[float, float, float],
                     noise: OdometryNoise) -> tuple[FloatArray, float]:
    rot1, trans, rot2 = delta
    shift_rows, shift_cols = _bounded_shifts(model, rot1, trans)
    sigma_cells, sigma_bins = _motion_noise(delta, noise, model)
    rows, cols = model.free.shape
    first, second = np.empty_like(belief), np.empty_like(belief)
    # The heading layers that may hold probability, through each pass: the others are
    # zero before and after it, and are not passed over (a tracked belief holds a few).
    held, made = belief.any(axis=(1, 2)), np.empty(model.heading_bins, dtype=bool)
    kernels.shift_motion(belief, shift_rows, shift_cols, (rot1 + rot2) / model.bin_width,
                         held, first, made)
    held, made = made, held
    taps = _heading_taps(sigma_bins, model.heading_bins)
    if not _identity(taps):
        kernels.blur_headings(first, taps, held, second, made)
        first, second = second, first
        held, made = made, held
    taps = _reaching_taps(sigma_cells, rows)
    if not _identity(taps):
        kernels.blur_rows(first, taps, held, second)
        first, second = second, first
    total = kernels.blur_cols_masked(first, _reaching_taps(sigma_cells, cols), model.free,
                                     held, second)
    return second, float(total)


def _normalized(belief: FloatArray, total: float) -> FloatArray:
    if not total > 0:
        raise ZeroEvidenceError("delta: the motion left no probability on a free cell")
    belief /= total
    return belief


# --- the prediction's pieces: fractional shifts, Gaussian blurs ----------------------------


def _shift_bilinear(layer: FloatArray, shift_cols: float, shift_rows: float) -> FloatArray:
    """``layer`` moved by a fractional number of columns and rows: each cell's mass split
    over the four nearest target cells by bilinear weights; what leaves the grid is lost."""
    base_c, base_r = math.floor(shift_cols), math.floor(shift_rows)
    frac_c, frac_r = shift_cols - base_c, shift_rows - base_r
    out = np.zeros_like(layer)
    for dr, wr in ((0, 1.0 - frac_r), (1, frac_r)):
        for dc, wc in ((0, 1.0 - frac_c), (1, frac_c)):
            weight = wr * wc
            if weight > 0:
                _add_shifted(out, layer, base_r + dr, base_c + dc, weight)
    return out


def _add_shifted(out: FloatArray, layer: FloatArray, rows: int, cols: int,
                 weight: float) -> None:
    """out[i + rows, j + cols] += weight * layer[i, j], where both are inside."""
    height, width = layer.shape
    if abs(rows) >= height or abs(cols) >= width:
        return
    src_r = slice(max(0, -rows), min(height, height - rows))
    dst_r = slice(max(0, rows), min(height, height + rows))
    src_c = slice(max(0, -cols), min(width, width - cols))
    dst_c = slice(max(0, cols), min(width, width + cols))
    out[dst_r, dst_c] += weight * layer[src_r, src_c]


def _shift_headings(belief: FloatArray, shift_bins: float) -> FloatArray:
    """Headings turned by a fractional number of bins (cyclic, linear weights)."""
    base = math.floor(shift_bins)
    frac = shift_bins - base
    out = (1.0 - frac) * np.roll(belief, base, axis=0)
    if frac > 0:
        out += frac * np.roll(belief, base + 1, axis=0)
    return out


def _half_width(sigma: float) -> int:
    """How many taps either side ``gaussian_taps`` lists (3 sigma), or one more than it
    may (MAX_TAPS_HALF_WIDTH + 1) for a wider, or infinite, sigma."""
    three = 3.0 * sigma
    return math.ceil(three) if three <= MAX_TAPS_HALF_WIDTH else MAX_TAPS_HALF_WIDTH + 1


def gaussian_taps(sigma: float) -> FloatArray:
    """A normalized Gaussian kernel of std ``sigma`` (in cells) over -3 sigma..3 sigma;
    [1] when sigma is too small to spread. At most MAX_TAPS_HALF_WIDTH taps either side:
    a wider sigma is refused (the steps cut theirs to the axis, see ``_reaching_taps``)."""
    sigma = check_non_negative("sigma", sigma)
    half = _half_width(sigma)
    if half > MAX_TAPS_HALF_WIDTH:
        raise InvalidInputError(f"sigma: {sigma:g} cells needs more than "
                                f"{MAX_TAPS_HALF_WIDTH} taps either side")
    return _gaussian_taps(sigma, half)


def _gaussian_taps(sigma: float, half: int) -> FloatArray:
    if half == 0:
        return np.ones(1)
    offsets = np.arange(-half, half + 1)
    taps = np.exp(-0.5 * (offsets / sigma) ** 2)
    return taps / taps.sum()


def _identity(taps: FloatArray) -> bool:
    return taps.size == 1 and taps[0] == 1.0


def _reaching_taps(sigma: float, length: int) -> FloatArray:
    """The taps of a blur of std ``sigma`` along an axis of ``length`` cells (not cyclic).

    Taps more than length - 1 away reach only the zeros beyond the edge, so they are cut:
    the blur is the same, bit for bit, and its cost and memory follow the axis, not
    sigma. A sigma too wide to list its taps (beyond MAX_TAPS_HALF_WIDTH) gets those within
    reach normalized among themselves: the prediction is normalized at its end, so only
    the taps' ratios matter (an infinite sigma spreads evenly).
    """
    half = _half_width(sigma)
    reach = length - 1
    if half <= reach:
        return _gaussian_taps(sigma, half)
    if half <= MAX_TAPS_HALF_WIDTH:
        return _gaussian_taps(sigma, half)[half - reach:half + reach + 1]
    offsets = np.arange(-reach, reach + 1)
    taps = np.exp(-0.5 * (offsets / sigma) ** 2)
    return taps / taps.sum()


def _heading_taps(sigma: float, bins: int) -> FloatArray:
    """The taps of the cyclic blur of std ``sigma`` over ``bins`` headings.

    Up to 3 sigma of four turns (4 K taps either side) they are ``gaussian_taps``, the
    blur passing over the headings once per tap. A wider kernel is folded around the
    circle (the taps of each heading offset modulo K summed), so the blur takes at most
    K + 1 passes whatever sigma: the same blur, to rounding. Beyond MAX_TAPS_HALF_WIDTH
    taps (a std of over 349,000 bins, an infinite one included) the spread is uniform:
    the folded kernel differs from even by less than 0.005 K / sigma there.
    """
    half = _half_width(sigma)
    if half <= 4 * bins:
        return _gaussian_taps(sigma, half)
    if half > MAX_TAPS_HALF_WIDTH:
        return np.full(bins, 1.0 / bins)
    folded = np.bincount(np.arange(-half, half + 1) % bins, weights=_gaussian_taps(sigma, half),
                         minlength=bins)
    # Centred taps for offsets -(K // 2)..K // 2: each residue once (for an even K the
    # last offset, K / 2, is the first one again and gets nothing).
    centre = bins // 2
    return np.concatenate([folded[np.arange(-centre, bins - centre) % bins],
                           np.zeros(1 - bins % 2)])


def _blur(belief: FloatArray, taps: FloatArray, axis: int) -> FloatArray:
    """Spread along ``axis`` (not cyclic: what spreads past the edge is lost)."""
    if _identity(taps):
        return belief
    half = taps.size // 2
    moved = np.moveaxis(belief, axis, -1)
    padded = np.pad(moved, [(0, 0)] * (moved.ndim - 1) + [(half, half)])
    out = np.zeros_like(moved)
    n = moved.shape[-1]
    for index, tap in enumerate(taps):
        out += tap * padded[..., index:index + n]
    return np.moveaxis(out, -1, axis)


def _blur_cyclic(belief: FloatArray, taps: FloatArray, axis: int) -> FloatArray:
    """Spread along a cyclic ``axis`` (the headings)."""
    if _identity(taps):
        return belief
    half = taps.size // 2
    out = np.zeros_like(belief)
    for index, tap in enumerate(taps):
        out += tap * np.roll(belief, index - half, axis=axis)
    return out
