"""A node's process: main(), exit codes, ending with the parent that started it."""

from __future__ import annotations

import ctypes
import os
import signal
import sys
from collections.abc import Callable, Sequence

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

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
    # A Ctrl-C is an end in every phase: before rclpy.init() Python raises KeyboardInterrupt;
    # after it, rclpy's handler shuts the context down and the spin raises
    # ExternalShutdownException.
    try:
        if not end_with_parent():
            return 0
        if prepare is not None:
            prepare()
        try:
            for path in params_files_in(argv):
                check_params_file(path)
            rclpy.init(args=argv)
        except (ValueError, RCLError) as error:
            print(f"[FATAL] [{name}]: cannot start: {str(error).split(', at ')[0]}",
                  file=sys.stderr)
            return 2
        node = node_class()
        rclpy.spin(node)
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
