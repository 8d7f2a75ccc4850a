"""Running a graph from a script or a test: spin until something holds, start and end child
node processes, and the demo's one run block (``run_graph``) with its Ctrl-C handling."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from estimation_nodes.nodes.interrupts import HeldInterrupts

#: The exit code of a run ended by Ctrl-C: the shell's for an end by SIGINT.
INTERRUPTED = 130


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


def start_node(name: str, params: Path, *overrides: str,
               command: Sequence[str] | None = None) -> subprocess.Popen:
    """The package's node ``name`` (nodes/start.py) as a child of this process, with its
    parameter file and ``overrides`` (ROS arguments); or ``command`` (a tool of the
    package, such as estimation_play), started the same way.

    The child ends with this process even if it is killed (nodes/process.end_with_parent),
    and runs in a process group of its own: a terminal's Ctrl-C then reaches this process
    alone, which stops each child with exactly one SIGINT (``stop_children``). It starts in
    nodes/start.py, so that this SIGINT ends it quietly even while it is still loading.
    """
    from estimation_nodes.nodes.process import PARENT_PID_ENV

    if command is None:
        command = [sys.executable, "-m", "estimation_nodes.nodes.start", name, "--ros-args",
                   "--params-file", str(params), *overrides]
    # The child inherits this thread's signal mask: with SIGINT blocked, a stop sent while
    # Python is still starting up (before any code of ours could take it; it would print
    # "Fatal Python error") waits until nodes/start.py unblocks it.
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    # PYTHONSAFEPATH: ``python -m`` would put the current folder first on the child's path,
    # so a demo started in a source checkout ran its nodes on the checkout's code and
    # itself on the installed package's; the child imports what this process would.
    env = {**os.environ, PARENT_PID_ENV: str(os.getpid()), "PYTHONSAFEPATH": "1"}
    try:
        return subprocess.Popen(command, env=env, process_group=0)
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)


def stop_children(processes: Iterable[subprocess.Popen]) -> None:
    """End the children started with ``start_node``, the last started first."""
    for process in reversed(list(processes)):
        stop_process(process)


@dataclass(frozen=True)
class NodeStart:
    """One node of a run: its executable name and ROS arguments, started once ``ready``
    (given the monitor) holds; None: at once."""

    name: str
    overrides: tuple[str, ...] = ()
    ready: Callable[[Any], bool] | None = None
    #: A tool's whole command line instead of a node's (see ``start_node``).
    command: tuple[str, ...] | None = None


def run_graph(params: Path, make_monitor: Callable[[], Any], starts: Sequence[NodeStart],
              main: str, timeout: float, linger: float) -> tuple[int, Any]:
    """The demo's run: start each of ``starts`` in turn, watched by the node that
    ``make_monitor`` makes, until ``main`` ends (then ``linger`` s more); then end every
    child by its pid. Returns the exit code (``run_until_done``'s, or 130 after a Ctrl-C)
    and the monitor (None if it could not be made).

    A Ctrl-C in any phase ends the run the same way: the children started so far are
    stopped, none is left behind, nothing is printed but one line. It is noted, not raised
    where it lands: a KeyboardInterrupt raised inside rclpy (the executor building a Task)
    left half-made objects whose finalizers printed tracebacks. The spins look at the note
    every 20 ms. rclpy's own signal handler is left out: it would shut the context down
    under the run.
    """
    processes: dict[str, subprocess.Popen] = {}
    executor = monitor = None
    code = 0
    held = HeldInterrupts()

    def check_interrupt() -> None:
        if held.noted:
            raise KeyboardInterrupt

    with held:
        # Imported here, under the hold: rclpy's C extension loader turned a Ctrl-C in
        # the middle of its import into ImportError "initialization failed".
        import rclpy
        from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions

        try:
            check_interrupt()
            rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
            executor = SingleThreadedExecutor()
            monitor = make_monitor()
            executor.add_node(monitor)
            deadline = time.monotonic() + timeout

            def any_ended() -> bool:
                return any(p.poll() is not None for p in processes.values())

            for start in starts:
                check_interrupt()
                if start.ready is not None:
                    # A node that ended (a bad parameter) ends the wait and the run.
                    spin_until(executor, lambda s=start: held.noted or s.ready(monitor)
                               or any_ended(), deadline - time.monotonic())
                    check_interrupt()
                    if any_ended():
                        break
                processes[start.name] = start_node(start.name, params, *start.overrides,
                                                   command=start.command)
            code = run_until_done(executor, processes, main, deadline, linger,
                                  interrupted=lambda: held.noted)
            check_interrupt()
        except (KeyboardInterrupt, ExternalShutdownException):
            code = INTERRUPTED
        finally:
            if code == INTERRUPTED or held.noted:
                print("estimation_demo: interrupted, stopping the nodes", file=sys.stderr)
            stop_children(processes.values())
            if monitor is not None:
                monitor.destroy_node()
            if executor is not None:
                executor.shutdown(timeout_sec=1.0)
            rclpy.try_shutdown()
    if held.noted:
        code = INTERRUPTED
    if code == INTERRUPTED:
        # The end has begun: the summary is printed whole, a second Ctrl-C is ignored.
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    return code, monitor


def run_until_done(executor: Any, processes: dict[str, subprocess.Popen], main: str,
                   deadline: float, linger: float,
                   interrupted: Callable[[], bool] = lambda: False) -> int:
    """Spin until a child ends; the run's exit code: 0 when ``main`` ended well (then spin
    ``linger`` s more), 1 on a timeout or an error, 2 when a node's parameter was invalid.
    Says why on stderr. Returns at once (the code then does not matter) once
    ``interrupted()`` holds."""
    import sys

    process = processes.get(main)
    finished = process is None or spin_until(
        executor, lambda: interrupted() or any(p.poll() is not None
                                               for p in processes.values()),
        deadline - time.monotonic())
    if interrupted():
        return INTERRUPTED
    failed = {n: p.returncode for n, p in processes.items()
              if p.poll() is not None and p.returncode != 0}
    if not finished:
        print("estimation_demo: stopped early: --timeout reached", file=sys.stderr)
        return 1
    if failed or process is None or process.poll() is None:
        print(f"estimation_demo: stopped early: exit codes {failed}", file=sys.stderr)
        return 2 if 2 in failed.values() else 1
    spin_until(executor, interrupted, linger)
    return 0
