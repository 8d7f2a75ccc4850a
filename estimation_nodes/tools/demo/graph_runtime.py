"""Running a graph from a script or a test: spin until something holds, start and end child
node processes."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any


def spin_until(executor: Any, done: Callable[[], bool], timeout: float) -> bool:
    """Spin ``executor`` until ``done()`` holds or ``timeout`` seconds pass; ``done()``'s last
    value."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if done():
            return True
        executor.spin_once(timeout_sec=0.02)
    return bool(done())


def stop_process(process: subprocess.Popen, grace: float = 5.0) -> int:
    """End one child by its pid: SIGINT (a clean rclpy shutdown), then SIGKILL."""
    if process.poll() is None:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(timeout=grace)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
    return process.returncode


def start_node(module: str, params: Path, *overrides: str) -> subprocess.Popen:
    """One of the package's nodes (``python -m module``) as a child of this process, with
    its parameter file and ``overrides`` (ROS arguments).

    The child ends with this process even if it is killed (nodes/process.end_with_parent),
    and runs in a process group of its own: a terminal's Ctrl-C then reaches this process
    alone, which stops each child with exactly one SIGINT (``stop_children``).
    """
    from estimation_nodes.nodes.process import PARENT_PID_ENV

    command = [sys.executable, "-m", module, "--ros-args", "--params-file", str(params),
               *overrides]
    return subprocess.Popen(command, env={**os.environ, PARENT_PID_ENV: str(os.getpid())},
                            process_group=0)


def stop_children(processes: Iterable[subprocess.Popen]) -> None:
    """End the children started with ``start_node``, the last started first, once further
    Ctrl-Cs no longer interrupt this process's own shutdown."""
    from estimation_nodes.nodes.process import ignore_further_interrupts

    ignore_further_interrupts()
    for process in reversed(list(processes)):
        stop_process(process)


def run_until_done(executor: Any, processes: dict[str, subprocess.Popen], main: str,
                   deadline: float, linger: float) -> int:
    """Spin until a child ends; the run's exit code: 0 when ``main`` ended well (then spin
    ``linger`` s more), 1 on a timeout or an error, 2 when a node's parameter was invalid.
    Says why on stderr."""
    import sys

    process = processes.get(main)
    finished = process is None or spin_until(
        executor, lambda: any(p.poll() is not None for p in processes.values()),
        deadline - time.monotonic())
    failed = {n: p.returncode for n, p in processes.items()
              if p.poll() is not None and p.returncode != 0}
    if not finished:
        print("estimation_demo: stopped early: --timeout reached", file=sys.stderr)
        return 1
    if failed or process is None or process.poll() is None:
        print(f"estimation_demo: stopped early: exit codes {failed}", file=sys.stderr)
        return 2 if 2 in failed.values() else 1
    spin_until(executor, lambda: False, linger)
    return 0
