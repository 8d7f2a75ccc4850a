"""Interleaved timing: each figure with a reference measured in the same run.

Every repeat times the candidate and its reference back to back, so a noisy
machine slows both alike; the ratio of the medians is what the tables quote,
with the spread (10th to 90th percentile of the per-call time) beside it.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Timing:
    """Per-call seconds over the repeats."""

    samples: np.ndarray

    @property
    def median(self) -> float:
        return float(np.median(self.samples))

    def spread(self) -> str:
        low, high = np.percentile(self.samples, [10, 90])
        return f"{format_seconds(low)}..{format_seconds(high)}"


def format_seconds(seconds: float) -> str:
    if seconds < 1e-3:
        return f"{seconds * 1e6:.2f} us"
    if seconds < 1.0:
        return f"{seconds * 1e3:.3f} ms"
    return f"{seconds:.3f} s"


def _calls_for(function: Callable[[], object], budget: float) -> int:
    """How many calls fill about ``budget`` seconds (at least one)."""
    start = time.perf_counter()
    function()
    once = max(time.perf_counter() - start, 1e-7)
    return max(1, int(budget / once))


def _per_call(function: Callable[[], object], calls: int) -> float:
    start = time.perf_counter()
    for _ in range(calls):
        function()
    return (time.perf_counter() - start) / calls


def compare(
    functions: dict[str, Callable[[], object]], repeats: int = 15, budget: float = 0.02
) -> dict[str, Timing]:
    """Time each function ``repeats`` times, interleaved, each repeat about ``budget`` s."""
    calls = {name: _calls_for(f, budget) for name, f in functions.items()}
    samples: dict[str, list[float]] = {name: [] for name in functions}
    for _ in range(repeats):
        for name, function in functions.items():
            samples[name].append(_per_call(function, calls[name]))
    return {name: Timing(np.array(values)) for name, values in samples.items()}


def table(header: list[str], rows: list[list[str]]) -> str:
    """A Markdown table, so the README can carry the output as it is."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)
