"""meshadjust-batch: simplify (and optionally fit and refine) many meshes.

    meshadjust-batch scans/ --faces 2000 --fit --refine 2 --out out/ --report out/report.json
    meshadjust-batch scans/ --ratio 0.01 --dask tcp://scheduler:8786 --out /shared/out
    .venv/bin/python scripts/meshadjust_batch.py scan.smf --faces 500      # from a checkout

Inputs are files or folders (searched one level) of OBJ and SMF (read by the
core, NumPy only) and PLY, STL, glTF/GLB (Blender's importers: needs the bpy
module). For each input ``NAME.ext`` it writes ``NAME_cage.<fmt>`` and, with
``--refine``, ``NAME_refined.<fmt>`` into ``--out``; inputs whose names
collide get their extension in the name (``scan.obj`` and ``scan.ply`` ->
``scan_obj_cage.obj``, ``scan_ply_cage.obj``), then a number.

Before any compute the output folder, every output path, the report and the
log are checked (a file where the folder should be, a name too long for the
file system: an immediate error naming the path, exit status 2). Outputs
appear under their final names only when every step of their file succeeded;
a file that failed after the simplify keeps its cage as
``incomplete/NAME_cage.<fmt>`` in the output folder (and ``--skip-existing``
runs it again). Every file is converted in a worker process
(``cli.runners``): a file that crashes its worker fails alone, and with
``--timeout SECONDS`` a file still converting after that long is stopped
and fails, timed out in the step it was in, leaving no output. At the
end one table row per file (status ``ok``, ``warn`` with the reason,
``FAILED`` with the step and the cause, ``skipped``, ``cancelled``), a
summary line, and with ``--report`` a JSON report of every file. Exit status:
0 all converted (warnings allowed unless ``--strict``), 1 a file failed or
timed out (or warned, with ``--strict``), 2 bad arguments, 130 interrupted
(Ctrl-C: the workers are stopped, the summary and the report still written).
"""

import argparse
import datetime
import importlib.util
import json
import math
import os
import shutil
import signal
import sys
import threading
import time
from collections import Counter
from dataclasses import asdict

if __name__ == "__main__" and __package__ == "cli":
    # `python -m cli.batch` in a checkout: the folder is then a top-level package, whose
    # modules cannot import the core beside it as `..core` (an ImportError traceback); the
    # checkout's script runs the tool as the package `meshadjust` instead, and exits
    import runpy
    runpy.run_path(os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                "scripts", "meshadjust_batch.py"), run_name="__main__")

from . import blender_io  # noqa: E402
from . import convert as _convert  # noqa: E402
from . import dask_runner, outputs, report, runners  # noqa: E402
from ..core.errors import InvalidArgumentError  # noqa: E402
from ..core.subdivide import check_subdivision_args  # noqa: E402

PROG = "meshadjust-batch"
#: how a worker process is started from an installed package
MODULE_ENTRY = ["-m", "meshadjust.cli.batch"]


def parse_args(argv, prog=PROG):
    p = argparse.ArgumentParser(
        prog=prog,
        description="Simplify meshes into cages with MeshAdjust (QEM), optionally fit the "
                    "cages to the originals and refine them back with the detail.",
        epilog="Exit status: 0 all files converted (warnings allowed unless --strict), 1 a file "
               "failed or timed out, 2 bad arguments or output paths, 130 interrupted (Ctrl-C), "
               "143 stopped (SIGTERM). Inside "
               "Blender put the options after '--': blender -b -P scripts/meshadjust_batch.py -- "
               "IN... --faces N.")
    p.add_argument("inputs", nargs="+", help="mesh files or folders (.obj .smf: NumPy only; "
                   ".ply .stl .gltf .glb: Blender's importers)")
    _cage_arguments(p)
    p.add_argument("--fit", action="store_true", help="fit the cage so its subdivision "
                   "matches the input (undoes QEM's shrinkage; evaluated at --refine's levels, "
                   "at most 2: more gain nothing)")
    p.add_argument("--refine", type=int, metavar="LEVELS", default=0,
                   help="also write the cage refined LEVELS times with the input's detail")
    p.add_argument("--scheme", choices=("butterfly", "loop"), default="butterfly",
                   help="subdivision scheme for --fit and --refine (default: butterfly)")
    _run_arguments(p)
    args = p.parse_args(argv)
    _check(p, args)
    return args


