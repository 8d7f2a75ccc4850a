"""Helpers that the tests and the benchmarks share: seeded large worlds, resident memory."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def write_world(cells: int, directory: Path) -> Path:
    """A world file of ``cells`` dark and bright cells, drawn with ``cells`` as the seed."""
    rng = np.random.default_rng(cells)
    names = np.where(rng.random(cells) < 0.5, "dark", "bright")
    path = directory / f"world_{cells}.txt"
    path.write_text("\n".join(names.tolist()) + "\n", encoding="utf-8")
    return path


def large_world_params(directory: Path, cells: int, steps: int, history_depth: int = 1) -> Path:
    """A parameter file for the tile graph on ``write_world(cells)``, ``steps`` moves of 1;
    the estimator's outputs keep ``history_depth`` estimates."""
    world = write_world(cells, directory)
    model = (f"    world_file: {world}\n    classes: [bright, dark]\n"
             f"    sensor_model: [0.8, 0.2, 0.4, 0.6]\n    motion_kernel: [0.1, 0.8, 0.1]\n")
    params = directory / "large.yaml"
    params.write_text(
        f"/**/motion_commander:\n  ros__parameters:\n    commands: [1]\n    repeat: true\n"
        f"    max_commands: {steps}\n    rate_hz: 4.0\n"
        f"/**/tile_sensor:\n  ros__parameters:\n{model}    seed: 3\n"
        f"/**/estimator:\n  ros__parameters:\n{model}    history_depth: {history_depth}\n")
    return params


def resident_mib(pid: int | str = "self") -> float:
    """A process's resident memory (VmRSS) in MiB."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError(f"no VmRSS for process {pid}")
