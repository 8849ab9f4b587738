"""Every file's record in the JSON report has the same keys, whatever its
status (found by a fuzz of the batch CLI on 2026-12-05, second campaign)."""

import json

import core
from tests.cli.test_batch import run_batch
from tests.mesh_factory import icosphere


def test_skipped_failed_and_converted_files_have_the_same_fields(tmp_path):
    """A file skipped by --skip-existing (or cancelled, or whose worker
    died) had a record of 8 keys, no 'faces_in', 'error' or 'seconds': a
    pipeline reading files[i]['faces_in'] of a resumed batch met a
    KeyError."""
    V, F = icosphere(2)
    core.write_obj(tmp_path / "ball.obj", V, F)
    core.write_obj(tmp_path / "other.obj", V * 2, F)
    (tmp_path / "bad.obj").write_text("v 0 0 0\nf 1 2 3\n")
    run_batch(["ball.obj", "--faces", "100", "--out", "out"], tmp_path)
    proc = run_batch(["ball.obj", "other.obj", "bad.obj", "--faces", "100", "--out", "out",
                      "--skip-existing", "--report", "r.json"], tmp_path)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    report = json.loads((tmp_path / "r.json").read_text())
    ball, other, bad = report["files"]
    assert [ball["status"], other["status"], bad["status"]] == ["skipped", "ok", "failed"]
    assert sorted(ball) == sorted(other) == sorted(bad)
    assert ball["faces_in"] is None and ball["error"] is None and ball["incomplete"] == []
    assert ball["outputs"] == [str(tmp_path / "out" / "ball_cage.obj")]
    assert other["faces_in"] == 320 and other["faces_out"] == 100
    assert bad["failed_step"] == "read" and "refers to a missing vertex" in bad["error"]
    assert report["counts"] == {"ok": 1, "warn": 0, "failed": 1, "skipped": 1, "cancelled": 0}


def test_a_named_pipe_named_like_a_mesh_is_no_regular_file_not_a_missing_one(tmp_path):
    """A FIFO (or a link to /dev/zero) named scan.obj in a folder was
    reported 'no such file', though it is right there."""
    import os
    os.mkfifo(tmp_path / "pipe.obj")
    os.symlink("/dev/zero", tmp_path / "zero.stl")
    proc = run_batch([".", "--faces", "100", "--out", "out", "--report", "r.json"], tmp_path)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    pipe, zero = json.loads((tmp_path / "r.json").read_text())["files"]
    for r, name in ((pipe, "pipe.obj"), (zero, "zero.stl")):
        assert r["error"] == (f"{name}: read failed: not a regular file (a named pipe, a device "
                              f"or a socket): {tmp_path / name}")


def test_a_missing_input_given_with_a_trailing_slash_keeps_its_name(tmp_path):
    """'scans/' that does not exist was shown with an empty name ('| | ... |
    FAILED: : read failed: no such file') and planned outputs '_cage.obj'."""
    V, F = icosphere(1)
    core.write_obj(tmp_path / "ball.obj", V, F)
    proc = run_batch(["scans/", "ball.obj/", "--faces", "20", "--out", "out", "--report",
                      "r.json"], tmp_path)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    scans, ball = json.loads((tmp_path / "r.json").read_text())["files"]
    assert scans["name"] == "scans" and scans["error"] == (
        f"scans: read failed: no such file: {tmp_path / 'scans'}")
    assert ball["name"] == "ball.obj" and ball["status"] == "ok"
    assert ball["outputs"] == [str(tmp_path / "out" / "ball_cage.obj")]


def test_the_summary_table_says_a_small_deviation_with_its_digits():
    """The table's deviation is said as the add-on says it (``core.percent``):
    a CAD cage 8e-6 of the size off had read 0.000 in the column."""
    import os
    import sys
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(
        os.path.abspath(__file__)))), "scripts"))
    import meshadjust_batch
    meshadjust_batch.checkout_package()
    from meshadjust.cli import report
    rows = report.summary_table([
        {"name": "cad.stl", "status": "ok", "faces_in": 10_000, "faces_out": 2_000,
         "deviation_pct": 0.00079, "seconds": 1.0},
        {"name": "scan.ply", "status": "ok", "faces_in": 252_000, "faces_out": 1_500,
         "deviation_pct": 0.65, "seconds": 2.0},
        {"name": "soup.stl", "status": "warn", "warnings": ["a soup"], "deviation_pct": None}])
    cells = [[c.strip() for c in line.split("|")[1:-1]] for line in rows.splitlines()[2:]]
    assert [c[4] for c in cells] == ["0.00079%", "0.65%", ""]
    assert rows.splitlines()[0].split("|")[5].strip() == "max deviation"
