"""The numba kernels of a feature, imported and compiled once, on first use.

numba and LLVM take memory and start-up time that a small world never pays
back, so no kernel module is imported until a filter step asks for it.
"""

from __future__ import annotations

import functools
import importlib
from types import ModuleType


@functools.cache
def load_kernels(module: str) -> ModuleType | None:
    """``module`` imported and warmed up (compiled, or loaded from numba's cache); None where
    numba does not import (missing, or not matching this numpy): the caller takes numpy's
    path."""
    try:
        kernels = importlib.import_module(module)
    except ImportError:
        return None
    kernels.warm_up()
    return kernels
