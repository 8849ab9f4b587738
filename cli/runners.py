"""Where the batch's files are converted: one by one (``--jobs 1``), in local
worker processes (``--jobs N``) or as tasks on a Dask cluster (``--dask``).

Every runner calls ``on_done(index, report)`` as each file finishes and
returns True when it was interrupted (Ctrl-C), after stopping what it started;
the driver then marks the files without a report as cancelled.

A worker is a fresh process running this tool: with ``--worker JSON`` it
converts one file and prints ``MESHADJUST_RESULT <json report>``; with
``--worker-serve`` it reads one such JSON per line on its stdin and prints a
report for each, until its stdin ends. Blender as a module is neither
thread-safe nor safe to fork, and a crash (a segmentation fault in an
importer) takes the worker down, not the batch: the file it was converting
fails with how the worker died, and the batch goes on. A serial batch runs
the files Blender reads or writes in one serving worker (``bpy`` imported
once; a new one after a crash) and converts OBJ and SMF in its own process:
the core is NumPy only and fails by raising, which the file's report takes.
Workers start in a session of their own, so the terminal's Ctrl-C reaches
only the driver, which then stops them in order: SIGTERM (the worker turns
it into a cancel, removes its temporary output and reports), then SIGKILL
after :data:`STOP_GRACE_S`.

On Dask each task starts such a process on its worker machine with the
worker's own Python (``python -m meshadjust.cli.batch``, or the checkout's
``scripts/meshadjust_batch.py`` when the driver runs from a checkout; the
paths must be the same on every machine). A cancel is a Dask ``Event`` the
running tasks poll; tasks not yet started are cancelled by the client.
"""

import json
import os
import queue
import signal
import subprocess
import sys
import tempfile
import threading
import time
import uuid

RESULT_MARK = "MESHADJUST_RESULT "
#: the environment variable naming a file (its base name) whose conversion in a worker
#: process aborts that process (``os.abort``: SIGABRT, as a crashing importer does): the
#: tests' way to crash a real worker; read only by workers (``batch._worker_convert``)
CRASH_TEST_VARIABLE = "MESHADJUST_TEST_WORKER_CRASH_ON"
#: seconds a worker gets to stop after SIGTERM before it is killed
STOP_GRACE_S = 10.0
_POLL_S = 0.05


def run_serial(tasks, convert, on_done, *, isolate, payload, command):
    """Convert the files one by one: those ``isolate(task)`` picks in one
    serving worker (:class:`ServingWorker`, started with ``command()``;
    another takes the next of them after one dies), the others in this
    process with ``convert(task)``. ``payload(task)`` is the worker's JSON
    line for a task."""
    worker, in_worker = None, None     # (the task the worker is converting)
    try:
        for i, task in enumerate(tasks):
            if not isolate(task):
                report = dict(convert(task), pid=os.getpid())
            else:
                if worker is not None and worker.poll() is not None:     # it died on a file
                    worker.close()
                    worker = None
                if worker is None:
                    worker = ServingWorker(command())
                in_worker = i
                report = worker.convert(task, payload(task))
                in_worker = None
            on_done(i, report)
        return False
    except KeyboardInterrupt:
        _stop_all({} if in_worker is None else {in_worker: worker}, tasks, on_done)
        return True
    finally:
        if worker is not None:
            worker.close()


def _stop_all(running, tasks, on_done):
    """After a Ctrl-C: SIGTERM to every worker of ``running`` ({task index:
    worker}) at once, then each stopped in turn (:meth:`_Worker.stop`) and
    its file reported (cancelled, unless it finished in between). A second
    Ctrl-C is ignored meanwhile: it must not cut this short."""
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        for w in running.values():
            w.terminate()
        for i, w in running.items():
            w.stop()
            on_done(i, w.report(tasks[i], stopped=True))
    finally:
        signal.signal(signal.SIGINT, old)


def worker_report(task, text, code, pid, *, stopped=False):
    """The report a worker process printed in its output ``text`` (the last
    :data:`RESULT_MARK` line), with ``pid`` its process id; when it printed
    none, a cancelled report (``stopped``: the driver stopped it) or a failed
    one saying how the worker ended (``code``: its exit status, negative for
    a signal) and quoting its last lines, its output as the log."""
    for line in reversed(text.splitlines()):
        if line.startswith(RESULT_MARK):
            return dict(json.loads(line[len(RESULT_MARK):]), pid=pid)
    if stopped:
        return dict(cancelled_report(task), pid=pid)
    how = f"exit status {code}"
    if code is not None and code < 0:
        how = f"killed by {signal.Signals(-code).name}"
    tail = " | ".join(text.strip().splitlines()[-3:])
    return dict(failed_report(task, f"the worker process died ({how})" +
                              (f": {tail}" if tail else ""), log=text), pid=pid)


