"""Core filter steps against filterpy 2.0 and a floor of plain numpy passes.

    python bench/core/core_bench.py [--quick]

Histogram: one step as the estimator runs it (predict with u = 1, then
correct in place) against filterpy.discrete_bayes.predict + update on the
same inputs, and against a floor of three streaming numpy passes over N
doubles into preallocated arrays. Kalman: the scalar path (Algorithm 4)
against filterpy's KalmanFilter with dim_x = 1, and the matrix path against
KalmanFilter on a 4-state constant-velocity model; one predict + one correct
each.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from filterpy import discrete_bayes
from filterpy.kalman import KalmanFilter

sys.path.insert(1, str(Path(__file__).resolve().parents[2]))  # the repository: bench
from bench.common import compare, format_seconds, table  # noqa: E402

from estimation_nodes.core.kalman import linear as kalman  # noqa: E402
from estimation_nodes.core.tiles import histogram  # noqa: E402
from estimation_nodes.core.kalman.filter import KalmanFilter as RunningKalman  # noqa: E402
from estimation_nodes.core.kalman.models import GaussianState, LinearGaussianModel  # noqa: E402
from estimation_nodes.core.tiles.models import MotionKernel  # noqa: E402
from estimation_nodes.nodes.process_memory import keep_freed_memory  # noqa: E402


def book_like_kernel(width: int) -> MotionKernel:
    """The book's 0.1/0.8/0.1 for width 3; a normalized triangle for wider kernels."""
    if width == 3:
        return MotionKernel(np.array([0.1, 0.8, 0.1]))
    half = width // 2
    weights = (half + 1.0) - np.abs(np.arange(-half, half + 1))
    return MotionKernel(weights / weights.sum())


def histogram_row(n: int, width: int, repeats: int, compiled: bool = True) -> list[str]:
    """One row; ``compiled=False`` keeps large worlds on numpy's path (see histogram.py)."""
    rng = np.random.default_rng(n + width)
    prior = rng.random(n)
    prior /= prior.sum()
    likelihood = rng.uniform(0.2, 0.8, n)
    kernel = book_like_kernel(width)
    weights = kernel.weights.copy()
    a, b, c = np.empty(n), np.empty(n), np.empty(n)

    def ours() -> None:
        predicted = histogram.predict(prior, 1, kernel, compiled=compiled)
        histogram.correct(predicted, likelihood, out=predicted, compiled=compiled)

    def filterpy_step() -> None:
        discrete_bayes.update(likelihood, discrete_bayes.predict(prior, 1, weights))

    def floor() -> None:
        np.multiply(prior, likelihood, out=a)
        np.multiply(a, 0.5, out=b)
        np.add(a, b, out=c)

    # The same answer first: a benchmark of a wrong result would mean nothing.
    predicted = histogram.predict(prior, 1, kernel, compiled=compiled)
    posterior, _ = histogram.correct(predicted, likelihood, compiled=compiled)
    reference = discrete_bayes.update(likelihood, discrete_bayes.predict(prior, 1, weights))
    np.testing.assert_allclose(posterior, reference, rtol=1e-9, atol=1e-15)

    t = compare({"ours": ours, "filterpy": filterpy_step, "floor": floor}, repeats=repeats)
    path = "compiled" if histogram.compiled_kernels(n, compiled) else "numpy"
    return [f"{n:,}", str(width), path, format_seconds(t["ours"].median), t["ours"].spread(),
            format_seconds(t["filterpy"].median),
            f"{t['filterpy'].median / t['ours'].median:.1f}x",
            format_seconds(t["floor"].median),
            f"{t['ours'].median / t['floor'].median:.2f}"]


