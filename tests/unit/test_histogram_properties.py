"""Invariants of the histogram filter, against an explicit-loop oracle."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from estimation_nodes.core import errors
from estimation_nodes.core.tiles import histogram
from estimation_nodes.core.tiles.models import HistogramModel, MotionKernel

# Every histogram test here runs on numpy's path and on the compiled one.
pytestmark = pytest.mark.usefixtures("histogram_path")


def loop_predict(belief, u, weights):
    """The prediction written as the book's sum, one cell and one tap at a time."""
    n = len(belief)
    half = len(weights) // 2
    out = [0.0] * n
    for source in range(n):
        for tap, weight in enumerate(weights):
            out[(source + u + tap - half) % n] += weight * belief[source]
    return np.array(out)


def loop_correct(belief, likelihood):
    products = [b * p for b, p in zip(belief, likelihood)]
    evidence = sum(products)
    return np.array([p / evidence for p in products]), evidence


def distributions(min_size=1, max_size=60):
    raw = arrays(np.float64, st.integers(min_size, max_size),
                 elements=st.floats(0.0, 1.0, allow_subnormal=False))
    return raw.filter(lambda a: a.sum() > 1e-3).map(lambda a: a / a.sum())


def kernels(max_half_width=4):
    raw = st.integers(0, max_half_width).flatmap(
        lambda h: arrays(np.float64, 2 * h + 1, elements=st.floats(0.0, 1.0)))
    return raw.filter(lambda a: a.sum() > 1e-3).map(lambda a: MotionKernel(a / a.sum()))


moves = st.integers(-10**12, 10**12)


@settings(max_examples=200, deadline=None)
@given(belief=distributions(), u=moves, kernel=kernels())
def test_predict_matches_explicit_loop(belief, u, kernel):
    np.testing.assert_allclose(histogram.predict(belief, u, kernel),
                               loop_predict(belief, u, kernel.weights), atol=1e-12)


@settings(max_examples=200, deadline=None)
@given(belief=distributions(), u=moves, kernel=kernels())
def test_predict_keeps_a_distribution(belief, u, kernel):
    predicted = histogram.predict(belief, u, kernel)
    assert np.all(predicted >= 0.0)
    np.testing.assert_allclose(predicted.sum(), 1.0, atol=1e-12)


@settings(max_examples=200, deadline=None)
@given(belief=distributions(), u=moves, half=st.integers(0, 3), data=st.data())
def test_one_hot_kernel_is_a_rotation(belief, u, half, data):
    hot = data.draw(st.integers(0, 2 * half))
    weights = np.zeros(2 * half + 1)
    weights[hot] = 1.0
    predicted = histogram.predict(belief, u, MotionKernel(weights))
    np.testing.assert_array_equal(predicted, np.roll(belief, (u + hot - half) % len(belief)))


@settings(max_examples=200, deadline=None)
@given(belief=distributions(), data=st.data())
def test_correct_matches_explicit_loop_and_keeps_a_distribution(belief, data):
    likelihood = data.draw(arrays(np.float64, belief.size, elements=st.floats(0.01, 1.0)))
    posterior, evidence = histogram.correct(belief, likelihood)
    expected, expected_evidence = loop_correct(belief, likelihood)
    np.testing.assert_allclose(posterior, expected, atol=1e-12)
    np.testing.assert_allclose(evidence, expected_evidence, rtol=1e-12)
    assert np.all(posterior >= 0.0)
    np.testing.assert_allclose(posterior.sum(), 1.0, atol=1e-12)


def test_steps_do_not_modify_their_inputs():
    model = HistogramModel.book()
    belief = np.array([0.1, 0.2, 0.3, 0.25, 0.15])
    before = belief.copy()
    histogram.predict(belief, 3, model.kernel)
    histogram.correct(belief, model.likelihood("dark"))
    np.testing.assert_array_equal(belief, before)


def test_zero_evidence_is_an_error_not_nan():
    belief = histogram.one_hot(5, 0)
    likelihood = np.array([0.0, 1.0, 1.0, 1.0, 1.0])
    with pytest.raises(errors.ZeroEvidenceError, match="evidence 0.0"):
        histogram.correct(belief, likelihood)


def test_single_cell_world_with_wide_kernel():
    kernel = MotionKernel(np.array([0.1, 0.2, 0.4, 0.2, 0.1]))
    np.testing.assert_allclose(histogram.predict(np.array([1.0]), 7, kernel), [1.0])


def test_random_worlds_against_loop_oracle_seeded():
    rng = np.random.default_rng(20261121)
    for _ in range(50):
        n = int(rng.integers(1, 200))
        belief = rng.random(n)
        belief /= belief.sum()
        weights = rng.random(2 * int(rng.integers(0, 6)) + 1)
        u = int(rng.integers(-1000, 1000))
        kernel = MotionKernel(weights / weights.sum())
        np.testing.assert_allclose(histogram.predict(belief, u, kernel),
                                   loop_predict(belief, u, kernel.weights), atol=1e-12)


def test_entropy_bounds():
    assert histogram.entropy(histogram.one_hot(8, 3)) == 0.0
    np.testing.assert_allclose(histogram.entropy(histogram.uniform(8)), 3.0, rtol=1e-12)


def test_correct_into_out_matches_and_is_untouched_on_zero_evidence():
    rng = np.random.default_rng(5)
    belief = rng.random(50)
    belief /= belief.sum()
    likelihood = rng.uniform(0.1, 1.0, 50)
    expected, expected_evidence = histogram.correct(belief, likelihood)
    owned = belief.copy()
    posterior, evidence = histogram.correct(owned, likelihood, out=owned)
    assert posterior is owned
    np.testing.assert_array_equal(posterior, expected)
    assert evidence == expected_evidence
    hot = histogram.one_hot(50, 3)
    with pytest.raises(errors.ZeroEvidenceError):
        histogram.correct(hot, np.where(np.arange(50) == 3, 0.0, 1.0), out=hot)
    np.testing.assert_array_equal(hot, histogram.one_hot(50, 3))
