"""Long seeded runs of the core filters, checking their numerical health at every step.

    python bench/core/numerical_health.py --steps 1000000

Histogram: the book's world, sensor and kernel, random moves in [-3, 3] and
observations drawn from the sensor model at a simulated true position; the
belief must stay finite, non-negative, sum to 1 within 1e-12 and never
underflow to all zeros. Kalman: a constant-velocity model (position and
velocity, position measured), P must stay exactly symmetric and positive
definite (a Cholesky factorization succeeds) with a finite state.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from estimation_nodes.core.kalman import linear as kalman
from estimation_nodes.core.kalman.models import LinearGaussianModel
from estimation_nodes.core.sim import draws as simulation
from estimation_nodes.core.tiles import histogram
from estimation_nodes.core.tiles.models import HistogramModel


def histogram_health(steps: int, seed: int = 1) -> dict:
    model = HistogramModel.book()
    rng = np.random.default_rng(seed)
    moves = rng.integers(-3, 4, steps)
    belief, position = histogram.uniform(model.size), 0
    worst_sum_error, smallest_max = 0.0, 1.0
    for u in moves.tolist():
        position += u + simulation.sample_offset(model.kernel, rng)
        observed = simulation.sample_observation(
            model.sensor.probabilities, model.cell_class_index(position), rng)
        belief = histogram.predict(belief, u, model.kernel)
        belief, _ = histogram.correct(belief, model.likelihood(model.sensor.classes[observed]))
        worst_sum_error = max(worst_sum_error, abs(float(belief.sum()) - 1.0))
        smallest_max = min(smallest_max, float(belief.max()))
        if not (np.all(np.isfinite(belief)) and np.all(belief >= 0.0)):
            raise AssertionError(f"belief became invalid: {belief}")
    return {"steps": steps, "worst |sum - 1|": worst_sum_error,
            "smallest max cell": smallest_max, "ok": worst_sum_error <= 1e-12}


def kalman_health(steps: int, seed: int = 2) -> dict:
    dt = 0.1
    model = LinearGaussianModel(
        A=np.array([[1.0, dt], [0.0, 1.0]]), B=np.array([[0.0], [dt]]),
        C=np.array([[1.0, 0.0]]), F=np.eye(2), Q=np.diag([1e-4, 1e-2]), R=np.array([[0.5]]))
    rng = np.random.default_rng(seed)
    x, P = np.zeros(2), np.eye(2) * 100.0
    truth = np.zeros(2)
    smallest_eigen, asymmetric = np.inf, 0
    for step in range(steps):
        u = float(np.sin(step * 0.01))
        truth = model.A @ truth + model.B[:, 0] * u + rng.normal(0, [1e-2, 1e-1])
        z = truth[0] + rng.normal(0, np.sqrt(0.5))
        x, P = kalman.predict(x, P, [u], model)
        x, P, _ = kalman.correct(x, P, [z], model)
        asymmetric += int(not np.array_equal(P, P.T))
        np.linalg.cholesky(P)   # raises if P is not positive definite
        if step % 1000 == 0:
            smallest_eigen = min(smallest_eigen, float(np.linalg.eigvalsh(P).min()))
        if not np.all(np.isfinite(x)):
            raise AssertionError(f"state became non-finite at step {step}")
    return {"steps": steps, "asymmetric steps": asymmetric,
            "smallest eigenvalue (every 1000th step)": smallest_eigen,
            "ok": asymmetric == 0 and smallest_eigen > 0.0}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=1_000_000)
    args = parser.parse_args()
    for name, check in (("histogram", histogram_health), ("kalman", kalman_health)):
        start = time.perf_counter()
        result = check(args.steps)
        print(f"{name}: {result} in {time.perf_counter() - start:.1f} s", flush=True)


if __name__ == "__main__":
    main()
