"""The numba kernels of a feature, imported and compiled once, on first use.

numba and LLVM take memory and start-up time that a small world never pays
back, so no kernel module is imported until a filter step asks for it.
"""

from __future__ import annotations

import functools
import importlib
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from types import ModuleType
from typing import Any


@functools.cache
def load_kernels(module: str) -> ModuleType | None:
    """``module`` imported and warmed up (compiled, or loaded from numba's cache); None where
    numba does not import (missing, or not matching this numpy): the caller takes numpy's
    path. A Ctrl-C while it compiles is raised once the compilation is over."""
    with interrupts_held_through_callbacks():
        try:
            kernels = importlib.import_module(module)
        except ImportError:
            return None
        kernels.warm_up()
    return kernels


@contextmanager
def interrupts_held_through_callbacks() -> Iterator[None]:
    """Raise, at the end of the block, a KeyboardInterrupt that a C callback swallowed.

    LLVM calls back into Python (llvmlite's object cache) while numba compiles; a Ctrl-C
    raised in such a ctypes callback cannot leave it: Python prints it as "Exception
    ignored on calling ctypes callback function", with a traceback, and drops it. Here it
    is noted instead, and raised where it can be handled.
    """
    swallowed: list[BaseException | None] = []
    previous_hook = sys.unraisablehook

    def hold(unraisable: Any) -> None:
        if unraisable.exc_type is not None and issubclass(unraisable.exc_type,
                                                          KeyboardInterrupt):
            swallowed.append(unraisable.exc_value)
        else:
            previous_hook(unraisable)

    sys.unraisablehook = hold
    try:
        yield
    finally:
        sys.unraisablehook = previous_hook
    if swallowed:
        raise KeyboardInterrupt


#: Every feature's kernel module.
KERNEL_MODULES = ("estimation_nodes.core.tiles.compiled", "estimation_nodes.core.kalman.compiled",
                  "estimation_nodes.core.grid.compiled", "estimation_nodes.core.fusion.compiled")


def warm_all() -> list[str]:
    """Compile every feature's kernels into numba's cache (beside the installed modules):
    the kernel modules that imported. Run once after an install (the Makefile does), so a
    node's first start and the tests load them instead of compiling (tens of seconds on a
    busy machine)."""
    return [module for module in KERNEL_MODULES if load_kernels(module) is not None]


if __name__ == "__main__":
    warmed = warm_all()
    print(f"numba kernels compiled into the cache: {len(warmed)} of {len(KERNEL_MODULES)}")

