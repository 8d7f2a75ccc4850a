"""A node's process: main(), exit codes, ending with the parent that started it."""

from __future__ import annotations

import ctypes
import os
import signal
import sys
from collections.abc import Callable, Sequence

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from estimation_nodes.nodes.interrupts import HeldInterrupts
from estimation_nodes.nodes.parameters import ConfigurationError
from estimation_nodes.nodes.rclpy_internals import RCLError
from estimation_nodes.params.param_files import check_params_file, params_files_in


def run(node_class: Callable[..., Node], args: Sequence[str] | None = None,
        prepare: Callable[[], None] | None = None) -> int:
    """Run one node until Ctrl-C or shutdown, the way the Jazzy demos do; ``prepare`` (a
    process-wide set-up) runs first, where a Ctrl-C ends the process as in any phase.

    Returns the process exit code: 0 on a normal end, 2 when a parameter is
    invalid (one log line names it), 1 on an unexpected error.
    """
    name = getattr(node_class, "node_name", node_class.__name__)
    argv = list(sys.argv if args is None else args)
    node = None
    code = 0
    # A Ctrl-C is an end in every phase: until the node is made Python raises
    # KeyboardInterrupt; from the spin on it is noted and ends the spin at its next turn
    # (spin_until_interrupted). rclpy's own handler is left out: it raised KeyboardInterrupt
    # anywhere in rclpy, in an executor's constructor too, whose finalizer then printed
    # a traceback.
    try:
        if not end_with_parent():
            return 0
        if prepare is not None:
            prepare()
        try:
            for path in params_files_in(argv):
                check_params_file(path)
            rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
        except (ValueError, RCLError) as error:
            print(f"[FATAL] [{name}]: cannot start: {str(error).split(', at ')[0]}",
                  file=sys.stderr)
            return 2
        node = node_class()
        spin_until_interrupted(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RCLError:
        # rclpy may still run a ready callback after Ctrl-C has shut the context down;
        # whatever it asked of rcl then fails with "context is invalid": a normal end.
        if rclpy.ok():
            raise
    except ConfigurationError as error:
        rclpy.logging.get_logger(name).fatal(f"invalid parameter {error}")
        code = 2
    except SystemExit as done:
        code = int(done.code or 0)
    finally:
        ignore_further_interrupts()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return code


#: How long a spin waits for work before it looks whether a Ctrl-C came (s): the most a
#: Ctrl-C of an idle node waits.
SPIN_TURN_S = 0.1


def spin_until_interrupted(node: Node) -> None:
    """Spin ``node`` until a Ctrl-C or the context's shutdown; a callback's SystemExit or
    error comes out as it was raised."""
    with HeldInterrupts(restore=False) as held:
        executor = SingleThreadedExecutor(context=node.context)
        try:
            executor.add_node(node)
            while not held.noted and executor.context.ok():
                executor.spin_once(timeout_sec=SPIN_TURN_S)
        finally:
            executor.shutdown(timeout_sec=0)


def ignore_further_interrupts() -> None:
    """Let a shutdown that has begun finish: a second Ctrl-C (a terminal and a launcher
    both sending SIGINT) would otherwise break into it with a traceback."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


#: Set by a parent (estimation_demo) to its pid: the node then ends when that
#: parent dies, even by SIGKILL, instead of running on as an orphan.
PARENT_PID_ENV = "ESTIMATION_NODES_PARENT_PID"
_PR_SET_PDEATHSIG = 1


def end_with_parent() -> bool:
    """Ask Linux for a SIGINT (a clean shutdown) when the parent named in the
    environment dies. False when that parent is already gone: nothing to run for.
    Does nothing when run by hand, or off Linux."""
    expected = os.environ.get(PARENT_PID_ENV)
    if not expected or not sys.platform.startswith("linux"):
        return True
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGINT, 0, 0, 0)
    except (OSError, AttributeError):
        return True
    # Checked after prctl: a parent that died before it took effect sends nothing.
    return str(os.getppid()) == expected


def main_for(node_class: Callable[..., Node],
             prepare: Callable[[], None] | None = None) -> Callable[[], None]:
    """A console-script entry point for ``node_class`` (``prepare``: see ``run``)."""

    def main(args: Sequence[str] | None = None) -> None:
        sys.exit(run(node_class, args, prepare))

    return main
