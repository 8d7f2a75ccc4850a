"""Every worked example of the chapter (shared reference README) to 1e-6."""

import numpy as np
import pytest

from estimation_nodes.core.kalman import linear as kalman
from estimation_nodes.core.kalman.models import LinearGaussianModel
from estimation_nodes.core.tiles import histogram
from estimation_nodes.core.tiles.models import HistogramModel

TOL = 1e-6


@pytest.fixture
def book(histogram_path) -> HistogramModel:
    """The book's world; the histogram examples run on both code paths of the core."""
    return HistogramModel.book()


def observe(model, belief, observations):
    evidences = []
    for observed in observations:
        belief, evidence = histogram.correct(belief, model.likelihood(observed))
        evidences.append(evidence)
    return belief, evidences


def test_book_likelihood_vectors(book):
    np.testing.assert_allclose(book.likelihood("dark"), [0.2, 0.2, 0.6, 0.6, 0.2], atol=1e-12)
    np.testing.assert_allclose(book.likelihood("bright"), [0.8, 0.8, 0.4, 0.4, 0.8], atol=1e-12)


@pytest.mark.parametrize(
    "observations, evidence, posterior",
    [
        pytest.param(["dark"], 0.36, [0.111111, 0.111111, 0.333333, 0.333333, 0.111111],
                     id="example_6_9"),
        pytest.param(["dark", "dark"], 0.466667,
                     [0.047619, 0.047619, 0.428571, 0.428571, 0.047619], id="example_6_10_2"),
        pytest.param(["dark", "bright"], 0.533333,
                     [0.166667, 0.166667, 0.25, 0.25, 0.166667], id="example_6_10_3"),
        pytest.param(["dark", "bright", "dark"], 0.4,
                     [0.083333, 0.083333, 0.375, 0.375, 0.083333], id="example_6_10_4"),
    ],
)
def test_correction_examples(book, observations, evidence, posterior):
    belief, evidences = observe(book, histogram.uniform(5), observations)
    np.testing.assert_allclose(evidences[-1], evidence, atol=TOL)
    np.testing.assert_allclose(belief, posterior, atol=TOL)


@pytest.mark.parametrize(
    "moves, expected",
    [
        pytest.param([2], [0, 0.1, 0.8, 0.1, 0], id="example_6_11"),
        pytest.param([2, 1], [0.01, 0.01, 0.16, 0.66, 0.16], id="example_6_12"),
        pytest.param([1] * 10, [0.294878, 0.224306, 0.128255, 0.128255, 0.224306],
                     id="example_6_13_ten_moves"),
        pytest.param([1] * 1000, [0.2] * 5, id="example_6_13_thousand_moves"),
    ],
)
def test_prediction_examples(book, moves, expected):
    belief = histogram.one_hot(5, 0)
    for u in moves:
        belief = histogram.predict(belief, u, book.kernel)
    np.testing.assert_allclose(belief, expected, atol=TOL)


EXAMPLE_6_14 = [
    # (observation, predicted, corrected)
    ("bright", [0.2] * 5, [0.25, 0.25, 0.125, 0.125, 0.25]),
    ("dark", [0.2375, 0.25, 0.2375, 0.1375, 0.1375],
     [0.135714, 0.142857, 0.407143, 0.235714, 0.078571]),
    ("dark", [0.1, 0.130714, 0.168571, 0.363571, 0.237143],
     [0.048443, 0.063322, 0.244983, 0.528374, 0.114879]),
]


@pytest.mark.parametrize("step", [1, 2, 3], ids=lambda s: f"example_6_14_step_{s}")
def test_localization_example_6_14(book, step):
    belief = histogram.uniform(5)
    for observed, _, _ in EXAMPLE_6_14[:step]:
        predicted = histogram.predict(belief, 1, book.kernel)
        belief, _ = histogram.correct(predicted, book.likelihood(observed))
    _, predicted_expected, corrected_expected = EXAMPLE_6_14[step - 1]
    np.testing.assert_allclose(predicted, predicted_expected, atol=TOL)
    np.testing.assert_allclose(belief, corrected_expected, atol=TOL)


