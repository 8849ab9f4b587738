"""Run NumPy-heavy blocks of work on a few threads (private).

NumPy releases the GIL inside its array operations, so independent blocks of
a long vectorised computation run side by side on several cores. Blocks of
a few tens of thousands of elements also keep the temporaries in cache and
below the allocator's ``mmap`` threshold, which makes even the one-thread
case faster than a single pass over millions of elements.

Results never depend on the number of threads: the blocks are fixed by the
problem size alone and every block writes its own slice.
"""

import os
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import NamedTuple

#: worker threads (at most 4: the hot loops are memory bound beyond that;
#: the environment variable MESHADJUST_THREADS overrides it, 1 runs everything inline)
WORKERS = int(os.environ.get("MESHADJUST_THREADS", 0)) or max(1, min(4, os.cpu_count() or 1))

_lock = threading.Lock()
_pool = None


def _executor():
    global _pool
    with _lock:
        if _pool is None:
            _pool = ThreadPoolExecutor(max_workers=WORKERS, thread_name_prefix="meshadjust")
        return _pool


def blocks(n, size):
    """Split ``range(n)`` into consecutive ``(start, stop)`` blocks of about ``size``."""
    if n <= 0:
        return []
    k = max(1, -(-n // max(1, size)))
    edges = [(i * n) // k for i in range(k + 1)]
    return list(zip(edges[:-1], edges[1:]))


def _inline(items, threads=True):
    """Whether ``items`` run inline: fewer than two, ``threads`` False, or
    :func:`_no_workers`."""
    return not threads or len(items) <= 1 or _no_workers()


def _no_workers():
    """Whether work runs inline whatever its size: one worker, or already on
    a worker."""
    return WORKERS == 1 or threading.current_thread().name.startswith("meshadjust")


def run_each(fn, items, threads=True):
    """``[fn(item) for item in items]``, on the worker threads when there are
    several items (and this is not already a worker, and ``threads``: False
    for work too small to repay the hand-offs); results in item order."""
    items = list(items)
    if _inline(items, threads):
        return [fn(item) for item in items]
    return list(_executor().map(fn, items))


def run_blocks(fn, spans):
    """Call ``fn(start, stop)`` for every span of :func:`blocks`, as :func:`run_each`."""
    return run_each(lambda s: fn(*s), spans)


def each_in_order(fn, items):
    """Yield ``fn(item)`` for every item, in item order, as soon as it is
    done, the items running on the worker threads meanwhile (inline when
    :func:`run_each` would run them inline). Leaving the loop early (an
    exception, ``break``) cancels the items not yet started."""
    items = list(items)
    if _inline(items):
        for item in items:
            yield fn(item)
        return
    futures = [_executor().submit(fn, item) for item in items]
    try:
        for future in futures:
            yield future.result()
    finally:
        for future in futures:
            future.cancel()


class _Done(NamedTuple):
    """A result already there (:func:`in_background` run inline)."""

    value: object

    def result(self):
        return self.value

    def cancel(self):
        return False


def in_background(fn):
    """Start ``fn()`` on a worker thread (inline where there is none to hand
    it to: :func:`_no_workers`) and return at once: ``.result()`` waits for
    its value (or raises its exception), ``.cancel()`` drops it if it has
    not started.
    The worker runs it alone (its own ``run_each`` calls inline), while the
    caller's further work runs on the other workers."""
    if _no_workers():
        return _Done(fn())
    return _executor().submit(fn)