def _cage_arguments(p):
    """The arguments of the simplify step: the target and the cage's options."""
    target = p.add_mutually_exclusive_group(required=True)
    target.add_argument("--faces", type=int, metavar="N", help="cage face count")
    target.add_argument("--ratio", type=float, metavar="R", help="cage faces as a fraction "
                        "(0 < R <= 1) of the input's")
    target.add_argument("--max-error", type=float, metavar="E", help="stop before the error "
                        "exceeds E percent of the bounding-box diagonal")
    p.add_argument("--feature-angle", type=float, default=60.0, metavar="DEG",
                   help="dihedral angle above which edges are kept sharp (default 60)")
    p.add_argument("--max-dihedral", type=float, default=None, metavar="DEG",
                   help="stop before a collapse would bend two adjacent cage faces by more than "
                        "DEG degrees away from the creases (0 < DEG < 180; default: no bound)")
    p.add_argument("--weld-distance", type=float, default=None, metavar="D",
                   help="weld vertices on open edges closer than D of the bounding-box "
                        "diagonal (default: automatic, 1e-6 widening to 1e-5 or 1e-4 when "
                        "the input comes in pieces)")
    p.add_argument("--keep-pinholes", action="store_true",
                   help="keep every hole: by default, when holes keep the cage from its target, "
                        "those smaller than one cage face (a scan's dropouts) are capped and "
                        "the file simplified again (the report counts them)")
    p.add_argument("--symmetry", choices=("X", "Y", "Z"), default=None,
                   help="make the cage mirror-symmetric about the plane through the origin "
                        "normal to this axis, in the file's coordinates (the fit keeps it so); "
                        "an input whose two sides differ by more than "
                        f"{100 * _convert.ASYMMETRY_NOTE:g}%% of its size fails")


def _run_arguments(p):
    """The arguments of the run: outputs, workers, the report."""
    p.add_argument("--out", default="out", metavar="DIR", help="output folder (default: out)")
    p.add_argument("--format", choices=_convert.OUTPUT_FORMATS, default=None,
                   help="output format (default: the input's own, glTF as glb)")
    p.add_argument("--jobs", type=int, default=1, metavar="N",
                   help="files converted at once, each in its own worker process (default 1: "
                        "one after the other in one worker process, a new one after a file "
                        "crashes it or times out); with --dask local, the number of Dask "
                        "workers")
    p.add_argument("--timeout", type=float, default=None, metavar="SECONDS",
                   help="stop a file still converting SECONDS after its first step began "
                        "(wall-clock; default: no limit) as Ctrl-C stops a worker: the file "
                        "fails, timed out in the step it was in, leaves no output "
                        "(--skip-existing runs it again), and the batch goes on")
    p.add_argument("--dask", metavar="ADDRESS", default=None,
                   help="send each file as a task to a Dask scheduler (tcp://host:8786), or "
                        "'local' for a LocalCluster of --jobs workers; needs dask.distributed, "
                        "and paths every worker sees")
    p.add_argument("--report", metavar="FILE.json", default=None,
                   help="write a JSON report: per file the input, faces in and out, target, why "
                        "it stopped, deviation, cleaning, time of each step, outputs, warnings")
    p.add_argument("--log", metavar="FILE", default=None,
                   help="write Blender's log here (default: into the report, never to stdout)")
    p.add_argument("--skip-existing", action="store_true",
                   help="skip a file whose outputs all exist already, made from it as it is "
                        "now (to resume a batch; outputs are written only when every step "
                        "succeeded; a failed file keeps its cage in OUT/incomplete/ and runs "
                        "again; OUT/.meshadjust-sources.jsonl records each output's input)")
    p.add_argument("--strict", action="store_true",
                   help="exit 1 when a file only warned (missed target, unchanged cage)")


