"""The batch on a Dask cluster (``--dask``): each file a task that starts a
worker process (:mod:`.runners`) on its Dask worker machine with that
worker's own Python (``python -m meshadjust.cli.batch``, or the checkout's
``scripts/meshadjust_batch.py`` when the driver runs from a checkout; the
paths must be the same on every machine), and enforces ``--timeout`` there.
A cancel is a Dask ``Event`` the running tasks poll; tasks not yet started
are cancelled by the client.
"""

import contextlib
import json
import logging
import sys
import time
import uuid

from . import runners
from .runners import (POLL_S, STOP_GRACE_S, WorkerProcess, cancelled_report, failed_report,
                      stops_ignored)

#: seconds between a Dask task's looks at the batch's cancel event (a round trip each)
_EVENT_POLL_S = 0.5


def _dask_task(entry, payload_json, cancel_event, timeout=None):
    """Runs on a Dask worker: one worker process for one file, stopped
    there when it runs past ``timeout`` seconds; polls the cancel event
    while it runs."""
    from distributed import Event
    task = json.loads(payload_json)["task"]
    event = Event(cancel_event)
    if event.is_set():         # queued on this worker when the batch was cancelled
        return cancelled_report(task)
    w = WorkerProcess([sys.executable, *entry, "--worker", payload_json], timeout=timeout)
    looked = time.monotonic()
    while w.poll() is None:
        time.sleep(POLL_S)
        if time.monotonic() - looked >= _EVENT_POLL_S:
            looked = time.monotonic()
            if event.is_set():
                w.stop()
                return w.report(task, stopped=True)
    return w.report(task)


class SchedulerUnreachable(Exception):
    """The Dask scheduler ``--dask`` names cannot be reached (an unknown
    scheme, nothing answering there); the message says which and why."""


def _remote_client(Client, address):
    """A Dask ``Client`` of the scheduler at ``address``; raises
    :class:`SchedulerUnreachable` (the batch ended in distributed's
    traceback: "ValueError: unknown address scheme", "OSError: Timed out
    trying to connect")."""
    try:
        return Client(address, timeout="20s")
    except (OSError, ValueError, TimeoutError) as exc:
        raise SchedulerUnreachable(f"cannot reach the Dask scheduler {address}: "
                                   f"{' '.join(str(exc).split())}") from None


def task_function():
    """The function each Dask task runs (``_dask_task``), made to travel by
    value, so the scheduler and the workers need not import this package
    (only run the tool): Dask pickles an importable function by reference
    and uses cloudpickle only for what plain pickle refuses, such as this
    lambda, whose globals cloudpickle then sends by value because their
    modules (this one and :mod:`.runners`) are registered."""
    import cloudpickle
    for module in (sys.modules[__name__], runners):
        cloudpickle.register_pickle_by_value(module)
    return lambda *a: _dask_task(*a)  # noqa: E731


def run_dask(tasks, payload, entry, address, jobs, on_done, *, timeout=None):
    """Convert the files as tasks on a Dask cluster: ``address`` is a
    scheduler (``tcp://host:8786``) or ``"local"`` for a ``LocalCluster`` of
    ``jobs`` workers in this process (each task runs its own worker process,
    so threads are enough here); ``timeout``: seconds a file may take, its
    task's worker process stopped on the Dask worker past it."""
    from distributed import Client, Event, LocalCluster, as_completed
    task_fn = task_function()
    cluster = None
    if address == "local":
        cluster = LocalCluster(n_workers=jobs, threads_per_worker=1, processes=False,
                               dashboard_address=None)
        client = Client(cluster)
    else:
        client = _remote_client(Client, address)
    cancel_event = f"meshadjust-cancel-{uuid.uuid4().hex}"
    try:
        futures = [client.submit(task_fn, entry, payload(task), cancel_event, timeout,
                                 pure=False, key=f"meshadjust-{i}-{uuid.uuid4().hex[:8]}")
                   for i, task in enumerate(tasks)]
        index = {f.key: i for i, f in enumerate(futures)}
        done = set()

        def collect(fut):
            i = index[fut.key]
            try:
                report = fut.result()
            except Exception as exc:     # the task itself failed on the worker
                report = failed_report(tasks[i],
                                       f"the Dask task failed: {type(exc).__name__}: {exc}")
            done.add(i)
            on_done(i, report)

        try:
            for fut in as_completed(futures):
                collect(fut)
            return False
        except KeyboardInterrupt:
            with stops_ignored():
                Event(cancel_event, client=client).set()
                running = {k for keys in client.processing().values() for k in keys}
                waiting = [f for f in futures if index[f.key] not in done]
                client.cancel([f for f in waiting if f.key not in running])
                # the running tasks see the event, stop their worker and report
                deadline = time.monotonic() + STOP_GRACE_S + 5
                for f in waiting:
                    if f.key not in running:
                        continue
                    while f.status == "pending" and time.monotonic() < deadline:
                        time.sleep(POLL_S)
                    if f.status == "finished":
                        collect(f)
            return True
    finally:
        with quiet_logs("distributed"):
            client.close()
            if cluster is not None:
                cluster.close()


@contextlib.contextmanager
def quiet_logs(prefix):
    """Hold the loggers named ``prefix`` and below to CRITICAL meanwhile: a
    closing cluster races its own messages (a worker's batched send on a
    comm the scheduler has closed) and distributed logs each such
    CommClosedError with its traceback, which the batch's terminal showed
    after a run whose every file had a report (seen once in a test run
    under load)."""
    names = [prefix] + [n for n in list(logging.root.manager.loggerDict)
                        if n.startswith(prefix + ".")]
    loggers = [logging.getLogger(n) for n in names]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        for lg, level in zip(loggers, levels):
            lg.setLevel(level)

