"""Where the batch's files are converted: one by one (``--jobs 1``), in local
worker processes (``--jobs N``) or as tasks on a Dask cluster (``--dask``).

Every runner calls ``on_done(index, report)`` as each file finishes and
returns True when it was interrupted (Ctrl-C), after stopping what it started;
the driver then marks the files without a report as cancelled.

A worker is a fresh process running this tool: with ``--worker JSON`` it
converts one file and prints ``MESHADJUST_RESULT <json report>``; with
``--worker-serve`` it reads one such JSON per line on its stdin and prints a
report for each, until its stdin ends. As each step of a file begins it
prints ``MESHADJUST_STEP <seconds since the file began> <step>``. Every file
is converted in a worker, never in the batch's own process: Blender as a
module is neither thread-safe nor safe to fork, and a file that crashes its
worker (a segmentation fault in an importer, the kernel's OOM killer on a
scan too large for the memory) takes the worker down, not the batch: the
file fails with how the worker died, and the batch goes on. A serial batch
runs its files in one serving worker (``bpy`` imported once, and only when a
file needs Blender; a new worker after one dies or is stopped).

Workers start in a session of their own, so the terminal's Ctrl-C reaches
only the driver, which then stops them in order: SIGTERM (the worker turns
it into a cancel, removes its temporary output and reports), then SIGKILL
after :data:`STOP_GRACE_S`. ``--timeout`` stops a worker the same way when
its file has run longer than the limit, counted from the file's first step
mark (a worker's start and Python's imports are not the file's; a worker
that has not begun its file :data:`START_GRACE_S` after it was handed it is
stopped too); the file fails, timed out in the step of its last mark.

The Dask runner (:mod:`.dask_runner`) starts such a worker on the Dask
worker machines.
"""

import contextlib
import json
import os
import queue
import signal
import subprocess
import threading
import time

RESULT_MARK = "MESHADJUST_RESULT "
#: the line a worker prints as each step of a file begins, then the seconds since the
#: file began and the step's name: ``MESHADJUST_STEP 0.6853 simplify``
STEP_MARK = "MESHADJUST_STEP "
#: the environment variable naming a file (its base name) whose conversion in a worker
#: process aborts that process (``os.abort``: SIGABRT, as a crashing importer does): the
#: tests' way to crash a real worker; read only by workers (``batch._worker_convert``)
CRASH_TEST_VARIABLE = "MESHADJUST_TEST_WORKER_CRASH_ON"
#: seconds a worker gets to stop after SIGTERM before it is killed
STOP_GRACE_S = 10.0
#: with ``--timeout``, seconds a worker may take to begin a file (its first step) before
#: the file's own time counts: a fresh worker's start (Python, NumPy; Blender inside
#: Blender) is not the file's, but a worker that never begins must not hold the batch
START_GRACE_S = 60.0
#: seconds between a driver's looks at its workers
POLL_S = 0.05


def run_serial(tasks, payload, command, on_done, *, timeout=None):
    """Convert the files one by one in one serving worker
    (:class:`ServingWorker`, started with ``command()``; another takes the
    next file after one dies or is stopped). ``payload(task)`` is the
    worker's JSON line for a task; ``timeout``: seconds a file may take
    (None: no limit)."""
    worker, in_worker = None, None     # (the task the worker is converting)
    try:
        for i, task in enumerate(tasks):
            if worker is not None and worker.poll() is not None:     # it died on a file
                worker.close()
                worker = None
            if worker is None:
                worker = ServingWorker(command(), timeout=timeout)
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
    Ctrl-C or SIGTERM is ignored meanwhile: it must not cut this short."""
    with stops_ignored():
        for w in running.values():
            w.terminate()
        for i, w in running.items():
            w.stop()
            on_done(i, w.report(tasks[i], stopped=True))


@contextlib.contextmanager
def stops_ignored():
    """Ctrl-C and SIGTERM ignored inside (a batch stopping its workers after
    one of them: a second must not cut that short), their handlers put back
    after."""
    old = {s: signal.signal(s, signal.SIG_IGN) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)


def step_marks(text):
    """``[(seconds since the file began, step), ...]`` of the
    :data:`STEP_MARK` lines in a worker's output ``text``, in order."""
    marks = []
    for line in text.splitlines():
        if line.startswith(STEP_MARK):
            seconds, _, step = line[len(STEP_MARK):].partition(" ")
            marks.append((float(seconds), step))
    return marks