def _check(p, args):
    """Refuse values the run could not use (``p.error``: exit status 2)."""
    if args.faces is not None and args.faces < 4:
        p.error("--faces must be at least 4")
    if args.ratio is not None and not 0 < args.ratio <= 1:
        p.error("--ratio must be in (0, 1]")
    if args.max_error is not None and not 0 < args.max_error < math.inf:
        p.error("--max-error must be a positive number")
    if not 0 < args.feature_angle <= 180:
        p.error("--feature-angle must be in (0, 180] degrees")
    if args.max_dihedral is not None and not 0 < args.max_dihedral < 180:
        p.error("--max-dihedral must be in (0, 180) degrees")
    if args.weld_distance is not None and not 0 <= args.weld_distance < 1:
        p.error("--weld-distance must be in [0, 1) (a share of the bounding-box diagonal)")
    if args.timeout is not None and not 0 < args.timeout < math.inf:
        p.error(f"--timeout must be a positive number of seconds, got {args.timeout:g}")
    if args.refine < 0 or args.jobs < 1:
        p.error("--refine must be >= 0 and --jobs >= 1")
    try:     # (levels no cage of --faces faces, or of 4, takes: --refine 99 failed after the
        #      simplify, its cage kept in incomplete/)
        check_subdivision_args(args.refine, args.scheme, "--refine", args.faces or 4)
    except InvalidArgumentError as exc:
        p.error(str(exc))


def options(args):
    return _convert.Options(faces=args.faces, ratio=args.ratio, max_error_pct=args.max_error,
                            fit=args.fit, refine=args.refine, scheme=args.scheme,
                            feature_angle_deg=args.feature_angle, format=args.format,
                            symmetry=args.symmetry, max_dihedral_deg=args.max_dihedral,
                            weld_distance=args.weld_distance,
                            close_pinholes=not args.keep_pinholes)


def _is_output(name):
    stem = os.path.splitext(name)[0]
    return stem.endswith("_cage") or stem.endswith("_refined")


def collect_inputs(paths, out=None):
    """``(files, problems)``: the files to convert, in the order given
    (folders: their mesh files, sorted; in the output folder itself, not the
    cages and refined meshes a run wrote there, as its record of sources
    (:func:`~.outputs.read_sources`) lists them: a file of the user's own
    named like one, ``scan_cage.obj``, had been left out without a word and
    then overwritten by ``scan.obj``'s cage, where it is now an input, which
    :func:`_inputs_overwritten` names; the same file named twice is
    converted once), and a message for each folder whose files cannot be
    listed (no read permission: the batch had ended in a raw PermissionError,
    exit 1, the other inputs not converted)."""
    files, seen, problems = [], set(), []
    out = os.path.realpath(out) if out is not None else None
    for path in paths:
        if os.path.isdir(path):
            ours = outputs.read_sources(path) if os.path.realpath(path) == out else {}
            try:
                names = os.listdir(path)
            except OSError as exc:
                problems.append(f"{path}: cannot list the folder's files ({exc.strerror})")
                continue
            found = _without_links_to_others(sorted(
                os.path.join(path, f) for f in names
                if os.path.splitext(f)[1].lower() in _convert.INPUT_EXTENSIONS
                and not (_is_output(f) and f in ours)))
        else:
            found = [path]
        for f in found:
            key = os.path.realpath(f)
            if key not in seen:
                seen.add(key)
                files.append(f)
    return files, problems


def _without_links_to_others(found):
    """The files ``found`` in a folder but the symbolic links to another of
    them: the file is converted under its own name (a link sorted before it,
    ``link_to_suzanne.obj``, took its row and its outputs' names)."""
    real = {os.path.realpath(f) for f in found if not os.path.islink(f)}
    return [f for f in found if not (os.path.islink(f) and os.path.realpath(f) in real)]