class _Worker:
    """A worker process (``self.proc``) in a session of its own, its stdout
    and stderr together."""

    def __init__(self, cmd, **streams):
        self.proc = subprocess.Popen(cmd, stderr=subprocess.STDOUT, start_new_session=True,
                                     **streams)

    def poll(self):
        return self.proc.poll()

    def _signal(self, hard):
        """SIGTERM (``hard``: SIGKILL) to the worker's session; where there
        are no sessions (Windows), Popen's terminate (kill)."""
        if not hasattr(os, "killpg"):
            (self.proc.kill if hard else self.proc.terminate)()
        else:
            os.killpg(self.proc.pid, signal.SIGKILL if hard else signal.SIGTERM)

    def terminate(self):
        """SIGTERM to the worker's session, without waiting."""
        if self.proc.poll() is None:
            try:
                self._signal(hard=False)
            except ProcessLookupError:     # it ended in between
                pass

    def stop(self):
        """SIGTERM, then SIGKILL after the grace period."""
        for hard, wait in ((False, STOP_GRACE_S), (True, 5.0)):
            if self.proc.poll() is not None:
                return
            try:
                self._signal(hard)
            except ProcessLookupError:
                return
            try:
                self.proc.wait(timeout=wait)
            except subprocess.TimeoutExpired:
                continue


class WorkerProcess(_Worker):
    """One worker process converting one file, its output in a temporary file."""

    def __init__(self, cmd):
        self.out = tempfile.TemporaryFile()
        super().__init__(cmd, stdout=self.out, stdin=subprocess.DEVNULL)

    def report(self, task, *, stopped=False):
        """The worker's report (:func:`worker_report`)."""
        self.out.seek(0)
        text = self.out.read().decode("utf-8", "replace")
        self.out.close()
        return worker_report(task, text, self.proc.returncode, self.proc.pid, stopped=stopped)


class ServingWorker(_Worker):
    """One long-lived worker process converting files one after the other
    (``--worker-serve``): a JSON line per file on its stdin, its output read
    up to the file's :data:`RESULT_MARK` line. The text since the last
    report is the current file's (the log quoted if it dies). A thread
    reads the worker's output into a queue (``select`` on a pipe is POSIX
    only), ``None`` at its end."""

    def __init__(self, cmd):
        super().__init__(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE)
        self.text = b""
        self.chunks = queue.Queue()
        self.reader = threading.Thread(target=self._read, daemon=True,
                                       name="batch-worker-output")
        self.reader.start()

    def _read(self):
        """(The reader thread) the worker's output, chunk by chunk, then None."""
        stream = self.proc.stdout
        for chunk in iter(lambda: stream.read1(1 << 16), b""):
            self.chunks.put(chunk)
        self.chunks.put(None)

    def convert(self, task, payload_json):
        """The report of ``task``: the worker's, or a failed one when it died
        converting it (it then takes no more files)."""
        try:
            self.proc.stdin.write(payload_json.encode("utf-8") + b"\n")
            self.proc.stdin.flush()
        except (BrokenPipeError, OSError):    # it died since its last file: said below
            pass
        while True:
            try:
                chunk = self.chunks.get(timeout=_POLL_S)
            except queue.Empty:
                chunk = b""
            if chunk:
                self.text += chunk
                if self._has_report():
                    return self.report(task)
            elif chunk is None or self.proc.poll() is not None:   # the end of its output, or of it
                if chunk is None:
                    self.chunks.put(None)         # (the end stays in the queue for _drain)
                try:
                    self.proc.wait(timeout=STOP_GRACE_S)
                except subprocess.TimeoutExpired:      # (its output closed, itself alive)
                    self.stop()
                return self.report(task)

    def _has_report(self):
        whole = self.text[:self.text.rfind(b"\n") + 1]
        return whole.startswith(RESULT_MARK.encode()) or b"\n" + RESULT_MARK.encode() in whole

    def report(self, task, *, stopped=False):
        """The current file's report (:func:`worker_report`), from the text
        since the last one; the worker's exit status when it has ended."""
        if self.proc.poll() is not None:
            self._drain()
        text, self.text = self.text.decode("utf-8", "replace"), b""
        return worker_report(task, text, self.proc.returncode, self.proc.pid, stopped=stopped)

    def _drain(self):
        """Take what an ended worker left in its output (the reader thread
        reaches the end of it within ``STOP_GRACE_S``)."""
        deadline = time.monotonic() + STOP_GRACE_S
        while True:
            try:
                chunk = self.chunks.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                return
            if chunk is None:
                self.chunks.put(None)        # (a later report drains nothing more)
                return
            self.text += chunk

    def close(self):
        """End the worker: its stdin closed, it leaves (stopped if it does not)."""
        try:
            self.proc.stdin.close()
        except (BrokenPipeError, OSError):
            pass
        try:
            self.proc.wait(timeout=STOP_GRACE_S)
        except subprocess.TimeoutExpired:
            self.stop()
        self.reader.join(timeout=STOP_GRACE_S)
        self.proc.stdout.close()


