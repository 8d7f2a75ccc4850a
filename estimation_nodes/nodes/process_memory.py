"""Keep freed large arrays' pages in the process instead of handing them back to the OS.

glibc gives each large allocation (over 128 KiB at first) fresh pages from the
kernel and returns them when it is freed. A histogram step over a million
cells makes a few arrays of 8 MB each time, so with that default every step
pays for thousands of page faults on fresh zeroed memory, which costs more
than the arithmetic (figures in docs/benchmarks.md). Raising glibc's mmap and
trim thresholds makes
freed blocks reusable by the next step. The cost is that the process keeps
its peak heap instead of shrinking after it; for an estimator whose arrays
keep one size, the peak is the steady state.
"""

from __future__ import annotations

import ctypes
import ctypes.util

_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
#: Allocations up to this size (32 million cells of doubles) come from the reusable heap.
_MMAP_THRESHOLD = 256 * 1024 * 1024
_TRIM_THRESHOLD = 2**31 - 1


def keep_freed_memory() -> bool:
    """Apply the thresholds; False where the C library is not glibc (nothing changes)."""
    name = ctypes.util.find_library("c")
    if name is None:
        return False
    try:
        libc = ctypes.CDLL(name)
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    return bool(mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD)) and bool(
        mallopt(_M_TRIM_THRESHOLD, _TRIM_THRESHOLD))