def plan(files, opts, out):
    """One task per file: its name as shown and its output paths, distinct
    even when input names collide (compared without case)."""
    bases = [_base_name(f) for f in files]
    stems = [os.path.splitext(b)[0] for b in bases]
    n_stem = Counter(s.casefold() for s in stems)
    n_base = Counter(b.casefold() for b in bases)
    used, tasks = set(), []
    for f, stem, base_name in zip(files, stems, bases):
        if n_stem[stem.casefold()] > 1:
            stem = f"{stem}_{os.path.splitext(base_name)[1].lower().lstrip('.')}"
        base, k = stem, 2
        while stem.casefold() in used:
            stem, k = f"{base}_{k}", k + 1
        used.add(stem.casefold())
        fmt = _convert.output_format(base_name, opts)
        name = base_name if n_base[base_name.casefold()] == 1 else f
        tasks.append({"input": os.path.abspath(f), "name": name,
                      "cage": os.path.join(out, f"{stem}_cage.{fmt}"),
                      "refined": os.path.join(out, f"{stem}_refined.{fmt}") if opts.refine
                      else None})
    return tasks


def _base_name(path):
    """The last part of ``path``, also when it ends with a separator (an
    input 'scans/' that is no folder was shown with an empty name, its
    outputs named '_cage.obj')."""
    return os.path.basename(path.rstrip(os.sep) or path)


def check_paths(args):
    """Problems with --out, --report and --log, found before any compute."""
    problems = []
    if os.path.exists(args.out) and not os.path.isdir(args.out):
        problems.append(f"--out {args.out} is a file, not a folder")
    else:
        try:
            os.makedirs(args.out, exist_ok=True)
        except OSError as exc:
            problems.append(f"--out {args.out}: cannot create it ({exc.strerror})")
        else:
            if not os.access(args.out, os.W_OK | os.X_OK):
                problems.append(f"--out {args.out}: not writable")
    for opt, path in (("--report", args.report), ("--log", args.log)):
        if path is None:
            continue
        folder = os.path.dirname(os.path.abspath(path))
        if os.path.isdir(path):
            problems.append(f"{opt} {path} is a folder")
        elif not os.path.isdir(folder):
            problems.append(f"{opt} {path}: no folder {folder}")
        elif not os.access(folder, os.W_OK):
            problems.append(f"{opt} {path}: {folder} is not writable")
        elif why := outputs.write_problem(path):
            problems.append(f"{opt} {path}: cannot be written ({why})")
    if (args.format in blender_io.BLENDER_EXPORT and args.dask is None
            and "bpy" not in sys.modules and importlib.util.find_spec("bpy") is None):
        problems.append(f"--format {args.format} needs Blender (the bpy module); "
                        f"obj and smf need only NumPy")
    if args.dask is not None:
        try:
            import distributed  # noqa: F401
        except ImportError:
            problems.append("--dask needs dask.distributed (pip install 'dask[distributed]')")
    return problems


#: glibc's ``mallopt`` parameters (``malloc.h``) a worker sets, and their value: blocks
#: up to this size come from the heap, and up to this much freed there stays for reuse
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_HEAP_REUSE = 1 << 30


def reuse_freed_memory():
    """Let this process's ``malloc`` (glibc's) serve blocks up to 1 GiB from
    its heap and keep up to 1 GiB freed there for the next ones, instead of
    mapping every large block fresh from the kernel and unmapping it when
    freed: the core's passes make and drop arrays of tens of MB, and each
    fresh page costs a fault. A 1.1M-face scan's job (simplify, fit, refine
    x2) 10.8 -> 10.1 s on the 2-core machine, its kernel time 1.85 -> 0.92
    s (page faults 919k -> 362k), the same peak memory; simplify alone 3.68
    -> 3.28 s. For the batch's own worker processes only (an add-on leaves
    Blender's memory alone). Returns whether it applied (False without
    glibc)."""
    import ctypes
    try:
        libc = ctypes.CDLL("libc.so.6")
        return bool(libc.mallopt(_M_MMAP_THRESHOLD, _HEAP_REUSE)
                    and libc.mallopt(_M_TRIM_THRESHOLD, _HEAP_REUSE))
    except (OSError, AttributeError):      # (not glibc: macOS, Windows, musl)
        return False


