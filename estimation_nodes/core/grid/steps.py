"""Grid Markov localization: the histogram filter over (heading, y, x) on a map.

The belief is a tensor ``b[k, i, j]``: the probability that the robot is in
state cell (row i, column j) with heading bin k (heading ``k * 2 pi / K``),
rows along y and columns along x, as nav_msgs/OccupancyGrid stores a map
(row 0 at the map's origin). Probabilistic Robotics ch. 8 (grid localization)
with the odometry motion model (5.4) and the likelihood-field sensor model
(6.4); Fox, Burgard and Thrun 1999.

- ``predict``: each heading layer is shifted by the odometry displacement
  rotated into that heading (bilinear weights over the four nearest cells),
  the headings by the rotation (linear weights over the two nearest bins),
  then spread by Gaussian noise growing with the motion (AMCL's alphas);
  mass that lands on an occupied cell or off the map is dropped and the rest
  renormalized. O(states x kernel), no transition matrix.
- ``scan_log_likelihood``: for each beam and heading the end point is the
  same cell offset from every state cell, so the log likelihood of a beam
  over one heading layer is a shifted view of the log likelihood field.
- ``correct``: posterior and log evidence, as the 1-D filter's ``correct``.

The map's rotation (an OccupancyGrid origin with yaw) is not supported here:
the state grid refuses it (core/grid/likelihood_field.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import ModuleType

import numpy as np

from estimation_nodes.core.compiled_loader import load_kernels
from estimation_nodes.core.errors import ZeroEvidenceError
from estimation_nodes.core.validation import FloatArray

TWO_PI = 2.0 * math.pi
#: Beliefs of at least this many states take the compiled kernels (core/compiled_grid.py)
#: when numba imports; smaller ones never import it.
COMPILED_MIN_STATES = 100_000


@dataclass(frozen=True)
class GridModel:
    """The state grid and the likelihood field of one map.

    ``free``: (H, W) bool, the cells the robot may be in; ``log_field``: (H, W) log
    likelihood of a beam ending in each cell; ``log_outside``: that of a beam ending
    off the map; ``resolution`` in m per cell; ``origin`` the (x, y) of cell (0, 0)'s
    corner; ``heading_bins`` K.
    """

    free: np.ndarray
    log_field: FloatArray
    log_outside: float
    resolution: float
    origin: tuple[float, float]
    heading_bins: int

    def __post_init__(self) -> None:
        if self.free.ndim != 2 or self.free.shape != self.log_field.shape:
            raise ValueError(f"free and log_field: expected two arrays of one (H, W) shape, "
                             f"got {self.free.shape} and {self.log_field.shape}")
        if not self.free.any():
            raise ValueError("free: the map has no free cell")
        if not (self.resolution > 0 and math.isfinite(self.resolution)):
            raise ValueError(f"resolution: expected a finite value > 0, got {self.resolution}")
        if not all(math.isfinite(v) for v in self.origin):
            raise ValueError(f"origin: expected finite x and y, got {self.origin}")
        if self.heading_bins < 1:
            raise ValueError(f"heading_bins: expected >= 1, got {self.heading_bins}")
        if not (np.isfinite(self.log_field).all() and math.isfinite(self.log_outside)):
            raise ValueError("log_field: expected finite log likelihoods")

    @property
    def shape(self) -> tuple[int, int, int]:
        """(K, H, W): the belief tensor's shape."""
        return (self.heading_bins, *self.free.shape)

    @property
    def bin_width(self) -> float:
        return TWO_PI / self.heading_bins

    def headings(self) -> FloatArray:
        """The heading of each bin (rad), bin k at k * 2 pi / K."""
        return np.arange(self.heading_bins, dtype=np.float64) * self.bin_width

    def cell_centres(self) -> tuple[FloatArray, FloatArray]:
        """x of each column's centre, y of each row's centre (m)."""
        rows, cols = self.free.shape
        x = self.origin[0] + (np.arange(cols, dtype=np.float64) + 0.5) * self.resolution
        y = self.origin[1] + (np.arange(rows, dtype=np.float64) + 0.5) * self.resolution
        return x, y


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
            if not (value >= 0 and math.isfinite(value)):
                raise ValueError(f"{name}: expected a finite value >= 0, got {value}")


def uniform_over_free(model: GridModel) -> FloatArray:
    """Not knowing where the robot is: equal probability on every free cell and heading."""
    layer = model.free.astype(np.float64)
    belief = np.broadcast_to(layer, model.shape).copy()
    return belief / belief.sum()


