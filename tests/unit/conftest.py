"""Unit-test fixtures: the histogram tests run over both of the core's code paths."""

import sys

import pytest
from hypothesis import HealthCheck, settings

from estimation_nodes.core.tiles import histogram

# The path fixture below is function-scoped on purpose: it holds for every
# example hypothesis draws within the test, so its health check does not apply.
settings.register_profile("unit", suppress_health_check=[HealthCheck.function_scoped_fixture])
settings.load_profile("unit")


@pytest.fixture(params=["numpy", "compiled"])
def histogram_path(request, monkeypatch):
    """Run the test with numpy's passes, then with the compiled kernels at every size."""
    if request.param == "compiled":
        assert histogram._compiled_module() is not None, "numba is a dependency; it must import"
        monkeypatch.setattr(histogram, "COMPILED_MIN_CELLS", 1)
    else:
        monkeypatch.setattr(histogram, "COMPILED_MIN_CELLS", sys.maxsize)
    return request.param
