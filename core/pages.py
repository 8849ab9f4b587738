"""Plain memory pages while the core works (no transparent huge pages).

NumPy asks the kernel for transparent huge pages (``madvise``) for every
array of 4 MiB or more. Where the kernel's huge-page defragmentation is
``madvise`` (the usual Linux default) and its memory is fragmented, the
first touch of such an array waits for the kernel to compact memory into
2 MiB pages: on the machine the benchmarks ran on, a fresh process filling
256 MB took 1.85 s one moment and 0.04 s the next, against a steady 0.11 s
with plain 4 KiB pages. The core allocates and fills arrays of tens to
hundreds of MB in every large step (an index's tables, a bind's frames), so
it asks for plain pages while it works (alternating processes, 2026-12-03:
``fit_cage`` of a 1M-vertex scan 8.6-9.0 s against 14.7-15.1 s, of which
2.4 against 9.1 s system time; a first ``simplify`` of the 1.1M-face bunny
x16 6.6-7.0 s against 8.8-11.1 s).

:func:`plain_pages` wraps the core's public entry points: NumPy's setting
is switched off when the outermost of them starts and put back when it
returns or raises (a counter, under a lock: calls nest and may run on
several threads). It is NumPy's process-wide setting, so other threads'
arrays made meanwhile get plain pages too (a performance hint only: results
never change). The environment variable ``MESHADJUST_HUGEPAGES=1`` keeps
NumPy's own setting.

Examples
--------
>>> @plain_pages
... def work(n):
...     return sum(range(n))
>>> work(10)
45
"""

import functools
import importlib
import os
import threading

__all__ = ["plain_pages", "numpy_hugepages"]

#: MESHADJUST_HUGEPAGES=1: leave NumPy's huge-page setting as it is
KEEP_HUGEPAGES = os.environ.get("MESHADJUST_HUGEPAGES", "") == "1"


def _numpy_setter():
    """NumPy's ``_set_madvise_hugepage(enabled) -> previous`` (in
    ``numpy._core.multiarray`` since 1.26, ``numpy.core.multiarray`` before),
    or None where there is none (then nothing is switched)."""
    for name in ("numpy._core.multiarray", "numpy.core.multiarray"):
        try:
            setter = getattr(importlib.import_module(name), "_set_madvise_hugepage", None)
        except ImportError:
            continue
        if setter is not None:
            return setter
    return None


_SET = None if KEEP_HUGEPAGES else _numpy_setter()
_lock = threading.Lock()
_depth = 0
_saved = True


def numpy_hugepages():
    """Whether NumPy currently asks for huge pages for large arrays (None
    where NumPy has no such setting)."""
    setter = _numpy_setter()
    if setter is None:
        return None
    with _lock:
        now = setter(False)
        setter(now)
    return bool(now)


def _enter():
    global _depth, _saved
    with _lock:
        if _depth == 0:
            _saved = _SET(False)
        _depth += 1


def _leave():
    global _depth
    with _lock:
        _depth -= 1
        if _depth == 0:
            _SET(_saved)


def plain_pages(fn):
    """Decorator: run ``fn`` with NumPy's huge pages off (see the module
    docstring); unchanged where NumPy has no such setting or
    ``MESHADJUST_HUGEPAGES=1``."""
    if _SET is None:
        return fn

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        _enter()
        try:
            return fn(*args, **kwargs)
        finally:
            _leave()
    return wrapper