def file_report(task, status, **fields):
    """A file's record in the report, every key present whatever its status
    (a skipped, cancelled or crashed file's had only a few: a pipeline
    reading ``files[i]["faces_in"]`` of a resumed batch met a KeyError):
    ``task``'s input and name, ``status``, then ``fields`` over the empty
    values of the rest. (Here, not in ``cli.report``: Dask sends this module
    by value, and the workers of a remote cluster cannot import the package.)"""
    r = {"input": task["input"], "name": task["name"], "status": status,
         "faces_in": None, "polygons_in": None, "target_faces": None, "max_error_pct": None,
         "faces_out": None, "stopped_because": None, "message": None, "deviation_pct": None,
         "mean_deviation_pct": None, "cleaning": None, "fit": None, "refined_faces": None,
         "phases_s": {}, "outputs": [], "incomplete": [], "warnings": [], "notes": [],
         "failed_step": None, "error": None, "seconds": None, "pid": None, "log": ""}
    unknown = set(fields) - set(r)
    if unknown:
        raise KeyError(f"file_report: no such field {sorted(unknown)}")
    r.update(fields)
    return r


def failed_report(task, cause, *, log=""):
    return file_report(task, "failed", failed_step="worker", error=f"{task['name']}: {cause}",
                       log=log)


def cancelled_report(task):
    return file_report(task, "cancelled")


def run_processes(tasks, payload, command, jobs, on_done):
    """Convert the files in up to ``jobs`` worker processes at a time.

    ``payload(task)`` is the worker's JSON argument, ``command(payload)`` its
    command line."""
    pending = list(range(len(tasks)))
    running = {}
    try:
        while pending or running:
            while pending and len(running) < jobs:
                i = pending.pop(0)
                running[i] = WorkerProcess(command(payload(tasks[i])))
            for i in [i for i, w in running.items() if w.poll() is not None]:
                on_done(i, running.pop(i).report(tasks[i]))
            time.sleep(_POLL_S)
        return False
    except KeyboardInterrupt:
        _stop_all(running, tasks, on_done)
        return True


def _dask_task(entry, payload_json, cancel_event):
    """Runs on a Dask worker: one worker process for one file; polls the
    cancel event while it runs."""
    from distributed import Event
    task = json.loads(payload_json)["task"]
    event = Event(cancel_event)
    if event.is_set():         # queued on this worker when the batch was cancelled
        return cancelled_report(task)
    w = WorkerProcess([sys.executable, *entry, "--worker", payload_json])
    while w.poll() is None:
        try:
            w.proc.wait(timeout=0.5)
        except subprocess.TimeoutExpired:
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


def run_dask(tasks, payload, entry, address, jobs, on_done):
    """Convert the files as tasks on a Dask cluster: ``address`` is a
    scheduler (``tcp://host:8786``) or ``"local"`` for a ``LocalCluster`` of
    ``jobs`` workers in this process (each task runs its own worker process,
    so threads are enough here)."""
    import cloudpickle
    from distributed import Client, Event, LocalCluster, as_completed
    # The task travels by value, so the scheduler and the workers need not
    # import this module (only run the tool): Dask pickles an importable
    # function by reference and uses cloudpickle only for what plain pickle
    # refuses, such as this lambda, whose globals cloudpickle then sends by
    # value because the module is registered.
    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    task_fn = lambda *a: _dask_task(*a)  # noqa: E731
    cluster = None
    if address == "local":
        cluster = LocalCluster(n_workers=jobs, threads_per_worker=1, processes=False,
                               dashboard_address=None)
        client = Client(cluster)
    else:
        client = _remote_client(Client, address)
    cancel_event = f"meshadjust-cancel-{uuid.uuid4().hex}"
    try:
        futures = [client.submit(task_fn, entry, payload(task), cancel_event, pure=False,
                                 key=f"meshadjust-{i}-{uuid.uuid4().hex[:8]}")
                   for i, task in enumerate(tasks)]
        index = {f.key: i for i, f in enumerate(futures)}
        done = set()

        def collect(fut):
            i = index[fut.key]
            try:
                report = fut.result()
            except Exception as exc:     # the task itself failed on the worker
                report = failed_report(tasks[i], f"the Dask task failed: {type(exc).__name__}: {exc}")
            done.add(i)
            on_done(i, report)

        try:
            for fut in as_completed(futures):
                collect(fut)
            return False
        except KeyboardInterrupt:
            old = signal.signal(signal.SIGINT, signal.SIG_IGN)
            try:
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
                        time.sleep(_POLL_S)
                    if f.status == "finished":
                        collect(f)
            finally:
                signal.signal(signal.SIGINT, old)
            return True
    finally:
        client.close()
        if cluster is not None:
            cluster.close()