def _without_marks(text):
    """A worker's output without its step and result lines: what it logged."""
    return "\n".join(ln for ln in text.splitlines()
                     if not ln.startswith((STEP_MARK, RESULT_MARK))).strip()


def worker_report(task, text, code, pid, *, stopped=False, timed_out=None):
    """The report a worker process printed in its output ``text`` (the last
    :data:`RESULT_MARK` line), with ``pid`` its process id; when it printed
    none, a cancelled report (``stopped``: the driver stopped it) or a failed
    one saying how the worker ended (``code``: its exit status, negative for
    a signal), in which step (its last :data:`STEP_MARK`), and quoting its
    last lines, its output as the log. ``timed_out``: ``(limit, seconds)``
    when the driver stopped it for ``--timeout``: the file fails, timed out
    (:func:`timed_out_report`), unless the worker finished it in between."""
    for line in reversed(text.splitlines()):
        if line.startswith(RESULT_MARK):
            r = dict(json.loads(line[len(RESULT_MARK):]), pid=pid)
            if timed_out is None or r["status"] != "cancelled":
                return r
            break
    if timed_out is not None:
        return timed_out_report(task, step_marks(text), *timed_out, pid=pid,
                                log=_without_marks(text))
    if stopped:
        return dict(cancelled_report(task), pid=pid)
    how = f"exit status {code}"
    if code is not None and code < 0:
        how = f"killed by {signal.Signals(-code).name}"
        if -code == getattr(signal, "SIGKILL", None):
            how += ": out of memory? the kernel's OOM killer sends it"
    marks = step_marks(text)
    where = f" in the {marks[-1][1]} step" if marks else ""
    log = _without_marks(text)
    tail = " | ".join(log.splitlines()[-3:])
    return dict(failed_report(task, f"the worker process died ({how}){where}" +
                              (f": {tail}" if tail else ""), log=log), pid=pid)


def timed_out_report(task, marks, limit, seconds, *, pid, log=""):
    """The failed report of a file whose worker was stopped after ``limit``
    seconds (``--timeout``), ``seconds`` after the file began: the step it
    was in (the last of ``marks``, :func:`step_marks` of its output; its
    ``failed_step``, ``"worker"`` when it had not begun) and the time of the
    steps it finished (one step's start to the next's, in ``phases_s``)."""
    phases = {step: round(t1 - t0, 4) for (t0, step), (t1, _) in zip(marks, marks[1:])}
    if marks:
        step = marks[-1][1]
        cause = f"timed out after {limit:g} s (--timeout), in the {step} step"
    else:
        step = "worker"
        cause = (f"timed out: the worker process had not begun the file {seconds:.0f} s after "
                 f"it was handed it (--timeout {limit:g} s counts from the file's first step, "
                 f"after up to {START_GRACE_S:g} s for a worker to start)")
    return file_report(task, "failed", failed_step=step, error=f"{task['name']}: {cause}",
                       timed_out=True, phases_s=phases, seconds=round(seconds, 4), pid=pid,
                       log=log)


