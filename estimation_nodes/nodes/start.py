"""Where each node's process starts: a Ctrl-C ends it quietly from its first line on.

A node's module imports rclpy, numpy and the core before its ``main()`` runs:
a few tenths of a second, more under load, in which a Ctrl-C raised
KeyboardInterrupt out of an import (Python's traceback, and the process killed
by SIGINT). The console scripts (what ``ros2 run`` runs) and the demo's
children therefore start here; this module imports nothing heavy, and a Ctrl-C
before the node's own ``main()`` has begun ends the process (once the import is
done) with exit code 0, as a Ctrl-C of a running node does (process.run).

    python -m estimation_nodes.nodes.start estimator --ros-args --params-file FILE

What comes before this module, Python's own start-up (some 40 ms), is not ours
to handle; the demo starts its children with SIGINT blocked
(tools/demo/graph_runtime.start_node), so a Ctrl-C then waits for this module,
which unblocks it.
"""

from __future__ import annotations

import _thread
import importlib
import signal
import sys
import time
from collections.abc import Callable
from typing import Any

#: Seconds before a Ctrl-C swallowed by a finalizer is given back (the hook returns in
#: microseconds).
REDELIVERY_DELAY_S = 0.01

#: Each node's executable and the module that holds its ``main()``.
NODE_MODULES = {
    "estimator": "estimation_nodes.nodes.estimator",
    "tile_sensor": "estimation_nodes.nodes.tile_sensor",
    "linear_system": "estimation_nodes.nodes.linear_system",
    "motion_commander": "estimation_nodes.nodes.motion_commander",
    "grid_localizer": "estimation_nodes.nodes.grid_localizer",
    "planar_robot": "estimation_nodes.nodes.planar_robot",
    "ekf_localizer": "estimation_nodes.nodes.ekf_localizer",
    "landmark_robot": "estimation_nodes.nodes.landmark_robot",
    "ekf_node": "estimation_nodes.nodes.ekf_node",
    "ukf_node": "estimation_nodes.nodes.ukf_node",
}


def run_main(module: str, interrupted_code: int) -> None:
    """Import ``module`` and call its ``main()``; a Ctrl-C during the import ends the
    process, once the import is done, with ``interrupted_code`` and nothing printed.

    The handler only notes the Ctrl-C: raised in the middle of an import, an exception
    came out as another error (numpy's C extension: ImportError "could not import module
    datetime") or was swallowed with a traceback ("Exception ignored in" a weakref
    callback of importlib) and the node ran on.
    """
    interrupted = False

    def note(_signum: int, _frame: Any) -> None:
        nonlocal interrupted
        interrupted = True

    # A process started with SIGINT ignored (a background job) keeps it so.
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        importlib.import_module(module).main()
        return
    signal.signal(signal.SIGINT, note)
    # One that came while Python was starting (the demo starts its children with SIGINT
    # blocked) arrives now.
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    main: Callable[[], None] = importlib.import_module(module).main
    if interrupted:
        signal.signal(signal.SIGINT, signal.SIG_IGN)   # the end has begun
        sys.exit(interrupted_code)
    # From here on the program's own handling (KeyboardInterrupt, or a noted Ctrl-C:
    # nodes/process.py).
    signal.signal(signal.SIGINT, signal.default_int_handler)
    sys.unraisablehook = redeliver_interrupts
    try:
        main()
    except (Exception, KeyboardInterrupt) as error:
        # A Ctrl-C that the program's own handling missed: one that landed in a module
        # imported late, which a C extension's loader turned into another error (rpyutils:
        # ImportError "initialization failed", from KeyboardInterrupt).
        if not caused_by_interrupt(error):
            raise
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        sys.exit(interrupted_code)


def redeliver_interrupts(unraisable: Any) -> None:
    """``sys.unraisablehook``: a Ctrl-C that landed in a finalizer (rclpy's
    ``RcutilsLogger.__del__``, a weakref callback) is swallowed there by Python with an
    "Exception ignored in" traceback; it is given back to the main thread instead, where
    the program's own handling takes it. Anything else goes to Python's own hook."""
    if isinstance(unraisable.exc_value, KeyboardInterrupt):
        # Not from here: an interrupt raised inside this hook is swallowed in its turn.
        _thread.start_new_thread(_interrupt_main_soon, ())
        return
    sys.__unraisablehook__(unraisable)


def _interrupt_main_soon() -> None:
    """The Ctrl-C given back once the hook has returned; one that lands in a finalizer
    again comes back through the hook again."""
    time.sleep(REDELIVERY_DELAY_S)
    _thread.interrupt_main()     # nothing where SIGINT is ignored (the end has begun)


def caused_by_interrupt(error: BaseException) -> bool:
    """Whether ``error`` is a KeyboardInterrupt or was raised while handling one (its
    ``__cause__`` or ``__context__`` chain holds one)."""
    seen: set[int] = set()
    link: BaseException | None = error
    while link is not None and id(link) not in seen:
        if isinstance(link, KeyboardInterrupt):
            return True
        seen.add(id(link))
        link = link.__cause__ or link.__context__
    return False


def estimator() -> None:
    run_main(NODE_MODULES["estimator"], 0)


def tile_sensor() -> None:
    run_main(NODE_MODULES["tile_sensor"], 0)


def linear_system() -> None:
    run_main(NODE_MODULES["linear_system"], 0)


def motion_commander() -> None:
    run_main(NODE_MODULES["motion_commander"], 0)


def grid_localizer() -> None:
    run_main(NODE_MODULES["grid_localizer"], 0)


def planar_robot() -> None:
    run_main(NODE_MODULES["planar_robot"], 0)


def ekf_localizer() -> None:
    run_main(NODE_MODULES["ekf_localizer"], 0)


def landmark_robot() -> None:
    run_main(NODE_MODULES["landmark_robot"], 0)


def ekf_node() -> None:
    run_main(NODE_MODULES["ekf_node"], 0)


def ukf_node() -> None:
    run_main(NODE_MODULES["ukf_node"], 0)


def _run_named() -> None:
    """``python -m estimation_nodes.nodes.start NODE [ARGS]``: NODE's main() with ARGS."""
    if len(sys.argv) < 2 or sys.argv[1] not in NODE_MODULES:
        print(f"usage: python -m {__spec__.name if __spec__ else 'start'} NODE [ARGS]; NODE "
              f"one of {', '.join(NODE_MODULES)}", file=sys.stderr)
        sys.exit(2)
    name = sys.argv.pop(1)
    sys.argv[0] = name
    run_main(NODE_MODULES[name], 0)


if __name__ == "__main__":
    _run_named()
