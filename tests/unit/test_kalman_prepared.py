"""KalmanFilter.prepare: the covariance work done ahead gives the same filter, bit for bit."""

import numpy as np
import pytest

from estimation_nodes.core import errors
from estimation_nodes.core.kalman import linear as kalman
from estimation_nodes.core.kalman.filter import KalmanFilter
from estimation_nodes.core.kalman.models import GaussianState, LinearGaussianModel


def random_model(rng, n, m, p, q):
    return LinearGaussianModel(
        A=np.eye(n) + 0.1 * rng.normal(size=(n, n)), B=rng.normal(size=(n, m)),
        C=rng.normal(size=(p, n)), F=rng.normal(size=(n, q)),
        Q=np.diag(rng.uniform(0.1, 1.0, q)), R=np.diag(rng.uniform(0.1, 1.0, p)))


def run(kalman_filter, rng_events, steps, prepare):
    """Random predictions and corrections; the estimate after each step."""
    history = []
    for _ in range(steps):
        if prepare:
            kalman_filter.prepare()
        if rng_events.random() < 0.5:
            kalman_filter.predict(rng_events.normal(size=kalman_filter.input_size))
        else:
            kalman_filter.correct(rng_events.normal(size=kalman_filter.measurement_size))
        history.append((kalman_filter.x.tobytes(), kalman_filter.P.tobytes(),
                        kalman_filter.last_nis))
    return history


@pytest.mark.parametrize("sizes", [(1, 1, 1, 1), (4, 2, 2, 2), (3, 1, 2, 3), (5, 2, 3, 1)])
def test_prepared_steps_equal_steps_computed_at_once(sizes):
    rng = np.random.default_rng(sum(sizes))
    model = random_model(rng, *sizes)
    initial = GaussianState(rng.normal(size=sizes[0]), np.eye(sizes[0]) * 5.0)
    with_preparation = run(KalmanFilter(initial, model), np.random.default_rng(1), 60, True)
    without = run(KalmanFilter(initial, model), np.random.default_rng(1), 60, False)
    assert with_preparation == without


def test_the_matrix_steps_are_the_book_equations_in_two_parts():
    rng = np.random.default_rng(3)
    model = random_model(rng, 4, 2, 2, 2)
    x, P, z = rng.normal(size=4), np.eye(4) * 2.0, rng.normal(size=2)
    gain = kalman.correction_gain(P, model)
    S = model.C @ P @ model.C.T + model.R
    K = P @ model.C.T @ np.linalg.inv(S)
    M = np.eye(4) - K @ model.C
    np.testing.assert_allclose(gain.K, K, rtol=1e-12)
    np.testing.assert_allclose(gain.P, M @ P @ M.T + K @ model.R @ K.T, rtol=1e-12)
    x_new, nis = kalman.corrected_mean(x, z, gain, model)
    y = z - model.C @ x
    np.testing.assert_allclose(x_new, x + K @ y, rtol=1e-12)
    assert nis == pytest.approx(y @ np.linalg.solve(S, y), rel=1e-12)
    np.testing.assert_allclose(kalman.predicted_covariance(P, model),
                               model.A @ P @ model.A.T + model.F @ model.Q @ model.F.T,
                               rtol=1e-12)


def test_a_preparation_is_not_used_for_another_state_or_model():
    rng = np.random.default_rng(5)
    model, other_model = random_model(rng, 3, 1, 1, 1), random_model(rng, 3, 1, 1, 1)
    initial = GaussianState(np.zeros(3), np.eye(3))
    prepared, reference = KalmanFilter(initial, model), KalmanFilter(initial, model)
    saved = prepared.snapshot()
    prepared.correct([1.0])
    prepared.prepare()               # for the corrected P ...
    prepared.restore(saved)          # ... which is no longer the filter's
    reference.correct([2.0])
    prepared.correct([2.0])
    assert prepared.P.tobytes() == reference.P.tobytes()
    prepared.prepare()
    prepared.reconfigure(initial, other_model)   # same sizes: the state is kept
    reference.reconfigure(initial, other_model)
    prepared.predict([0.5])
    reference.predict([0.5])
    assert prepared.P.tobytes() == reference.P.tobytes()


def test_a_preparation_that_cannot_be_finite_leaves_the_error_to_the_step():
    model = LinearGaussianModel(A=np.array([[1e200]]), B=np.array([[1.0]]),
                                C=np.array([[1.0]]), F=np.array([[1.0]]),
                                Q=np.array([[1.0]]), R=np.array([[1.0]]))
    kalman_filter = KalmanFilter(GaussianState(np.array([0.0]), np.array([[1e200]])), model)
    kalman_filter.prepare()   # A P A' overflows: nothing raised here
    before = kalman_filter.snapshot()
    with pytest.raises(errors.NonFiniteResultError):
        kalman_filter.predict([0.0])
    assert kalman_filter.snapshot() == before
    kalman_filter.correct([1.0])   # the correction does not overflow and still works
    assert np.isfinite(kalman_filter.P).all()


def count_calls(monkeypatch):
    """The names of the covariance steps, as the filter calls them."""
    calls = []
    for name in ("predicted_covariance", "correction_gain"):
        original = getattr(kalman, name)
        monkeypatch.setattr(kalman, name, lambda *args, _f=original, _n=name:
                            calls.append(_n) or _f(*args))
    return calls


def test_without_prepare_each_step_computes_only_its_own_covariance(monkeypatch):
    calls = count_calls(monkeypatch)
    model = random_model(np.random.default_rng(8), 4, 2, 2, 2)
    kalman_filter = KalmanFilter(GaussianState(np.zeros(4), np.eye(4)), model)
    kalman_filter.predict([0.1, 0.2])
    kalman_filter.correct([1.0, 2.0])
    assert calls == ["predicted_covariance", "correction_gain"]
    kalman_filter.prepare()   # alternating so far: a prediction comes next
    assert calls[2:] == ["predicted_covariance"]
    kalman_filter.correct([1.5, 2.5])   # it did not: the correction computes its own gain
    assert calls[2:] == ["predicted_covariance", "correction_gain"]


@pytest.mark.parametrize("pattern, foreseen", [("pc", True), ("cc", True), ("pp", True),
                                               ("ppc", False), ("pcc", False)])
def test_prepare_follows_a_repeating_pattern_of_two_after_two_steps(monkeypatch, pattern,
                                                                    foreseen):
    """Alternating inputs and measurements (a tracker), or runs of one kind: after the
    first two steps, each step finds its covariance prepared and computes none itself."""
    calls = count_calls(monkeypatch)
    model = random_model(np.random.default_rng(9), 4, 2, 2, 2)
    kalman_filter = KalmanFilter(GaussianState(np.zeros(4), np.eye(4)), model)
    steps = (pattern * 12)[:24]
    computed_by_steps = []
    for kind in steps:
        kalman_filter.prepare()
        before = len(calls)
        if kind == "p":
            kalman_filter.predict([0.1, 0.2])
        else:
            kalman_filter.correct([1.0, 2.0])
        computed_by_steps.append(len(calls) - before)
    if foreseen:   # a pattern of period one or two
        assert computed_by_steps[2:] == [0] * 22
    else:   # period three: the guess is wrong now and then, never the result
        assert 0 < sum(computed_by_steps[2:]) < 22