class _Worker:
    """A worker process (``self.proc``) in a session of its own, its stdout
    and stderr together, read by a thread into a queue (``select`` on a
    pipe is POSIX only; ``None`` at its end) and taken into ``self.text``,
    the output of the current file. ``timeout``: seconds a file may take
    from its first step mark (None: no limit), enforced by
    :meth:`check_time`."""

    def __init__(self, cmd, stdin, timeout):
        self.proc = subprocess.Popen(cmd, stdin=stdin, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, start_new_session=True)
        self.timeout = timeout
        self.text = b""
        self.chunks = queue.Queue()
        self.reader = threading.Thread(target=self._read, daemon=True,
                                       name="batch-worker-output")
        self.reader.start()
        self.term_sent = None          # (when SIGTERM was sent: it is sent once)
        self._hand_file()

    def _hand_file(self):
        """A file's clock: handed to the worker now, not begun, not stopped."""
        self.handed, self.began, self.stopped_at = time.monotonic(), None, None

    def poll(self):
        return self.proc.poll()

    def _read(self):
        """(The reader thread) the worker's output, chunk by chunk, then None."""
        stream = self.proc.stdout
        for chunk in iter(lambda: stream.read1(1 << 16), b""):
            self.chunks.put(chunk)
        self.chunks.put(None)

    def _take(self, wait):
        """Take the worker's output that has come, waiting up to ``wait``
        seconds for some, into ``self.text`` (the file's first step mark
        starts its clock); returns False at the end of the output, which
        stays in the queue for later takes."""
        try:
            chunk = self.chunks.get(timeout=wait) if wait else self.chunks.get_nowait()
        except queue.Empty:
            return True
        while chunk is not None:
            self.text += chunk
            try:
                chunk = self.chunks.get_nowait()
            except queue.Empty:
                break
        if self.began is None and STEP_MARK.encode() in self.text:
            self.began = time.monotonic()
        if chunk is None:
            self.chunks.put(None)
            return False
        return True

    def check_time(self):
        """Enforce the timeout: SIGTERM to a worker whose file has run
        longer than ``timeout`` (a worker that has not begun it:
        :data:`START_GRACE_S` longer), SIGKILL :data:`STOP_GRACE_S` after."""
        if self.timeout is None or self.proc.poll() is not None:
            return
        now = time.monotonic()
        if self.stopped_at is None:
            start = self.began if self.began is not None else self.handed + START_GRACE_S
            if now >= start + self.timeout:
                self.stopped_at = now
                self.terminate()
        elif now >= self.term_sent + STOP_GRACE_S:
            self._send(hard=True)

    def _signal(self, hard):
        """SIGTERM (``hard``: SIGKILL) to the worker's session; where there
        are no sessions (Windows), Popen's terminate (kill)."""
        if not hasattr(os, "killpg"):
            (self.proc.kill if hard else self.proc.terminate)()
        else:
            os.killpg(self.proc.pid, signal.SIGKILL if hard else signal.SIGTERM)

    def _send(self, hard):
        """:meth:`_signal` to a worker still running (it may end in between)."""
        if self.proc.poll() is None:
            try:
                self._signal(hard)
            except ProcessLookupError:     # it ended in between
                pass

    def terminate(self):
        """SIGTERM to the worker's session, without waiting; only once: the
        worker turns each into a cancel, and a second could land in its
        handling of the first (its report, its clean-up)."""
        if self.term_sent is None and self.proc.poll() is None:
            self.term_sent = time.monotonic()
            self._send(hard=False)

    def stop(self):
        """SIGTERM (unless sent already), then SIGKILL when the grace period
        since it has passed."""
        self.terminate()
        if self.proc.poll() is not None:
            return
        try:
            self.proc.wait(timeout=max(0.0, self.term_sent + STOP_GRACE_S - time.monotonic()))
        except subprocess.TimeoutExpired:
            self._send(hard=True)
            try:
                self.proc.wait(timeout=5.0)
            except subprocess.TimeoutExpired:
                pass

    def report(self, task, *, stopped=False):
        """The current file's report (:func:`worker_report`), from the text
        since the last one; the worker's exit status when it has ended;
        timed out when :meth:`check_time` stopped it."""
        if self.proc.poll() is not None:
            self._drain()
        text, self.text = self.text.decode("utf-8", "replace"), b""
        timed_out = None
        if self.stopped_at is not None:
            start = self.began if self.began is not None else self.handed
            timed_out = (self.timeout, time.monotonic() - start)
        return worker_report(task, text, self.proc.returncode, self.proc.pid, stopped=stopped,
                             timed_out=timed_out)

    def _drain(self):
        """Take what an ended worker left in its output (the reader thread
        reaches the end of it within ``STOP_GRACE_S``)."""
        deadline = time.monotonic() + STOP_GRACE_S
        while self._take(max(0.0, deadline - time.monotonic())) and \
                time.monotonic() < deadline:
            pass

    def _close_output(self):
        self.reader.join(timeout=STOP_GRACE_S)
        self.proc.stdout.close()


