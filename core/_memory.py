"""Keep freed memory for reuse during a long NumPy computation (private).

The simplifier's passes allocate and free many temporaries of tens of
megabytes. glibc serves blocks that large with a fresh ``mmap`` each time
and hands them back on ``free``, so every pass pays the kernel for zeroed
pages again (about 15% of a 1M-triangle run). Inside
:func:`reuse_freed_memory` large blocks come from the heap and stay there
for the next pass; on the way out the thresholds go back to glibc's usual
steady-state values and the unused heap is returned to the system.

Anywhere else (macOS, Windows, musl, or a process whose ``malloc`` is not
glibc's) this does nothing.
"""

import ctypes
import ctypes.util
import sys
import threading
from contextlib import contextmanager

_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
_RUN_MMAP = 1 << 30             # blocks below 1 GiB come from the heap ...
_RUN_TRIM = (1 << 31) - 1       # ... and freed ones stay there
_MMAP_DEFAULT = 32 << 20        # glibc's dynamic thresholds settle at these (64-bit)
_TRIM_DEFAULT = 64 << 20

_lock = threading.Lock()
_depth = 0
_libc = None


def _glibc():
    global _libc
    if _libc is None:
        _libc = False
        if sys.platform.startswith("linux"):
            try:
                libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
                libc.gnu_get_libc_version  # glibc only
                _libc = libc
            except (OSError, AttributeError):
                pass
    return _libc


@contextmanager
def reuse_freed_memory():
    """Context in which freed large blocks are kept for reuse (glibc only;
    nested and concurrent uses are counted, the last one out restores)."""
    global _depth
    libc = _glibc()
    if not libc:
        yield
        return
    with _lock:
        if _depth == 0:
            libc.mallopt(_M_MMAP_THRESHOLD, _RUN_MMAP)
            libc.mallopt(_M_TRIM_THRESHOLD, _RUN_TRIM)
        _depth += 1
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0:
                libc.mallopt(_M_MMAP_THRESHOLD, _MMAP_DEFAULT)
                libc.mallopt(_M_TRIM_THRESHOLD, _TRIM_DEFAULT)
                libc.malloc_trim(0)
