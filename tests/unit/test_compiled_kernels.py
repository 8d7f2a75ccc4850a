"""The compiled histogram kernels (numba) against numpy's path, and the routing between them."""

import numpy as np
import pytest

from estimation_nodes.core import errors
from estimation_nodes.core.tiles import compiled, histogram
from estimation_nodes.core.tiles.models import MotionKernel


def random_kernel(rng, width):
    weights = rng.random(width)
    return MotionKernel(weights / weights.sum())


@pytest.mark.parametrize("size", [1, 2, 3, 5, 7, 31, 64, 1000, histogram.COMPILED_MIN_CELLS + 7])
@pytest.mark.parametrize("width", [1, 3, 5, 7, 31, 63])
def test_prediction_equals_numpy_path(size, width):
    # Worlds smaller than the kernel, equal to it and far larger; shifts at
    # every edge of the split between the two runs of the output.
    rng = np.random.default_rng(size * 100 + width)
    belief = rng.random(size)
    belief /= belief.sum()
    kernel = random_kernel(rng, width)
    for u in {0, 1, -1, width // 2, size - 1, size, size + 3, -size - 2, 10**15 + 3}:
        predicted = np.empty(size)
        compiled.predict_into(belief, u % size, kernel.weights, predicted)
        np.testing.assert_allclose(predicted, histogram.predict(belief, u, kernel, compiled=False),
                                   rtol=1e-13, atol=1e-300, err_msg=f"u={u}")


def test_correction_is_bit_for_bit_numpys(monkeypatch):
    rng = np.random.default_rng(5)
    belief, likelihood = rng.random(1000), rng.uniform(0.1, 0.9, 1000)
    belief /= belief.sum()
    with monkeypatch.context() as patch:
        patch.setattr(histogram, "COMPILED_MIN_CELLS", 1)
        fast, fast_evidence = histogram.correct(belief, likelihood)
    reference, evidence = histogram.correct(belief, likelihood)
    assert fast_evidence == evidence
    np.testing.assert_array_equal(fast, reference)


def test_large_worlds_route_to_the_compiled_kernels():
    assert histogram.compiled_kernels(histogram.COMPILED_MIN_CELLS) is compiled
    assert histogram.compiled_kernels(histogram.COMPILED_MIN_CELLS - 1) is None


def test_a_large_world_without_numba_takes_numpys_path(monkeypatch):
    size = histogram.COMPILED_MIN_CELLS
    rng = np.random.default_rng(9)
    belief, likelihood = rng.random(size), rng.uniform(0.1, 0.9, size)
    belief /= belief.sum()
    kernel = MotionKernel(np.array([0.1, 0.8, 0.1]))
    expected = histogram.correct(histogram.predict(belief, 3, kernel), likelihood)[0]
    monkeypatch.setattr(histogram, "_compiled_module", lambda: None)
    assert histogram.compiled_kernels(size) is None
    fallback = histogram.correct(histogram.predict(belief, 3, kernel), likelihood)[0]
    np.testing.assert_allclose(fallback, expected, rtol=1e-13)


def test_in_place_correction_of_a_large_world_writes_only_on_success():
    size = histogram.COMPILED_MIN_CELLS
    belief = histogram.uniform(size)
    with pytest.raises(errors.ZeroEvidenceError):
        histogram.correct(belief, np.zeros(size), out=belief)
    np.testing.assert_array_equal(belief, histogram.uniform(size))
    posterior, _ = histogram.correct(belief, np.linspace(0.1, 0.9, size), out=belief)
    assert posterior is belief
    np.testing.assert_allclose(belief.sum(), 1.0, rtol=1e-12)
