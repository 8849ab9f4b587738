"""A serial batch (``--jobs 1``) converts every file in one long-lived worker
process: a crash of that worker (an importer's segmentation fault, the OOM
killer on a scan too large for the memory) fails the file it was converting,
and a new worker takes the rest. Until 2026-12-05 23:45 OBJ and SMF were
converted in the batch's own process, where such a crash ended the batch.
The crash is real: a worker aborts (SIGABRT) on the file named by
``batch.CRASH_TEST_VARIABLE``."""

import json
import os
import select
import signal
import subprocess
import sys
import time

import pytest

import core
from cli.runners import CRASH_TEST_VARIABLE, RESULT_MARK
from tests.cli.test_batch import ROOT, rows, SCRIPT
from tests.mesh_factory import icosphere, out_files, shared_mesh_path, write_binary_stl, write_ply


def _batch(args, tmp_path, **env):
    """The batch in a process of its own: ``(its pid, CompletedProcess)``."""
    env = dict(os.environ, HOME=str(tmp_path), BLENDER_USER_RESOURCES=str(tmp_path), **env)
    proc = subprocess.Popen([sys.executable, SCRIPT, *map(str, args)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env, cwd=str(tmp_path))
    out, err = proc.communicate(timeout=300)
    return proc.pid, subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


def _report(tmp_path):
    return json.loads((tmp_path / "r.json").read_text())


def test_a_worker_crash_fails_its_file_and_a_new_worker_takes_the_rest(tmp_path):
    """An importer crash the file checks do not foresee ended the whole serial
    batch: no row, no report, no file after it converted."""
    V, F = icosphere(2)
    names = [f"s{k}.ply" for k in range(5)]
    for k, name in enumerate(names):
        write_ply(tmp_path / name, V * (1 + 0.1 * k), F)
    _, proc = _batch([*names, "--faces", "100", "--out", "out", "--report", "r.json",
                      "--log", "blender.log"], tmp_path, **{CRASH_TEST_VARIABLE: "s2.ply"})
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stdout + proc.stderr
    body = rows(proc.stdout)
    assert len(body) == 5
    assert body[2] == ("| s2.ply |  |  |  |  |  |  | FAILED: s2.ply: the worker process died "
                       "(killed by SIGABRT) |")
    assert "4 converted, 1 failed; output in out" in proc.stdout
    assert "5/5" in proc.stderr                          # the progress bar reached the end
    rep = _report(tmp_path)
    assert rep["exit_status"] == 1 and not rep["interrupted"]
    assert rep["counts"] == {"ok": 4, "warn": 0, "failed": 1, "skipped": 0, "cancelled": 0}
    files = rep["files"]
    assert [f["name"] for f in files] == names
    assert [f["status"] for f in files] == ["ok", "ok", "failed", "ok", "ok"]
    crashed = files[2]
    assert crashed["failed_step"] == "worker" and crashed["outputs"] == []
    assert crashed["error"] == "s2.ply: the worker process died (killed by SIGABRT)"
    for f in files[:2] + files[3:]:
        assert f["faces_in"] == 320 and f["faces_out"] == 100
        assert f["outputs"] == [str(tmp_path / "out" / f["name"].replace(".ply", "_cage.ply"))]
    assert out_files(tmp_path / "out") == ["s0_cage.ply", "s1_cage.ply",
                                                    "s3_cage.ply", "s4_cage.ply"]
    # the files before the crash and the crashed one in one worker, the rest in another
    pids = [f["pid"] for f in files]
    assert pids[0] == pids[1] == pids[2] != pids[3] == pids[4]
    log = (tmp_path / "blender.log").read_text()        # Blender's log of the four, one each
    assert [ln for ln in log.splitlines() if ln.startswith("==== ")] == [
        f"==== {tmp_path / n} ====" for n in names if n != "s2.ply"]


def test_a_serial_batch_converts_every_file_in_one_worker(tmp_path):
    """One worker process for all the files (it was the batch's own process
    for all of them, then for OBJ and SMF: a crash there ended the batch),
    not one per file (each would import bpy again)."""
    V, F = icosphere(2)
    write_ply(tmp_path / "a.ply", V, F)
    write_binary_stl(tmp_path / "b.stl", V, F)
    core.write_obj(tmp_path / "c.obj", V, F)
    write_ply(tmp_path / "d.ply", V, F, ascii=True)
    core.write_smf(tmp_path / "e.smf", V, F)
    pid, proc = _batch([".", "--faces", "100", "--out", "out", "--report", "r.json"], tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    files = _report(tmp_path)["files"]
    assert [f["name"] for f in files] == ["a.ply", "b.stl", "c.obj", "d.ply", "e.smf"]
    assert [f["status"] for f in files] == ["ok"] * 5
    assert len({f["pid"] for f in files}) == 1 and files[0]["pid"] != pid
    # an OBJ written as PLY goes through Blender's exporter
    _, proc = _batch(["c.obj", "--faces", "100", "--format", "ply", "--out", "out2",
                      "--report", "r.json"], tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    (obj_as_ply,) = _report(tmp_path)["files"]
    assert obj_as_ply["status"] == "ok"
    assert out_files(tmp_path / "out2") == ["c_cage.ply"]


def test_an_obj_file_that_crashes_its_worker_fails_alone(tmp_path):
    """An OBJ whose conversion ends the process (a native crash, the OOM
    killer) ended the whole serial batch, converted in the batch's own
    process: no row, no report, no later file."""
    V, F = icosphere(2)
    core.write_obj(tmp_path / "a.obj", V, F)
    core.write_obj(tmp_path / "b.obj", V * 2, F)
    core.write_smf(tmp_path / "c.smf", V * 3, F)
    _, proc = _batch([".", "--faces", "100", "--out", "out", "--report", "r.json"], tmp_path,
                     **{CRASH_TEST_VARIABLE: "b.obj"})
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stdout + proc.stderr
    assert rows(proc.stdout)[1] == ("| b.obj |  |  |  |  |  |  | FAILED: b.obj: the worker "
                                    "process died (killed by SIGABRT) |")
    assert "2 converted, 1 failed; output in out" in proc.stdout
    a, b, c = _report(tmp_path)["files"]
    assert [a["status"], b["status"], c["status"]] == ["ok", "failed", "ok"]
    assert b["failed_step"] == "worker" and b["outputs"] == [] and not b["timed_out"]
    assert a["pid"] == b["pid"] != c["pid"]             # a new worker after the crash
    assert out_files(tmp_path / "out") == ["a_cage.obj", "c_cage.smf"]


def _maps_bpy(pid):
    """Whether process ``pid`` has Blender's module (``bpy/__init__.so`` and
    its libraries) mapped."""
    with open(f"/proc/{pid}/maps") as fh:
        return any(f"{os.sep}bpy{os.sep}" in line for line in fh)


def _serve(worker, tmp_path, name):
    """Send the serving ``worker`` the file ``name`` (in ``tmp_path``) and
    return its report."""
    task = {"input": str(tmp_path / name), "name": name, "refined": None,
            "cage": str(tmp_path / "out" / name.replace(".", "_cage."))}
    worker.stdin.write(json.dumps({"task": task, "options": {"faces": 100}}) + "\n")
    worker.stdin.flush()
    for line in iter(worker.stdout.readline, ""):
        if line.startswith(RESULT_MARK):
            return json.loads(line[len(RESULT_MARK):])
    raise AssertionError(f"the worker ended before it reported {name}")


@pytest.mark.skipif(not os.path.exists("/proc/self/maps"), reason="needs /proc (Linux)")
def test_a_worker_imports_blender_only_for_a_file_that_needs_it(tmp_path):
    """Every file of a serial batch goes through its serving worker: one
    that only meets OBJ and SMF must not pay for Blender (bpy's import, its
    memory), which it meets first with a PLY."""
    pytest.importorskip("bpy")
    V, F = icosphere(2)
    core.write_obj(tmp_path / "a.obj", V, F)
    core.write_smf(tmp_path / "b.smf", V, F)
    write_ply(tmp_path / "c.ply", V, F)
    env = dict(os.environ, HOME=str(tmp_path), BLENDER_USER_RESOURCES=str(tmp_path))
    worker = subprocess.Popen([sys.executable, SCRIPT, "--worker-serve"], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                              env=env, cwd=str(tmp_path))
    try:
        assert _serve(worker, tmp_path, "a.obj")["status"] == "ok"
        assert _serve(worker, tmp_path, "b.smf")["status"] == "ok"
        assert not _maps_bpy(worker.pid)
        assert _serve(worker, tmp_path, "c.ply")["status"] == "ok"
        assert _maps_bpy(worker.pid)                 # (the check sees Blender when it is there)
    finally:
        worker.stdin.close()
        worker.wait(timeout=60)


def _stderr_until(proc, text, timeout=240):
    """Read the batch's stderr until ``text`` appears in it; returns what was read."""
    seen, fd = "", proc.stderr.fileno()
    while text not in seen:
        ready, _, _ = select.select([fd], [], [], timeout)
        chunk = os.read(fd, 4096).decode() if ready else ""
        if not chunk:
            raise AssertionError(f"the batch's stderr ended or stalled before {text!r}: {seen}")
        seen += chunk
    return seen


def test_ctrl_c_in_a_serial_batch_stops_its_worker_and_the_batch_resumes(tmp_path):
    """Ctrl-C while the serving worker converts a file: that file cancelled
    and its temporary output removed, the files after it cancelled, the
    worker gone; ``--skip-existing`` then converts what is left."""
    V, F = icosphere(2)
    write_ply(tmp_path / "a.ply", V, F)
    V, F = core.read_obj(shared_mesh_path("stanford-bunny.obj"))   # seconds each, fitted
    for k in range(2):
        write_ply(tmp_path / f"b{k}.ply", V, F)
    args = [".", "--faces", "1000", "--fit", "--refine", "1", "--out", "out",
            "--report", "r.json"]
    # SIGINT at its default in the child (see test_batch._start)
    proc = subprocess.Popen([sys.executable, SCRIPT, *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env=dict(os.environ, HOME=str(tmp_path)),
                            cwd=str(tmp_path),
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    seen = _stderr_until(proc, "1/3 a.ply")             # a.ply done, b0.ply next
    # (b0.ply takes seconds: a moment for the driver to hand it to the worker, else the
    # Ctrl-C would come between two files, where b0.ply is cancelled before it starts)
    time.sleep(0.5)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    out, err = out.decode(), seen + err.decode()
    assert proc.returncode == 130, out + err
    assert "Traceback" not in err and "interrupted" in err
    assert [r.rsplit(" | ", 1)[1] for r in rows(out)] == ["ok |", "cancelled |", "cancelled |"]
    rep = _report(tmp_path)
    assert rep["interrupted"] and rep["exit_status"] == 130
    assert [f["status"] for f in rep["files"]] == ["ok", "cancelled", "cancelled"]
    assert rep["files"][1]["pid"] == rep["files"][0]["pid"]      # stopped in the worker
    with pytest.raises(ProcessLookupError):                       # and the worker is gone
        os.kill(rep["files"][0]["pid"], 0)
    assert out_files(tmp_path / "out") == ["a_cage.ply", "a_refined.ply"]
    _, again = _batch([*args[:1], "--faces", "100", "--out", "out", "--report", "r.json",
                       "--skip-existing", "--refine", "1"], tmp_path)
    assert again.returncode == 0, again.stdout + again.stderr
    assert [f["status"] for f in _report(tmp_path)["files"]] == ["skipped", "ok", "ok"]


def test_the_temporary_outputs_a_dead_worker_left_are_removed(tmp_path):
    """A worker that dies in the middle of a write (an exporter's crash, a
    SIGKILL) leaves its ``.part-<pid>-<k>`` files: the rename and its own
    clean-up never come. The batch removes those of the file that failed,
    by the dead worker's pid, and nothing else."""
    sys.path.insert(0, os.path.join(ROOT, "scripts"))
    import meshadjust_batch
    meshadjust_batch.checkout_package()
    from meshadjust.cli import outputs
    task = {"cage": str(tmp_path / "s_cage.ply"), "refined": str(tmp_path / "s_refined.ply")}
    dead, other = 4_000_001, 4_000_002
    left = [outputs.part_path(task["cage"], 0, dead), outputs.part_path(task["refined"], 1, dead),
            outputs.part_path(outputs.incomplete_path(task["cage"]), 0, dead)]
    kept = [outputs.part_path(task["cage"], 0, other), str(tmp_path / "s_cage.ply")]
    os.makedirs(os.path.dirname(left[2]))
    for path in left + kept:
        open(path, "wb").close()
    assert [os.path.basename(p) for p in left] == [".part-4000001-0.ply", ".part-4000001-1.ply",
                                                   ".part-4000001-0.ply"]
    outputs.remove_dead_parts(task, dead)
    assert [os.path.exists(p) for p in left + kept] == [False, False, False, True, True]


def test_the_parts_of_a_stopped_file_are_looked_for():
    """The records whose worker may have left temporary outputs: one that
    died, one stopped for its time limit, and one stopped by a Ctrl-C (a
    SIGKILL after the grace period leaves its parts as a crash does); never
    a converted file, nor a file no worker started (no pid)."""
    sys.path.insert(0, os.path.join(ROOT, "scripts"))
    import meshadjust_batch
    meshadjust_batch.checkout_package()
    from meshadjust.cli import batch, runners
    task = {"input": "in/s.obj", "name": "s.obj"}
    died = dict(runners.failed_report(task, "the worker process died (killed by SIGKILL)"), pid=7)
    slow = runners.file_report(task, "failed", timed_out=True, failed_step="fit", pid=7)
    cancelled = dict(runners.cancelled_report(task), pid=7)
    converted = runners.file_report(task, "ok", pid=7)
    unstarted = runners.cancelled_report(task)
    assert [batch.may_leave_parts(r) for r in (died, slow, cancelled, converted, unstarted)] \
        == [True, True, True, False, False]


_FAULTS = r"""
import resource, sys
import numpy as np
sys.path.insert(0, sys.argv[1])
from meshadjust_batch import checkout_package
checkout_package()
from meshadjust.cli.batch import reuse_freed_memory
try:                                  # (4 KB pages: each fresh one a fault to count)
    from numpy._core.multiarray import _set_madvise_hugepage
except ImportError:
    from numpy.core.multiarray import _set_madvise_hugepage
_set_madvise_hugepage(False)


def faults():
    np.ones(8_000_000)                # 64 MB made and dropped, then again 5 times
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(5):
        np.ones(8_000_000)
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before


print(faults(), reuse_freed_memory(), faults())
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's malloc (Linux)")
def test_a_worker_reuses_the_memory_it_freed():
    # a worker process (reuse_freed_memory, from _as_worker) keeps large blocks it frees
    # for the next ones: a 64 MB array made again and again pages in once, not each time
    # (each fresh page a fault; 16k of them per 64 MB)
    proc = subprocess.run([sys.executable, "-c", _FAULTS, os.path.join(ROOT, "scripts")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    fresh, applied, reused = proc.stdout.split()
    assert applied == "True"
    # (4 KB pages here: 78k faults fresh; where the kernel backs them with huge pages
    # anyway, far fewer, so the test asks for a tenth, not a count)
    assert int(reused) < 1_000 and 10 * int(reused) < int(fresh), proc.stdout
