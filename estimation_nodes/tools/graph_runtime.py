"""Running a graph from a script or a test: spin until something holds, end a child process."""

from __future__ import annotations

import signal
import subprocess
import time
from collections.abc import Callable
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