def _as_worker():
    """A worker's signals: SIGTERM is a cancel (a ``KeyboardInterrupt``), and
    the terminal's Ctrl-C is the driver's to decide; its memory reused
    (:func:`reuse_freed_memory`)."""
    import signal
    reuse_freed_memory()

    def terminate(signum, frame):
        raise KeyboardInterrupt
    signal.signal(signal.SIGTERM, terminate)
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _worker_convert(payload):
    """Convert the file of a worker's ``payload`` (its task and options) and
    print its report on a line of its own, and each step's start as it
    begins (``runners.STEP_MARK``); returns False when it was cancelled
    (SIGTERM)."""
    task = payload["task"]
    if os.environ.get(runners.CRASH_TEST_VARIABLE) == os.path.basename(task["input"]):
        os.abort()
    t0 = time.perf_counter()

    def began(step):
        _say_to_parent(f"{runners.STEP_MARK}{time.perf_counter() - t0:.4f} {step}")

    try:
        result = _convert.convert(task, _convert.Options(**payload["options"]), on_step=began)
    except KeyboardInterrupt:
        result = runners.cancelled_report(task)
    _say_to_parent(runners.RESULT_MARK + json.dumps(report.json_safe(result)))
    return result["status"] != "cancelled"


def _say_to_parent(line):
    """Print a marked ``line`` for the parent process on a line of its own (a
    newline first: Blender's log may have left a line unfinished)."""
    print("\n" + line, flush=True)


def worker_main(payload_json):
    """A worker process (``--worker JSON``): convert one file, print its report."""
    _as_worker()
    _worker_convert(json.loads(payload_json))
    return 0


def serve_main():
    """A serving worker process (``--worker-serve``): convert the file of
    each JSON line on stdin, printing its report, until stdin ends or a
    cancel (SIGTERM)."""
    _as_worker()
    try:
        for line in iter(sys.stdin.readline, ""):
            if not _worker_convert(json.loads(line)):
                break
    except KeyboardInterrupt:          # stopped between two files
        pass
    return 0


