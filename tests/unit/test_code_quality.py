"""ruff over the whole tree and mypy over the layers without ROS (core, params)."""

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
BIN = Path(sys.executable).parent


def test_ruff_finds_nothing():
    result = subprocess.run([str(BIN / "ruff"), "check", "estimation_nodes", "tests", "bench"],
                            cwd=REPO, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr


def test_mypy_on_the_core_and_params_finds_nothing():
    result = subprocess.run(
        [sys.executable, "-m", "mypy", "estimation_nodes/core", "estimation_nodes/params"],
        cwd=REPO, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