def test_example_6_14_most_likely_cell_is_cell_4(book):
    belief = histogram.uniform(5)
    for observed, _, _ in EXAMPLE_6_14:
        belief, _ = histogram.correct(histogram.predict(belief, 1, book.kernel),
                                      book.likelihood(observed))
    assert histogram.most_likely_cell(belief) == 3


def test_fusion_example_6_16():
    fused = kalman.fuse(2.0, 4.0, 4.0, 1.0)
    np.testing.assert_allclose([fused.x, fused.var, np.sqrt(fused.var)],
                               [3.6, 0.8, 0.894427], atol=TOL)


def test_fusion_formula_example_6_15():
    x1, s1, x2, s2 = 1.5, 0.7, -2.0, 3.1
    fused = kalman.fuse(x1, s1, x2, s2)
    np.testing.assert_allclose(fused.x, (s2 * x1 + s1 * x2) / (s1 + s2), rtol=1e-12)
    np.testing.assert_allclose(fused.var, 1.0 / (1.0 / s1 + 1.0 / s2), rtol=1e-12)


def test_fusion_is_a_scalar_correction():
    fused = kalman.fuse(2.0, 4.0, 4.0, 1.0)
    x, var, _ = kalman.correct_scalar(2.0, 4.0, 4.0, 1.0)
    np.testing.assert_allclose([x, var], [fused.x, fused.var], rtol=1e-12)


EXAMPLE_6_18 = dict(
    x0=3.0, var0=100.0, u=[2, 3, 2, 1, 1], z=[2, 5, 7, 8, 9], var_u=2.0, var_z=4.0,
    predicted_x=[5.000000, 5.113208, 7.045977, 8.021958, 9.010857],
    predicted_var=[102, 5.849057, 4.375479, 4.089661, 4.022167],
    corrected_x=[2.113208, 5.045977, 7.021958, 8.010857, 9.005414],
    corrected_var=[3.849057, 2.375479, 2.089661, 2.022167, 2.005526],
    gain=[0.962264, 0.593870, 0.522415, 0.505542, 0.501382],
)


def run_scalar_6_18():
    e = EXAMPLE_6_18
    x, var = e["x0"], e["var0"]
    rows = []
    for u, z in zip(e["u"], e["z"]):
        x, var = kalman.predict_scalar(x, var, u, e["var_u"])
        x_corrected, var_corrected, gain = kalman.correct_scalar(x, var, z, e["var_z"])
        rows.append((x, var, x_corrected, var_corrected, gain))
        x, var = x_corrected, var_corrected
    return np.array(rows)


def run_matrix_6_18():
    e = EXAMPLE_6_18
    model = LinearGaussianModel.scalar(e["var_u"], e["var_z"])
    x, P = np.array([e["x0"]]), np.array([[e["var0"]]])
    rows = []
    for u, z in zip(e["u"], e["z"]):
        x, P = kalman.predict(x, P, [u], model)
        predicted = (x[0], P[0, 0])
        x, P, K = kalman.correct(x, P, [z], model)
        rows.append((*predicted, x[0], P[0, 0], K[0, 0]))
    return np.array(rows)


@pytest.mark.parametrize("runner", [run_scalar_6_18, run_matrix_6_18], ids=["scalar", "matrix"])
@pytest.mark.parametrize("step", range(5), ids=lambda s: f"example_6_18_step_{s + 1}")
def test_kalman_example_6_18(runner, step):
    e = EXAMPLE_6_18
    got = runner()[step]
    expected = [e["predicted_x"][step], e["predicted_var"][step], e["corrected_x"][step],
                e["corrected_var"][step], e["gain"][step]]
    np.testing.assert_allclose(got, expected, atol=TOL)