def gaussian_prior(model: GridModel, x: float, y: float, yaw: float,
                   covariance: FloatArray) -> FloatArray:
    """A prior from a pose and its 3 x 3 covariance over (x, y, yaw), as RViz's "2D Pose
    Estimate" sends one, restricted to free cells; never all zero (the nearest free
    state takes the mass when the Gaussian covers none)."""
    cov = np.asarray(covariance, dtype=np.float64).reshape(3, 3)
    floor = np.diag([(model.resolution / 2) ** 2] * 2 + [(model.bin_width / 2) ** 2])
    information = np.linalg.inv(cov + floor)
    xs, ys = model.cell_centres()
    dx = xs[None, None, :] - x
    dy = ys[None, :, None] - y
    dyaw = _wrap(model.headings() - yaw)[:, None, None]
    exponent = (information[0, 0] * dx * dx + information[1, 1] * dy * dy
                + information[2, 2] * dyaw * dyaw + 2 * information[0, 1] * dx * dy
                + 2 * information[0, 2] * dx * dyaw + 2 * information[1, 2] * dy * dyaw)
    belief = np.exp(-0.5 * (exponent - exponent.min())) * model.free[None, :, :]
    total = belief.sum()
    if not total > 0:
        belief = np.zeros(model.shape)
        k, i, j = np.unravel_index(np.argmin(np.where(model.free[None], exponent, np.inf)),
                                   model.shape)
        belief[k, i, j] = 1.0
        return belief
    return belief / total


def odometry_delta(previous: tuple[float, float, float],
                   current: tuple[float, float, float]) -> tuple[float, float, float]:
    """(rot1, trans, rot2) between two odometry poses (x, y, yaw): Probabilistic
    Robotics Table 5.6. A turn on the spot is all rot1."""
    dx, dy = current[0] - previous[0], current[1] - previous[1]
    trans = math.hypot(dx, dy)
    rot1 = _wrap_scalar(math.atan2(dy, dx) - previous[2]) if trans > 1e-9 else 0.0
    rot2 = _wrap_scalar(current[2] - previous[2] - rot1)
    return rot1, trans, rot2


def _compiled_kernels() -> ModuleType | None:
    return load_kernels("estimation_nodes.core.grid.compiled")


def compiled_kernels(states: int, allowed: bool = True) -> ModuleType | None:
    """The compiled kernels a belief of ``states`` states uses, or None for numpy's."""
    return _compiled_kernels() if allowed and states >= COMPILED_MIN_STATES else None


def motion_noise(delta: tuple[float, float, float], noise: OdometryNoise,
                 model: GridModel) -> tuple[float, float]:
    """The spread of a motion: std in cells (x and y) and in heading bins."""
    rot1, trans, rot2 = delta
    sigma_m = noise.floor_m + noise.alpha3 * trans + noise.alpha4 * (abs(rot1) + abs(rot2))
    sigma_rad = noise.floor_rad + noise.alpha1 * (abs(rot1) + abs(rot2)) + noise.alpha2 * trans
    return sigma_m / model.resolution, sigma_rad / model.bin_width


def layer_shifts(model: GridModel, rot1: float, trans: float) -> tuple[FloatArray, FloatArray]:
    """How far (rows, columns) each heading layer moves: the displacement seen from it."""
    angles = model.headings() + rot1
    return (trans * np.sin(angles) / model.resolution,
            trans * np.cos(angles) / model.resolution)


def predict(belief: FloatArray, model: GridModel, delta: tuple[float, float, float],
            noise: OdometryNoise, compiled: bool = True) -> FloatArray:
    """The belief after a motion (rot1, trans, rot2) measured by odometry."""
    kernels = compiled_kernels(belief.size, compiled)
    if kernels is not None:
        return _predict_compiled(kernels, belief, model, delta, noise)
    rot1, trans, rot2 = delta
    shift_rows, shift_cols = layer_shifts(model, rot1, trans)
    shifted = np.empty_like(belief)
    for k in range(model.heading_bins):
        shifted[k] = _shift_bilinear(belief[k], shift_cols[k], shift_rows[k])
    turned = _shift_headings(shifted, (rot1 + rot2) / model.bin_width)
    sigma_cells, sigma_bins = motion_noise(delta, noise, model)
    spread = _blur_cyclic(turned, sigma_bins, axis=0)
    spread = _blur(spread, sigma_cells, axis=1)
    spread = _blur(spread, sigma_cells, axis=2)
    spread *= model.free[None, :, :]
    return _normalized(spread, float(spread.sum()))


