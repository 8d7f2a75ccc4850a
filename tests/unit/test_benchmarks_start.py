"""Every benchmark script starts: its imports follow the package's layout (a benchmark is
run by hand, so a broken import would go unseen until then)."""

import subprocess
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[2] / "bench"
#: A module the scripts import, not a script.
HELPERS = ("amcl_baseline.py",)
#: The scripts, a folder per subject (bench/README.md).
SCRIPTS = sorted(p for p in BENCH.glob("*/*.py") if p.name not in HELPERS)


def test_the_scripts_are_in_their_subjects_folders():
    """bench/ itself holds the shared helpers only: common.py and the relay node."""
    assert sorted(p.name for p in BENCH.glob("*.py")) == ["common.py", "relay_node.py"]


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_the_benchmark_starts(script):
    result = subprocess.run([sys.executable, str(script), "--help"], capture_output=True,
                            text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert "usage" in result.stdout
