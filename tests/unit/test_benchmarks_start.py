"""Every benchmark script starts: its imports follow the package's layout (a benchmark is
run by hand, so a broken import would go unseen until then)."""

import subprocess
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[2] / "bench"
#: Modules the scripts import, not scripts.
HELPERS = ("timing.py", "ros_env.py", "relay_node.py", "amcl_baseline.py", "run_recorder.py")
SCRIPTS = sorted(p for p in BENCH.glob("*.py") if p.name not in HELPERS)


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.name)
def test_the_benchmark_starts(script):
    result = subprocess.run([sys.executable, str(script), "--help"], capture_output=True,
                            text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert "usage" in result.stdout
