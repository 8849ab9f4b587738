"""``--timeout SECONDS``: a file still converting after its limit is stopped
as Ctrl-C stops a worker, fails timed out in the step it was in, leaves no
output, and the batch goes on with the next file (a serial batch in a new
serving worker). The slow input is real: a 327,680-face icosphere, whose
read, simplify to 100 faces and measure take about 9 s here (read 0.5-0.8 s,
simplify 4 s), against a limit of 1.5 s; the small files convert in about
0.2 s. (Before --timeout one such file held a batch for as long as it took.)"""

import json
import os

import pytest

import core
from cli import runners
from tests.cli.test_batch import rows, run_batch
from tests.mesh_factory import icosphere, out_files

LIMIT = "1.5"
#: the steps of a file converted without --fit or --refine, in order
STEPS = ["read", "simplify", "measure", "write"]


@pytest.fixture(scope="module")
def slow_obj(tmp_path_factory):
    path = tmp_path_factory.mktemp("slow") / "b_slow.obj"
    core.write_obj(path, *icosphere(7))
    return path


def _small(tmp_path, name, scale=1.0):
    V, F = icosphere(1)
    core.write_obj(tmp_path / name, V * scale, F)


@pytest.mark.parametrize("mode", [[], ["--jobs", "2"], ["--dask", "local", "--jobs", "2"]],
                         ids=["serial", "jobs2", "dask"])
def test_a_file_past_its_time_limit_fails_timed_out_and_the_batch_goes_on(tmp_path, slow_obj,
                                                                          mode):
    if "--dask" in mode:
        pytest.importorskip("distributed", reason="dask.distributed is not installed")
    _small(tmp_path, "a_small.obj")
    _small(tmp_path, "c_small.obj", 2.0)
    proc = run_batch(["a_small.obj", slow_obj, "c_small.obj", "--faces", "20", "--timeout",
                      LIMIT, *mode, "--out", "out", "--report", "r.json"], tmp_path)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stdout + proc.stderr
    rep = json.loads((tmp_path / "r.json").read_text())
    assert rep["exit_status"] == 1 and rep["timeout_s"] == 1.5
    assert rep["counts"] == {"ok": 2, "warn": 0, "failed": 1, "skipped": 0, "cancelled": 0}
    a, b, c = rep["files"]
    assert [a["status"], b["status"], c["status"]] == ["ok", "failed", "ok"]
    assert sorted(a) == sorted(b) == sorted(c)                   # every record, every key
    assert not a["timed_out"] and not c["timed_out"] and b["timed_out"]
    # the step it was in, and the time of the steps it finished before it
    step = b["failed_step"]
    assert step in STEPS[:3], b
    assert list(b["phases_s"]) == STEPS[:STEPS.index(step)]
    assert b["error"] == f"b_slow.obj: timed out after 1.5 s (--timeout), in the {step} step"
    assert b["seconds"] >= 1.5 and b["faces_in"] is None
    assert b["outputs"] == [] and b["incomplete"] == []
    body = rows(proc.stdout)
    assert body[1].endswith(f"| FAILED: {b['error']} |")
    assert "2 converted, 1 failed; output in out" in proc.stdout
    # nothing left of it in the output folder: no cage, no temporary part, no incomplete/
    assert out_files(tmp_path / "out") == ["a_small_cage.obj", "c_small_cage.obj"]
    for f in (a, c):
        assert f["faces_in"] == 80 and f["faces_out"] == 20
        assert core.read_obj(f["outputs"][0])[1].shape == (20, 3)
    with pytest.raises(ProcessLookupError):                 # its worker is gone
        os.kill(b["pid"], 0)
    if not mode:          # one serving worker for a and b, a new one after b was stopped
        assert a["pid"] == b["pid"] != c["pid"]


def test_a_generous_limit_changes_nothing(tmp_path):
    """Files well within the limit: the same outputs, byte for byte, and the
    same records but for their times and processes, as without --timeout."""
    _small(tmp_path, "a.obj")
    _small(tmp_path, "b.obj", 2.0)
    records = {}
    for out, extra in (("plain", []), ("limited", ["--timeout", "600"])):
        proc = run_batch(["a.obj", "b.obj", "--faces", "20", "--out", out, "--report",
                          f"{out}.json", *extra], tmp_path)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        records[out] = json.loads((tmp_path / f"{out}.json").read_text())
    assert records["plain"]["timeout_s"] is None and records["limited"]["timeout_s"] == 600
    for plain, limited in zip(records["plain"]["files"], records["limited"]["files"]):
        assert limited["status"] == "ok" and not limited["timed_out"]
        for key in ("seconds", "phases_s", "pid", "outputs"):
            plain.pop(key), limited.pop(key)
        assert plain == limited
    for name in ("a_cage.obj", "b_cage.obj"):
        limited_bytes = (tmp_path / "limited" / name).read_bytes()
        assert limited_bytes == (tmp_path / "plain" / name).read_bytes()


def test_a_timed_out_record_names_the_step_and_times_the_steps_before_it():
    """The driver's record of a file stopped for the timeout, from the step
    marks its worker printed (a worker's cancel report is not the file's)."""
    task = {"input": "/scans/x.obj", "name": "x.obj"}
    text = (f"{runners.STEP_MARK}0.0010 read\nBlender says hi\n{runners.STEP_MARK}0.5010 simplify\n"
            f"{runners.STEP_MARK}2.0010 fit\n"
            f'{runners.RESULT_MARK}{json.dumps(runners.cancelled_report(task))}\n')
    r = runners.worker_report(task, text, 0, 42, timed_out=(2.5, 2.6))
    assert r == runners.file_report(
        task, "failed", failed_step="fit", timed_out=True, pid=42, seconds=2.6,
        error="x.obj: timed out after 2.5 s (--timeout), in the fit step",
        phases_s={"read": 0.5, "simplify": 1.5}, log="Blender says hi")
    # a worker that finished the file before it saw the stop: its own report holds
    done = runners.file_report(task, "ok", faces_in=8)
    assert runners.worker_report(task, f"{runners.RESULT_MARK}{json.dumps(done)}\n", 0, 42,
                                 timed_out=(2.5, 2.6)) == dict(done, pid=42)
    # a worker that never began the file
    r = runners.worker_report(task, "", -9, 42, timed_out=(2.5, 62.6))
    assert r["failed_step"] == "worker" and r["phases_s"] == {} and r["timed_out"]
    assert r["error"] == ("x.obj: timed out: the worker process had not begun the file 63 s "
                          "after it was handed it (--timeout 2.5 s counts from the file's first "
                          "step, after up to 60 s for a worker to start)")


def test_a_worker_that_died_says_in_which_step_and_suspects_memory_for_sigkill():
    task = {"input": "/scans/x.obj", "name": "x.obj"}
    text = f"{runners.STEP_MARK}0.0010 read\n{runners.STEP_MARK}0.5010 simplify\n"
    r = runners.worker_report(task, text, -9, 42)
    assert r["error"] == ("x.obj: the worker process died (killed by SIGKILL: out of memory? the "
                          "kernel's OOM killer sends it) in the simplify step")
    assert r["failed_step"] == "worker" and not r["timed_out"] and r["log"] == ""
    r = runners.worker_report(task, "half a line\n" + text + "Fatal Python error\n", -6, 42)
    assert r["error"] == ("x.obj: the worker process died (killed by SIGABRT) in the simplify "
                          "step: half a line | Fatal Python error")