def main(argv=None, *, entry=None, prog=PROG):
    """Run the batch; returns the exit status.

    ``entry``: how worker processes run this tool after the Python
    executable (default ``-m meshadjust.cli.batch``; the checkout's script
    passes its own path)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["--worker"]:
        return worker_main(argv[1])
    if argv == ["--worker-serve"]:
        return serve_main()
    args = parse_args(argv, prog)
    entry = MODULE_ENTRY if entry is None else entry
    t0 = time.perf_counter()
    started = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    opts, tasks, problems = _planned(args)
    if problems:
        for msg in problems:
            print(f"{prog}: {msg}", file=sys.stderr)
        return 2
    results, todo = _skipped(tasks, args.skip_existing, args.out)
    terminated = []
    try:
        with _terminate_as_interrupt(terminated):
            interrupted = _run(args, opts, entry, tasks, todo, results)
    except dask_runner.SchedulerUnreachable as exc:
        print(f"\n{prog}: --dask: {exc}", file=sys.stderr)
        return 2
    if interrupted:
        sys.stderr.write("\n")
        print(f"{prog}: interrupted; the files not finished are cancelled", file=sys.stderr)
    results = [r if r is not None else runners.cancelled_report(t)
               for r, t in zip(results, tasks)]
    print(report.summary_table(results))
    print(report.summary_line(results, args.out))
    c = report.counts(results)
    status = (143 if terminated else 130) if interrupted \
        else 1 if c["failed"] or (args.strict and c["warn"]) else 0
    if args.report:
        report.write_json(args.report, {
            "tool": prog, "started": started, "arguments": argv, "options": asdict(opts),
            "out": os.path.abspath(args.out),
            "log": os.path.abspath(args.log) if args.log else None,
            "timeout_s": args.timeout,
            "seconds": round(time.perf_counter() - t0, 3), "interrupted": interrupted,
            "exit_status": status, "counts": c, "files": [report.json_safe(r) for r in results]})
    return status


class _terminate_as_interrupt:
    """While the batch runs, SIGTERM (what ``kill``, ``timeout``, Slurm,
    systemd and ``docker stop`` send) stops it as Ctrl-C does: the workers
    stopped, the summary printed, the report written; the signal's number is
    added to ``terminated`` (the exit status is then 143, 128 + SIGTERM). It
    had killed the driver outright: no summary, no report, the worker left
    running until its next step. (Only from the main thread, where Python
    takes signals.)"""

    def __init__(self, terminated):
        self.terminated, self.previous = terminated, None

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            self.previous = signal.signal(signal.SIGTERM, self._handle)
        return self

    def _handle(self, signum, frame):
        self.terminated.append(signum)
        raise KeyboardInterrupt

    def __exit__(self, *exc):
        if self.previous is not None:
            signal.signal(signal.SIGTERM, self.previous)
        return False


def _planned(args):
    """(options, tasks, problems) of the batch: ``problems`` the messages of
    why it cannot run (paths missing, no input, an output path that is a
    folder or cannot be written), empty when it can."""
    problems = check_paths(args)
    files, unlisted = collect_inputs(args.inputs, args.out)
    if problems or unlisted:
        return None, None, problems + unlisted
    if not files:
        return None, None, ["no input files found"]
    opts = options(args)
    tasks = plan(files, opts, os.path.abspath(args.out))
    blocked = [p for t in tasks for p in (t["cage"], t["refined"]) if p and os.path.isdir(p)]
    if blocked:
        return None, None, [f"{len(blocked)} output path(s) are folders, e.g. {blocked[0]}"]
    return opts, tasks, _inputs_overwritten(tasks) or _unwritable(tasks)


def _inputs_overwritten(tasks):
    """Messages for the outputs that are inputs of the batch (``scans/*.obj
    --out scans`` with a ``scan_cage.obj`` among them: scan.obj's cage had
    replaced it before it was read, and the report described the cage as
    that input), at most 5, then how many more."""
    inputs = {os.path.realpath(t["input"]): t["name"] for t in tasks}
    found = [f"{t['name']}: its output {path} is the input {inputs[os.path.realpath(path)]}; "
             f"choose another --out folder (or rename that input)"
             for t in tasks for path in (t["cage"], t["refined"])
             if path and os.path.realpath(path) in inputs]
    return _first_five(found, "outputs that are inputs")


def _unwritable(tasks):
    """Messages for the output paths that cannot be written (a name too long
    for the file system, ...), found by trying before any compute: each
    names the input and the output path (at most 5, then how many more)."""
    found = []
    for t in tasks:
        for path in (t["cage"], t["refined"]):
            why = outputs.write_problem(path) if path else None
            if why:
                found.append(f"{t['name']}: cannot write its output {path} ({why})")
                break
    return _first_five(found, "inputs whose outputs cannot be written")


def _first_five(found, what):
    """The messages ``found``, at most five, then how many more ``what``."""
    return found[:5] + ([f"... and {len(found) - 5:,} more {what}"] if len(found) > 5 else [])


def _skipped(tasks, skip_existing, out):
    """(results, todo): the reports of the tasks skipped because their outputs
    exist (with ``skip_existing``; None for the others) and the indices of
    the tasks to run. Final names hold only whole results (``cli.outputs``);
    a file whose last run failed (its cage in ``incomplete/``) runs again,
    even beside the outputs of an earlier run, and so does one whose outputs
    the output folder's record (:data:`~.outputs.SOURCES_FILE`) does not say
    were made from this input as it is now: same-named inputs of several
    folders are numbered by their place in the run (``scan_obj_2_cage.obj``),
    and a run over other folders had taken another scan's cage for done; a
    scan exported again since had kept its old cage."""
    sources = outputs.read_sources(out) if skip_existing else {}
    results = [None] * len(tasks)
    todo = []
    for i, task in enumerate(tasks):
        outs = [p for p in (task["cage"], task["refined"]) if p]
        if skip_existing and all(os.path.isfile(p) for p in outs) and \
                not os.path.exists(outputs.incomplete_path(task["cage"])) and \
                _made_from(task["input"], outs, sources):
            results[i] = dict(runners.cancelled_report(task), status="skipped", outputs=outs)
        else:
            todo.append(i)
    return results, todo


def _made_from(path, outs, sources):
    """Whether the record ``sources`` (:func:`~.outputs.read_sources`) says
    each of the outputs ``outs`` was made from the input ``path`` as it is now."""
    stamp = outputs.source_stamp(path)
    return stamp is not None and all(sources.get(os.path.basename(p)) == stamp for p in outs)


def may_leave_parts(result):
    """Whether the worker process named in the file record ``result`` (its
    ``pid``) may have left temporary outputs of the file (``.part-<pid>-*``):
    it died, or was stopped for the time limit or by a Ctrl-C, where the
    SIGKILL after the grace period cuts its own clean-up short."""
    stopped = result["failed_step"] == "worker" or result["timed_out"] \
        or result["status"] == "cancelled"
    return stopped and result["pid"] is not None


def _run(args, opts, entry, tasks, todo, results):
    """Run the tasks ``todo`` (on Dask, worker processes or here), each
    result into ``results`` as it comes, with the progress bar and the
    per-file log; returns whether the run was interrupted."""
    log_fh = open(args.log, "w", encoding="utf-8") if args.log else None
    done = [len(tasks) - len(todo)]
    report.progress_bar(done[0], len(tasks), "")

    def on_done(k, result):
        i = todo[k]
        if may_leave_parts(result):
            outputs.remove_dead_parts(tasks[i], result["pid"])
        if result["status"] in ("ok", "warn") and result["outputs"]:
            stamp = outputs.source_stamp(tasks[i]["input"])
            outputs.record_sources(args.out, {os.path.basename(p): stamp
                                              for p in result["outputs"]})
        if log_fh is not None:
            if result.get("log"):
                log_fh.write(f"==== {result['input']} ====\n{result['log']}\n")
                log_fh.flush()
            result["log"] = None
        results[i] = result
        done[0] += 1
        report.progress_bar(done[0], len(tasks), tasks[i]["name"])

    sub = [tasks[i] for i in todo]

    def payload(task):
        return json.dumps({"task": task, "options": asdict(opts)})

    try:
        if not sub:
            return False
        if args.dask is not None:
            return dask_runner.run_dask(sub, payload, entry, args.dask, args.jobs, on_done,
                                        timeout=args.timeout)
        if args.jobs > 1:
            return runners.run_processes(sub, payload,
                                         lambda p: worker_command(entry, ["--worker", p]),
                                         args.jobs, on_done, timeout=args.timeout)
        return runners.run_serial(sub, payload,
                                  lambda: worker_command(entry, ["--worker-serve"]), on_done,
                                  timeout=args.timeout)
    finally:
        if log_fh is not None:
            log_fh.close()


def worker_command(entry, worker_args):
    """A worker's command line: this Python (or the Blender binary running
    us) with ``entry`` and ``worker_args`` (``["--worker", JSON]`` or
    ``["--worker-serve"]``)."""
    bpy = sys.modules.get("bpy")
    binary = getattr(getattr(bpy, "app", None), "binary_path", "") if bpy else ""
    if binary and os.path.basename(binary).lower().startswith("blender") and entry[:1] != ["-m"]:
        return [binary, "-b", "--factory-startup", "-P", entry[0], "--", *worker_args]
    return [sys.executable, *entry, *worker_args]


def exit_now(status):
    """Leave without the interpreter's shutdown, which bpy as a module can
    crash after everything is written; Blender's session folder
    (``bpy.app.tempdir``, a ``blender_XXXXXX`` folder of the system's
    temporary one), which that shutdown would remove, is removed here (each
    run and each of its workers left one behind)."""
    sys.stdout.flush()
    sys.stderr.flush()
    if "bpy" in sys.modules:
        session = sys.modules["bpy"].app.tempdir
        if session and os.path.basename(os.path.normpath(session)).startswith("blender_"):
            shutil.rmtree(session, ignore_errors=True)
        os._exit(status)
    sys.exit(status)


def console_main():
    """The ``meshadjust-batch`` console script."""
    exit_now(main())


if __name__ == "__main__":
    console_main()