def _predict_compiled(kernels: ModuleType, belief: FloatArray, model: GridModel,
                      delta: tuple[float, float, float], noise: OdometryNoise) -> FloatArray:
    rot1, trans, rot2 = delta
    shift_rows, shift_cols = layer_shifts(model, rot1, trans)
    sigma_cells, sigma_bins = motion_noise(delta, noise, model)
    first, second = np.empty_like(belief), np.empty_like(belief)
    kernels.shift_motion(belief, shift_rows, shift_cols, (rot1 + rot2) / model.bin_width, first)
    taps = gaussian_taps(sigma_bins)
    if taps.size > 1:
        kernels.blur_headings(first, taps, second)
        first, second = second, first
    taps = gaussian_taps(sigma_cells)
    if taps.size > 1:
        kernels.blur_rows(first, taps, second)
        first, second = second, first
    total = kernels.blur_cols_masked(first, taps, model.free, second)
    return _normalized(second, total)


def _normalized(belief: FloatArray, total: float) -> FloatArray:
    if not total > 0:
        raise ZeroEvidenceError("the motion left no probability on a free cell")
    belief /= total
    return belief


def beam_endpoints(model: GridModel, ranges: FloatArray, angles: FloatArray) -> np.ndarray:
    """(K, beams, 2) integer (row, column) offsets of each beam's end point from the
    state cell, for each heading bin: the cell the end point falls in, measured from
    the state cell's centre."""
    theta = model.headings()[:, None] + np.asarray(angles, dtype=np.float64)[None, :]
    r = np.asarray(ranges, dtype=np.float64)[None, :] / model.resolution
    return np.stack([np.floor(0.5 + r * np.sin(theta)), np.floor(0.5 + r * np.cos(theta))],
                    axis=-1).astype(np.int64)


def scan_log_likelihood(model: GridModel, ranges: FloatArray, angles: FloatArray,
                        compiled: bool = True) -> FloatArray:
    """Sum over the beams of log p(beam | state), for every state: (K, H, W).

    ``ranges`` and ``angles`` are the beams to use (already without max-range
    readings, which the likelihood-field model does not score).
    """
    offsets = beam_endpoints(model, ranges, angles)
    rows, cols = model.free.shape
    padded, pad = _padded_field(model, offsets)
    kernels = compiled_kernels(int(np.prod(model.shape)), compiled)
    if kernels is not None:
        out = np.empty(model.shape)      # the kernel writes every element
        kernels.scan_log_likelihood(padded, pad, offsets, model.heading_bins, rows, cols, out)
        return out
    total = np.zeros(model.shape)
    for k in range(model.heading_bins):
        layer = total[k]
        for dr, dc in offsets[k]:
            layer += padded[pad + dr:pad + dr + rows, pad + dc:pad + dc + cols]
    return total


def _padded_field(model: GridModel, offsets: np.ndarray) -> tuple[FloatArray, int]:
    """The log field with a border of ``log_outside`` wide enough for every offset."""
    pad = int(np.abs(offsets).max(initial=0)) + 1
    return np.pad(model.log_field, pad, constant_values=model.log_outside), pad


def correct_scan(belief: FloatArray, model: GridModel, ranges: FloatArray, angles: FloatArray,
                 compiled: bool = True) -> tuple[FloatArray, float]:
    """``correct`` with a scan: posterior and log evidence. (A compiled kernel that also
    weighted each row as soon as its beams were summed measured slower: numba's scalar exp
    costs more than the pass numpy's vectorized one needs.)"""
    return _correct_in(scan_log_likelihood(model, ranges, angles, compiled), belief)


def _correct_in(log_likelihood: FloatArray, belief: FloatArray) -> tuple[FloatArray, float]:
    """``correct``, the posterior written over ``log_likelihood`` (an array of ours): a
    tensor of millions of states allocated anew costs more than the arithmetic."""
    peak = float(log_likelihood.max())
    weighted = np.subtract(log_likelihood, peak, out=log_likelihood)
    np.exp(weighted, out=weighted)
    np.multiply(weighted, belief, out=weighted)
    total = float(weighted.sum())
    if not total > 0:
        raise ZeroEvidenceError("every state with probability rules the scan out")
    weighted /= total
    return weighted, peak + math.log(total)