class WorkerProcess(_Worker):
    """One worker process converting one file (``--worker JSON``)."""

    def __init__(self, cmd, *, timeout=None):
        super().__init__(cmd, subprocess.DEVNULL, timeout)

    def poll(self):
        """The worker's exit status, None while it runs; takes its output
        and enforces the timeout (:meth:`check_time`) on the way."""
        self._take(0)
        self.check_time()
        return self.proc.poll()

    def report(self, task, *, stopped=False):
        """The worker's report (:meth:`_Worker.report`), once it has ended."""
        r = super().report(task, stopped=stopped)
        self._close_output()
        return r


class ServingWorker(_Worker):
    """One long-lived worker process converting files one after the other
    (``--worker-serve``): a JSON line per file on its stdin, its output read
    up to the file's :data:`RESULT_MARK` line. The text since the last
    report is the current file's (the log quoted if it dies). A worker
    stopped for the timeout takes no more files."""

    def __init__(self, cmd, *, timeout=None):
        super().__init__(cmd, subprocess.PIPE, timeout)

    def convert(self, task, payload_json):
        """The report of ``task``: the worker's, or a failed one when it died
        converting it or was stopped for the timeout (it then takes no more
        files)."""
        self._hand_file()
        try:
            self.proc.stdin.write(payload_json.encode("utf-8") + b"\n")
            self.proc.stdin.flush()
        except (BrokenPipeError, OSError):    # it died since its last file: said below
            pass
        while True:
            more = self._take(POLL_S)
            if self._has_report():
                break
            if not more or self.proc.poll() is not None:   # the end of its output, or of it
                try:
                    self.proc.wait(timeout=STOP_GRACE_S)
                except subprocess.TimeoutExpired:      # (its output closed, itself alive)
                    self.stop()
                break
            self.check_time()
        if self.stopped_at is not None:      # (it reported its cancel, or finished: it leaves)
            self.stop()
        return self.report(task)

    def _has_report(self):
        whole = self.text[:self.text.rfind(b"\n") + 1]
        return whole.startswith(RESULT_MARK.encode()) or b"\n" + RESULT_MARK.encode() in whole

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
        self._close_output()


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
         "failed_step": None, "error": None, "timed_out": False, "seconds": None, "pid": None,
         "log": ""}
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


def run_processes(tasks, payload, command, jobs, on_done, *, timeout=None):
    """Convert the files in up to ``jobs`` worker processes at a time.

    ``payload(task)`` is the worker's JSON argument, ``command(payload)`` its
    command line; ``timeout``: seconds a file may take (None: no limit)."""
    pending = list(range(len(tasks)))
    running = {}
    try:
        while pending or running:
            while pending and len(running) < jobs:
                i = pending.pop(0)
                running[i] = WorkerProcess(command(payload(tasks[i])), timeout=timeout)
            for i in [i for i, w in running.items() if w.poll() is not None]:
                on_done(i, running.pop(i).report(tasks[i]))
            time.sleep(POLL_S)
        return False
    except KeyboardInterrupt:
        _stop_all(running, tasks, on_done)
        return True
