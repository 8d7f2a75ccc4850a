"""A shorter run of bench/core/numerical_health.py (the million-step run is in the README)."""

import importlib.util
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[2] / "bench" / "core" / "numerical_health.py"


def load():
    spec = importlib.util.spec_from_file_location("numerical_health", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_histogram_stays_normalized_over_a_long_run():
    result = load().histogram_health(20_000)
    assert result["ok"], result
    assert result["smallest max cell"] > 0.0


def test_kalman_covariance_stays_symmetric_positive_over_a_long_run():
    result = load().kalman_health(20_000)
    assert result["ok"], result