def correct(belief: FloatArray, log_likelihood: FloatArray) -> tuple[FloatArray, float]:
    """Posterior and log evidence log p(z) = log sum(belief * exp(log_likelihood))."""
    return _correct_in(np.array(log_likelihood, dtype=np.float64), belief)


def most_likely_state(belief: FloatArray) -> tuple[int, int, int]:
    k, i, j = np.unravel_index(int(np.argmax(belief)), belief.shape)
    return int(k), int(i), int(j)


def pose_of(model: GridModel, state: tuple[int, int, int]) -> tuple[float, float, float]:
    """(x, y, yaw) of a state cell's centre."""
    k, i, j = state
    xs, ys = model.cell_centres()
    return float(xs[j]), float(ys[i]), float(_wrap_scalar(k * model.bin_width))


def covariance_around(belief: FloatArray, model: GridModel,
                      pose: tuple[float, float, float]) -> FloatArray:
    """The 3 x 3 second moment of (x, y, yaw) about ``pose`` under the belief (yaw
    differences wrapped to (-pi, pi]), plus the grid's own quantization variance."""
    xs, ys = model.cell_centres()
    px = belief.sum(axis=(0, 1))
    py = belief.sum(axis=(0, 2))
    pk = belief.sum(axis=(1, 2))
    dx, dy = xs - pose[0], ys - pose[1]
    dyaw = _wrap(model.headings() - pose[2])
    pxy = belief.sum(axis=0)
    cov = np.empty((3, 3))
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
    xs, ys = model.cell_centres()
    near_xy = ((xs[None, :] - pose[0]) ** 2 + (ys[:, None] - pose[1]) ** 2) <= radius ** 2
    near_k = np.abs(_wrap(model.headings() - pose[2])) <= angle
    return float(belief[near_k][:, near_xy].sum())


def belief_map(belief: FloatArray) -> np.ndarray:
    """The belief's maximum over headings scaled to 0..100 (int8), the largest 100: the
    picture an OccupancyGrid display draws."""
    top = belief.max(axis=0)
    peak = top.max()
    scaled = np.rint(100.0 * top / peak) if peak > 0 else np.zeros_like(top)
    return scaled.astype(np.int8)


def entropy_bits(belief: FloatArray) -> float:
    positive = belief[belief > 0]
    return float(-(positive * np.log2(positive)).sum()) + 0.0


# --- the steps' pieces ---------------------------------------------------------------------


def _wrap(angles: FloatArray) -> FloatArray:
    """Angles to (-pi, pi]."""
    return np.pi - np.mod(np.pi - np.asarray(angles, dtype=np.float64), TWO_PI)


def _wrap_scalar(angle: float) -> float:
    return math.pi - (math.pi - angle) % TWO_PI


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


def gaussian_taps(sigma: float) -> FloatArray:
    """A normalized Gaussian kernel of std ``sigma`` (in cells) over -3 sigma..3 sigma;
    [1] when sigma is too small to spread."""
    half = int(math.ceil(3.0 * sigma))
    if half == 0:
        return np.ones(1)
    offsets = np.arange(-half, half + 1)
    taps = np.exp(-0.5 * (offsets / sigma) ** 2)
    return taps / taps.sum()


def _blur(belief: FloatArray, sigma: float, axis: int) -> FloatArray:
    """Spread along ``axis`` (not cyclic: what spreads past the edge is lost)."""
    taps = gaussian_taps(sigma)
    if taps.size == 1:
        return belief
    half = taps.size // 2
    moved = np.moveaxis(belief, axis, -1)
    padded = np.pad(moved, [(0, 0)] * (moved.ndim - 1) + [(half, half)])
    out = np.zeros_like(moved)
    n = moved.shape[-1]
    for index, tap in enumerate(taps):
        out += tap * padded[..., index:index + n]
    return np.moveaxis(out, -1, axis)


def _blur_cyclic(belief: FloatArray, sigma: float, axis: int) -> FloatArray:
    """Spread along a cyclic ``axis`` (the headings)."""
    taps = gaussian_taps(sigma)
    if taps.size == 1:
        return belief
    half = taps.size // 2
    out = np.zeros_like(belief)
    for index, tap in enumerate(taps):
        out += tap * np.roll(belief, index - half, axis=axis)
    return out