def kalman_rows(repeats: int) -> list[list[str]]:
    rows = []
    # 1-D: Example 6.18's model.
    kf1 = KalmanFilter(dim_x=1, dim_z=1, dim_u=1)
    kf1.x, kf1.P = np.array([[3.0]]), np.array([[100.0]])
    kf1.F, kf1.B, kf1.H = np.eye(1), np.eye(1), np.eye(1)
    kf1.Q, kf1.R = np.array([[2.0]]), np.array([[4.0]])
    state = [3.0, 100.0]

    def scalar() -> None:
        x, var = kalman.predict_scalar(state[0], state[1], 1.0, 2.0)
        state[0], state[1], _ = kalman.correct_scalar(x, var, 4.0, 4.0)

    def filterpy_1d() -> None:
        kf1.predict(u=np.array([[1.0]]))
        kf1.update(np.array([[4.0]]))

    t = compare({"ours": scalar, "filterpy": filterpy_1d}, repeats=repeats)
    rows.append(["scalar, 1 state (Algorithm 4)", format_seconds(t["ours"].median),
                 t["ours"].spread(), format_seconds(t["filterpy"].median),
                 f"{t['filterpy'].median / t['ours'].median:.1f}x"])

    dt = 0.1
    A = np.array([[1, 0, dt, 0], [0, 1, 0, dt], [0, 0, 1, 0], [0, 0, 0, 1.0]])
    B = np.array([[0, 0], [0, 0], [dt, 0], [0, dt]])
    C = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0]])
    Q, R = np.diag([1e-3, 1e-3, 1e-2, 1e-2]), np.eye(2) * 0.5
    model = LinearGaussianModel(A, B, C, np.eye(4), Q, R)
    kf4 = KalmanFilter(dim_x=4, dim_z=2, dim_u=2)
    kf4.F, kf4.B, kf4.H, kf4.Q, kf4.R = A, B, C, Q, R
    kf4.x, kf4.P = np.zeros((4, 1)), np.eye(4) * 10.0
    matrix_state = [np.zeros(4), np.eye(4) * 10.0]
    u, z = np.array([0.1, -0.2]), np.array([1.0, 2.0])
    u_col, z_col = u.reshape(2, 1), z.reshape(2, 1)

    def matrix() -> None:
        x, P = kalman.predict(matrix_state[0], matrix_state[1], u, model)
        matrix_state[0], matrix_state[1], _ = kalman.correct(x, P, z, model)

    def filterpy_4d() -> None:
        kf4.predict(u=u_col)
        kf4.update(z_col)

    t = compare({"ours": matrix, "filterpy": filterpy_4d}, repeats=repeats)
    rows.append(["matrix, 4 states, 2 inputs, 2 outputs (constant velocity)",
                 format_seconds(t["ours"].median),
                 t["ours"].spread(), format_seconds(t["filterpy"].median),
                 f"{t['filterpy'].median / t['ours'].median:.1f}x"])

    # What the estimator node runs per input: the step plus its NIS and finiteness checks.
    running = RunningKalman(GaussianState(np.zeros(4), np.eye(4) * 10.0), model)

    def estimator_path() -> None:
        running.predict(u)
        running.correct(z)

    t = compare({"ours": estimator_path, "filterpy": filterpy_4d}, repeats=repeats)
    rows.append(["the same in the estimator (filter_state: + NIS, finiteness checks)",
                 format_seconds(t["ours"].median), t["ours"].spread(),
                 format_seconds(t["filterpy"].median),
                 f"{t['filterpy'].median / t['ours'].median:.1f}x"])
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats, for a smoke run")
    args = parser.parse_args()
    repeats = 5 if args.quick else 21
    # As in the estimator process; filterpy runs in this same process, with the same allocator.
    print(f"allocator thresholds raised as in the estimator: {keep_freed_memory()}")
    rows = [histogram_row(n, 3, repeats) for n in (5, 1_000, 100_000, 1_000_000)]
    rows += [histogram_row(n, 3, repeats, compiled=False) for n in (100_000, 1_000_000)]
    rows += [histogram_row(n, width, repeats) for width in (7, 31) for n in (1_000, 1_000_000)]
    print("Histogram step (predict u=1 + correct); ratios of medians, same run, same inputs")
    print(table(["N", "kernel", "path", "ours", "ours p10..p90", "filterpy", "filterpy / ours",
                 "floor (3 passes)", "ours / floor"], rows))
    print()
    print("Kalman step (one predict + one correct)")
    print(table(["filter", "ours", "ours p10..p90", "filterpy", "filterpy / ours"],
                kalman_rows(repeats)))


if __name__ == "__main__":
    main()
