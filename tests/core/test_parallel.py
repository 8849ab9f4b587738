"""core/_parallel.py: each_in_order yields in order, runs the items on the
worker threads, and cancels the items not yet started when left early."""

import threading
import time

import pytest

import core._parallel as parallel


def test_each_in_order_yields_every_result_in_item_order():
    def slow_first(i):
        time.sleep(0.02 if i == 0 else 0.0)
        return i * i
    assert list(parallel.each_in_order(slow_first, range(7))) == [i * i for i in range(7)]
    assert list(parallel.each_in_order(slow_first, [])) == []


def test_each_in_order_runs_inline_on_a_worker_thread():
    names = []

    def outer(_):
        # called on a worker thread: the inner items run inline, no deadlock
        return list(parallel.each_in_order(lambda i: threading.current_thread().name, range(3)))
    for inner in parallel.each_in_order(outer, range(2)):
        names.extend(inner)
    if parallel.WORKERS > 1:
        assert all(n.startswith("meshadjust") for n in names)


def test_run_each_keeps_item_order_and_runs_inline_when_told():
    def name(i):
        return i, threading.current_thread().name
    threaded = parallel.run_each(name, range(5))
    inline = parallel.run_each(name, range(5), threads=False)
    assert [i for i, _ in threaded] == [i for i, _ in inline] == list(range(5))
    assert all(n == threading.current_thread().name for _, n in inline)
    if parallel.WORKERS > 1:
        assert all(n.startswith("meshadjust") for _, n in threaded)


@pytest.mark.skipif(parallel.WORKERS < 2, reason="needs worker threads")
def test_leaving_early_cancels_the_items_not_started():
    started = []

    def item(i):
        started.append(i)
        time.sleep(0.01)
        return i
    gen = parallel.each_in_order(item, range(100))
    assert next(gen) == 0
    gen.close()                           # leaving the loop early
    time.sleep(0.1)                       # the ones running finish; the rest never start
    assert len(started) < 20


def test_in_background_runs_beside_the_caller_and_gives_its_result_or_error():
    started = threading.Event()
    release = threading.Event()

    def build():
        started.set()
        assert release.wait(5)
        # on its worker, its own blocks run inline (no wait on the pool it holds)
        return threading.current_thread().name, parallel.run_each(lambda i: i * i, range(4))

    if parallel.WORKERS > 1:
        job = parallel.in_background(build)
        assert started.wait(5)          # it runs while the caller goes on
        assert parallel.run_each(lambda i: -i, range(3)) == [0, -1, -2]
        release.set()
        name, squares = job.result()
        assert name.startswith("meshadjust") and squares == [0, 1, 4, 9]
    else:
        release.set()
        assert parallel.in_background(build).result()[1] == [0, 1, 4, 9]

    def fails():
        raise ValueError("no index")
    with pytest.raises(ValueError, match="no index"):
        parallel.in_background(fails).result()


def test_in_background_on_a_worker_runs_inline():
    def outer(_):
        job = parallel.in_background(lambda: threading.current_thread().name)
        return job.result() == threading.current_thread().name and not job.cancel()
    assert all(parallel.run_each(outer, range(2)))
