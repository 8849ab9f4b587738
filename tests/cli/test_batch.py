"""The batch CLI on OBJ and SMF (NumPy only, no Blender), in fresh processes:
reports, statuses, name collisions, path checks, Ctrl-C, resuming, Dask."""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

import core
from cli.blender_io import grouped_warnings
from cli.ply_file import ply_size_problem
from tests.mesh_factory import (cad_cylinder, icosphere, octahedron, out_files, shared_mesh_path,
                                tetrahedron,
                                write_binary_stl, write_ply)

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCRIPT = os.path.join(ROOT, "scripts", "meshadjust_batch.py")


def run_batch(args, tmp_path, timeout=300):
    env = dict(os.environ, HOME=str(tmp_path), BLENDER_USER_RESOURCES=str(tmp_path))
    return subprocess.run([sys.executable, SCRIPT, *map(str, args)], capture_output=True,
                          text=True, env=env, timeout=timeout, cwd=str(tmp_path))


def bumpy_sphere(level=4):
    V, F = icosphere(level)
    return V * (1 + 0.02 * np.sin(11 * V[:, :1]) * np.cos(9 * V[:, 1:2])), F


def scattered(builder, k, spacing=4.0):
    """``k`` copies of a closed mesh side by side (same size: no debris)."""
    V0, F0 = builder()
    V = np.concatenate([V0 + [spacing * i, 0, 0] for i in range(k)])
    F = np.concatenate([F0 + len(V0) * i for i in range(k)])
    return V, F



def rows(stdout):
    return [ln for ln in stdout.splitlines() if ln.startswith("| ") and "---" not in ln][1:]


def errors_beside_a_whole_file(tmp_path, bad, whole):
    """``{name: error}`` of the files ``bad`` (names in ``tmp_path``) run in a
    batch (``--faces 100 --format obj``) with the file ``whole``, a 320-face
    icosphere, last; asserted on the way: exit status 1 and no traceback,
    every bad file failed, the whole one converted and its cage the only
    output (a bad file takes no other down)."""
    proc = run_batch([*bad, whole, "--faces", "100", "--format", "obj", "--out", "out",
                      "--report", "r.json"], tmp_path)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stdout + proc.stderr
    got = {f["name"]: f for f in json.loads((tmp_path / "r.json").read_text())["files"]}
    assert [got[n]["status"] for n in bad] == ["failed"] * len(bad)
    assert got[whole]["status"] == "ok" and got[whole]["faces_in"] == 320
    assert out_files(tmp_path / "out") == [
        whole.rsplit(".", 1)[0] + "_cage.obj"]
    return {n: got[n]["error"] for n in bad}


def test_smf_in_smf_out_report_and_a_nan_reported_not_zeroed(tmp_path):
    V, F = bumpy_sphere()
    core.write_smf(tmp_path / "ball.smf", V, F)
    (tmp_path / "nan.obj").write_text("v 0 0 0\nv 1 0 0\nv nan 1 0\nv 0 0 1\n"
                                      "f 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n")
    proc = run_batch(["ball.smf", "nan.obj", "--faces", "300", "--fit", "--refine", "1",
                      "--format", "smf", "--out", "out", "--report", "rep.json"], tmp_path)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "| ball.smf | 5,120 | 300 | 300 |" in proc.stdout
    assert ("| nan.obj |" in proc.stdout and "FAILED: nan.obj: read failed: read_obj:"
            in proc.stdout and "line 3: 'v nan 1 0' has a coordinate that is not a finite number"
            in proc.stdout)
    assert "1 converted, 1 failed; output in out" in proc.stdout
    Vc, Fc = core.read_smf(tmp_path / "out" / "ball_cage.smf")
    Vr, Fr = core.read_smf(tmp_path / "out" / "ball_refined.smf")
    assert Fc.shape == (300, 3) and Fr.shape == (1200, 3)
    assert not list((tmp_path / "out").glob("nan*"))
    rep = json.loads((tmp_path / "rep.json").read_text())
    assert rep["exit_status"] == 1 and rep["counts"] == {"ok": 1, "warn": 0, "failed": 1,
                                                         "skipped": 0, "cancelled": 0}
    ball, nan = rep["files"]
    assert ball["input"] == str(tmp_path / "ball.smf") and ball["status"] == "ok"
    assert (ball["faces_in"], ball["faces_out"], ball["target_faces"]) == (5120, 300, 300)
    assert ball["stopped_because"] == "target" and ball["message"]
    assert 0 < ball["mean_deviation_pct"] <= ball["deviation_pct"] < 2
    assert ball["fit"]["mean_after_pct"] < ball["fit"]["mean_before_pct"]
    assert ball["fit"]["levels"] == 1                   # (--refine 1)
    assert list(ball["phases_s"]) == ["read", "simplify", "fit", "measure", "bind", "refine",
                                      "write"]
    assert all(t >= 0 for t in ball["phases_s"].values())
    assert ball["outputs"] == [str(tmp_path / "out" / "ball_cage.smf"),
                               str(tmp_path / "out" / "ball_refined.smf")]
    assert ball["refined_faces"] == 1200 and ball["warnings"] == []
    assert "cleaning" in ball
    assert nan["status"] == "failed" and nan["failed_step"] == "read" and nan["outputs"] == []


def test_same_named_inputs_all_survive(tmp_path):
    V, F = bumpy_sphere(3)
    (tmp_path / "a").mkdir()
    core.write_obj(tmp_path / "scan.obj", V, F)
    core.write_smf(tmp_path / "scan.smf", V * 1.5, F)
    core.write_obj(tmp_path / "a" / "scan.obj", V * 2.0, F)
    proc = run_batch(["scan.obj", "scan.smf", "a/scan.obj", "scan.obj", "--faces", "100",
                      "--format", "obj", "--out", "out"], tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert out_files(tmp_path / "out") == ["scan_obj_2_cage.obj", "scan_obj_cage.obj",
                                                   "scan_smf_cage.obj"]
    scale = {n: np.abs(core.read_obj(tmp_path / "out" / n)[0]).max()
             for n in out_files(tmp_path / "out")}
    assert scale["scan_obj_cage.obj"] < scale["scan_smf_cage.obj"] < scale["scan_obj_2_cage.obj"]
    assert len(rows(proc.stdout)) == 3          # scan.obj named twice is converted once
    assert "| a/scan.obj |" in proc.stdout and "| scan.smf |" in proc.stdout
    assert "3 converted, 0 failed" in proc.stdout


def test_out_is_checked_before_any_compute(tmp_path):
    V, F = bumpy_sphere(5)                      # 20k faces: seconds, were it computed
    core.write_obj(tmp_path / "big.obj", V, F)
    (tmp_path / "out").write_text("a file in the way\n")
    t = time.perf_counter()
    proc = run_batch(["big.obj", "--faces", "100", "--out", "out"], tmp_path)
    assert proc.returncode == 2 and "--out out is a file, not a folder" in proc.stderr
    assert proc.stdout == "" and time.perf_counter() - t < 10
    proc = run_batch(["big.obj", "--faces", "100", "--out", "o", "--report", "no/such/r.json"],
                     tmp_path)
    assert proc.returncode == 2 and "--report no/such/r.json: no folder" in proc.stderr
    assert not (tmp_path / "o" / "big_cage.obj").exists()
    (tmp_path / "o" / "big_cage.obj").mkdir()
    proc = run_batch(["big.obj", "--faces", "100", "--out", "o"], tmp_path)
    assert proc.returncode == 2 and "1 output path(s) are folders, e.g. " in proc.stderr


def test_a_folder_whose_files_cannot_be_listed_is_a_bad_path(tmp_path, monkeypatch, capsys):
    """An input folder without read permission: exit 2 naming it, before any
    compute (a raw PermissionError had ended the batch, exit 1). (Called in
    this process, os.listdir refusing the folder: the tests may run as root,
    whom permissions do not stop.)"""
    sys.path.insert(0, os.path.join(ROOT, "scripts"))
    import meshadjust_batch
    meshadjust_batch.checkout_package()
    from meshadjust.cli import batch
    (tmp_path / "scans").mkdir()
    core.write_obj(tmp_path / "ok.obj", *bumpy_sphere(3))
    listdir = os.listdir

    def refusing(path="."):
        if os.path.basename(os.path.normpath(path)) == "scans":
            raise PermissionError(13, "Permission denied", path)
        return listdir(path)
    monkeypatch.setattr(os, "listdir", refusing)
    monkeypatch.chdir(tmp_path)
    assert batch.main(["scans", "ok.obj", "--faces", "100", "--out", "out"]) == 2
    assert "scans: cannot list the folder's files (Permission denied)" in capsys.readouterr().err
    assert not os.path.exists(tmp_path / "out" / "ok_cage.obj")


def test_an_output_that_is_an_input_is_refused_before_any_compute(tmp_path):
    """``scans/*.obj --out scans`` with a ``scan_cage.obj`` among the inputs:
    scan.obj's cage had replaced it before it was read (the report then
    described the cage as that input); exit 2 naming both, nothing written."""
    (tmp_path / "scans").mkdir()
    core.write_obj(tmp_path / "scans" / "scan.obj", *bumpy_sphere(3))
    mine = tmp_path / "scans" / "scan_cage.obj"
    core.write_obj(mine, *icosphere(2))
    before = mine.read_bytes()
    proc = run_batch(["scans/scan.obj", "scans/scan_cage.obj", "--faces", "100", "--out",
                      "scans"], tmp_path)
    assert proc.returncode == 2 and proc.stdout == ""
    assert (f"scan.obj: its output {mine} is the input scan_cage.obj; choose "
            f"another --out folder (or rename that input)") in proc.stderr
    assert mine.read_bytes() == before and sorted(os.listdir(tmp_path / "scans")) == [
        "scan.obj", "scan_cage.obj"]


def test_a_file_of_the_users_named_like_an_output_is_an_input_not_overwritten(tmp_path):
    """``scans --out scans`` with a ``scan_cage.obj`` of the user's own: it
    had been left out without a word and replaced by scan.obj's cage. It is
    an input now (the folder's record does not list it as an output), so the
    run is refused naming both; the cages a run wrote there are still left
    out of the next run's inputs."""
    (tmp_path / "scans").mkdir()
    core.write_obj(tmp_path / "scans" / "scan.obj", *bumpy_sphere(3))
    mine = tmp_path / "scans" / "scan_cage.obj"
    core.write_obj(mine, *icosphere(2))
    before = mine.read_bytes()
    proc = run_batch(["scans", "--faces", "100", "--out", "scans"], tmp_path)
    assert proc.returncode == 2 and proc.stdout == ""
    assert f"scan.obj: its output {mine} is the input scan_cage.obj" in proc.stderr
    assert mine.read_bytes() == before
    mine.rename(tmp_path / "scans" / "mine.obj")
    for _ in range(2):                       # the second run: scan_cage.obj is the first's
        proc = run_batch(["scans", "--faces", "100", "--out", "scans"], tmp_path)
        assert proc.returncode == 0 and "2 converted, 0 failed" in proc.stdout, proc.stdout
    assert out_files(tmp_path / "scans") == ["mine.obj", "mine_cage.obj", "scan.obj",
                                             "scan_cage.obj"]


def test_one_row_per_file_whatever_the_error_text(tmp_path):
    bad = tmp_path / "two\nlines | pipe.obj"
    bad.write_text("v 0 0 0\nv 1 x 0\n")
    (tmp_path / "empty.smf").write_text("# no faces\nv 0 0 0\n")
    proc = run_batch([bad.name, "empty.smf", "missing.obj", "--faces", "10"], tmp_path)
    assert proc.returncode == 1
    body = rows(proc.stdout)
    assert len(body) == 3, proc.stdout
    assert body[0].startswith("| two\\nlines \\| pipe.obj |") and "is not a number" in body[0]
    assert "empty.smf: read failed: no faces in the file" in body[1]
    assert "missing.obj: read failed: no such file" in body[2]
    assert all(r.count(" | ") == 7 for r in body)   # 8 cells: no separator from the texts
    assert "0 converted, 3 failed" in proc.stdout


def test_a_binary_stl_whose_count_disagrees_with_its_size_is_named_before_blender(tmp_path):
    V, F = tetrahedron()
    write_binary_stl(tmp_path / "plus7.stl", V, F, count=11)
    write_binary_stl(tmp_path / "cut.stl", V, F)
    (tmp_path / "cut.stl").write_bytes((tmp_path / "cut.stl").read_bytes()[:-33])  # in triangle 4
    (tmp_path / "tiny.stl").write_bytes(b"\0" * 40)
    proc = run_batch(["plus7.stl", "cut.stl", "tiny.stl", "--faces", "4"], tmp_path)
    assert proc.returncode == 1
    plus7, cut, tiny = rows(proc.stdout)
    assert ("FAILED: plus7.stl: read failed: plus7.stl: the header of this binary STL file says "
            "11 triangles, but its size (284 bytes) holds 4 (84 bytes of header and count, then "
            "50 a triangle): cut short, or a wrong count |") in plus7
    assert ("cut.stl: a binary STL file of 251 bytes, which is no whole number of triangles "
            "(84 bytes of header and count, then 50 a triangle; its header says 4)") in cut
    assert "tiny.stl: 40 bytes, neither ASCII STL nor a binary STL file" in tiny
    assert "no mesh with faces" not in proc.stdout and "0 converted, 3 failed" in proc.stdout


def test_a_ply_that_cannot_hold_what_its_header_declares_is_named_before_blender(tmp_path):
    V, F = icosphere(2)                                  # 162 vertices, 320 triangles
    write_ply(tmp_path / "cut.ply", V, F, cut=100)
    write_ply(tmp_path / "faces.ply", V, F, counts=(162, 330))
    write_ply(tmp_path / "vertices.ply", V, F, counts=(172, 320))
    write_ply(tmp_path / "lines.ply", V, F, ascii=True, counts=(162, 321))
    proc = run_batch(["cut.ply", "faces.ply", "vertices.ply", "lines.ply", "--faces", "40"],
                     tmp_path)
    assert proc.returncode == 1
    cut, faces, vertices, lines = rows(proc.stdout)
    # 13 bytes a triangle: 100 bytes short leaves 312 whole ones
    assert ("cut.ply: its header declares 162 vertex and 320 face elements, but the file ends "
            "(6,177 bytes) after 312 of the 320 face elements: cut short, or a wrong count in "
            "the header |") in cut
    assert "after 320 of the 330 face elements" in faces
    # 10 vertices too many: the faces are read 120 bytes late, inside the first records
    assert ("vertices.ply: its header declares 172 vertex and 320 face elements, but the first "
            "face record (at byte 2,237) holds no valid face") in vertices
    assert ("lines.ply: its header declares 162 vertex and 321 face elements, a line each (483), "
            "but the file has 482 lines after its header") in lines
    assert "Invalid face size" not in proc.stdout and "0 converted, 4 failed" in proc.stdout


def test_ply_size_check_passes_whole_files_of_any_layout(tmp_path):
    V, F = icosphere(1)
    quads = [list(f) for f in F[:10]] + [[0, 1, 2, 3], [4, 5, 6, 7, 8]]   # mixed lengths
    write_ply(tmp_path / "mixed.ply", V, quads)
    write_ply(tmp_path / "ascii.ply", V, F, ascii=True)
    write_ply(tmp_path / "tris.ply", V, F)
    # big-endian, a vertex colour, a face flag before the list and a float after it
    head = (b"ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty float x\n"
            b"property float y\nproperty float z\nproperty uchar red\nelement face 1\n"
            b"property uchar flags\nproperty list uchar uint vertex_indices\n"
            b"property float quality\nend_header\n")
    vert = np.zeros(3, dtype=[("p", ">f4", 3), ("r", "u1")])
    face = np.zeros(1, dtype=[("fl", "u1"), ("n", "u1"), ("i", ">u4", 3), ("q", ">f4")])
    face["n"], face["i"] = 3, [0, 1, 2]
    (tmp_path / "be.ply").write_bytes(head + vert.tobytes() + face.tobytes())
    for name in ("mixed.ply", "ascii.ply", "tris.ply", "be.ply"):
        assert ply_size_problem(str(tmp_path / name)) is None, name
    (tmp_path / "be_cut.ply").write_bytes(head + vert.tobytes() + face.tobytes()[:-1])
    assert "after 0 of the 1 face elements" in ply_size_problem(str(tmp_path / "be_cut.ply"))
    # mixed lengths: walked record by record (cut 5 bytes short had been left to Blender,
    # which read the last face from past the end and said nothing)
    write_ply(tmp_path / "mixed_cut5.ply", V, quads, cut=5)
    assert ("the file ends (838 bytes) after 11 of the 12 face elements"
            in ply_size_problem(str(tmp_path / "mixed_cut5.ply")))
    write_ply(tmp_path / "mixed_cut30.ply", V, quads, cut=30)
    assert ("the file ends (813 bytes) after 10 of the 12 face elements"
            in ply_size_problem(str(tmp_path / "mixed_cut30.ply")))


def test_blender_warnings_are_grouped_by_kind():
    lines = [f"WARNING Invalid PLY vertex index in face {f} loop {k}: {f * k}"
             for f in range(100, 130) for k in range(4)] + ["WARNING something else"]
    assert grouped_warnings(lines) == [
        "WARNING Invalid PLY vertex index in face 100 loop 0: 0 (and 119 more like it)",
        "WARNING something else"]


def test_missed_target_and_unchanged_cage_warn_and_strict_fails(tmp_path):
    core.write_obj(tmp_path / "octs.obj", *scattered(octahedron, 10))      # 80 faces, floor 40
    core.write_obj(tmp_path / "tets.obj", *scattered(tetrahedron, 10))     # 40 faces, floor 40
    args = ["octs.obj", "tets.obj", "--faces", "20", "--out", "out", "--report", "r.json"]
    proc = run_batch(args, tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    octs, tets = rows(proc.stdout)
    assert "| 80 | 40 | 20 |" in octs and "| warn: target 20 missed by 100%: stopped at 40" in octs
    assert "| warn: the cage came back unchanged, no collapse possible (topology floor): " in tets
    assert "2 converted (2 with warnings), 0 failed" in proc.stdout
    rep = json.loads((tmp_path / "r.json").read_text())
    assert [f["status"] for f in rep["files"]] == ["warn", "warn"]
    first = rep["files"][0]
    assert first["warnings"][0] == "target 20 missed by 100%: " + first["message"]
    assert first["stopped_because"] == "topology_floor"
    assert (tmp_path / "out" / "octs_cage.obj").exists()       # a warning still writes
    proc = run_batch(args + ["--strict"], tmp_path)
    assert proc.returncode == 1


def test_an_unchanged_cage_of_a_mesh_exported_twice_is_said_unchanged(tmp_path):
    # the batch guessed the cleaned face count from some of the cleaning's counts: ten
    # tetrahedra exported twice in place (80 faces, the copies dropped: 40, the floor)
    # came back unchanged, said only to miss its target; simplify now says how many
    # faces the collapse started from (SimplifyResult.n_clean_faces)
    from tests.mesh_factory import duplicated
    core.write_obj(tmp_path / "twice.obj", *duplicated(*scattered(tetrahedron, 10)))
    proc = run_batch(["twice.obj", "--faces", "20", "--out", "out", "--report", "r.json"],
                     tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    f, = json.loads((tmp_path / "r.json").read_text())["files"]
    assert (f["faces_in"], f["faces_out"]) == (80, 40)
    assert f["warnings"] == ["the cage came back unchanged, no collapse possible (topology "
                             "floor): " + f["message"]]


def test_skip_existing_resumes_a_batch(tmp_path):
    for k in range(2):
        core.write_obj(tmp_path / f"s{k}.obj", *bumpy_sphere(3))
    proc = run_batch(["s0.obj", "--faces", "100", "--out", "out"], tmp_path)
    assert proc.returncode == 0
    cage = tmp_path / "out" / "s0_cage.obj"
    before = cage.stat().st_mtime_ns
    proc = run_batch(["s0.obj", "s1.obj", "--faces", "100", "--out", "out", "--skip-existing"],
                     tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    s0, s1 = rows(proc.stdout)
    assert s0.endswith("| skipped: outputs exist |") and s1.endswith("| ok |")
    assert cage.stat().st_mtime_ns == before
    assert "1 converted, 0 failed, 1 skipped" in proc.stdout
    # the output folder as the input folder: its own cages are not inputs
    proc = run_batch([".", "--faces", "100", "--out", ".", "--skip-existing"], tmp_path)
    assert proc.returncode == 0 and len(rows(proc.stdout)) == 2, proc.stdout
    proc = run_batch([".", "--faces", "100", "--out", ".", "--skip-existing"], tmp_path)
    assert proc.returncode == 0 and "0 converted, 0 failed, 2 skipped" in proc.stdout


def test_skip_existing_skips_only_outputs_made_from_the_same_input(tmp_path):
    """Same-named scans in several folders are numbered by their place in the
    run: day 1 over s1 and s2, day 2 over s2 and a new s3, and s3/scan.obj
    had been skipped for s2's cage (``scan_obj_2_cage.obj``), exit 0; a scan
    exported again since its cage was made had kept the old cage. The output
    folder records each output's input (path, size, time)."""
    for k, level in ((1, 2), (2, 3)):
        (tmp_path / f"s{k}").mkdir()
        core.write_obj(tmp_path / f"s{k}" / "scan.obj", *icosphere(level))
    args = ["--faces", "60", "--out", "out", "--skip-existing"]
    assert run_batch(["s1", "s2", *args], tmp_path).returncode == 0
    (tmp_path / "s3").mkdir()
    core.write_obj(tmp_path / "s3" / "scan.obj", *bumpy_sphere(3))
    proc = run_batch(["s2", "s3", *args], tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert [r.split(" | ")[-1] for r in rows(proc.stdout)] == ["ok |", "ok |"]   # both renumbered
    record, = (tmp_path / "out").glob(".meshadjust-sources*")
    with open(record, "a") as fh:
        fh.write('\n{"output": "scan_obj_cage.obj", "inp')             # a line cut short
    proc = run_batch(["s2", "s3", *args], tmp_path)
    assert "0 converted, 0 failed, 2 skipped" in proc.stdout
    core.write_obj(tmp_path / "s3" / "scan.obj", *bumpy_sphere(4))        # exported again
    proc = run_batch(["s2", "s3", *args], tmp_path)
    assert "1 converted, 0 failed, 1 skipped" in proc.stdout and "| s3/scan.obj | 5,120 |" \
        in proc.stdout.replace("  ", " "), proc.stdout
    proc = run_batch(["s2", "s3", *args], tmp_path)        # (its line after the cut one is whole)
    assert "0 converted, 0 failed, 2 skipped" in proc.stdout


def test_the_fit_takes_at_most_two_levels_the_refined_mesh_all_asked_for(tmp_path):
    """A fit gains nothing past two levels (``core.MAX_FIT_LEVELS``) and costs 3-4x
    more at three: ``--refine 3`` fits at two and refines at three."""
    V, F = bumpy_sphere()
    core.write_obj(tmp_path / "ball.obj", V, F)
    proc = run_batch(["ball.obj", "--faces", "80", "--fit", "--refine", "3", "--out", "out",
                      "--report", "rep.json"], tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    ball = json.loads((tmp_path / "rep.json").read_text())["files"][0]
    assert ball["fit"]["levels"] == core.MAX_FIT_LEVELS == 2
    assert ball["fit"]["mean_after_pct"] < ball["fit"]["mean_before_pct"]
    assert ball["faces_out"] == 80 and ball["refined_faces"] == 80 * 4 ** 3
    # (its detail found from a two-level binding, cli.convert.bind_for_refined): the refined
    # mesh of the unedited cage lies on the input's surface
    Vr, Fr = core.read_obj(tmp_path / "out" / "ball_refined.obj")
    assert Fr.shape == (80 * 4 ** 3, 3)
    assert core.TriangleIndex(V, F).closest(Vr).distance.max() <= 1e-6 * core.bbox_diagonal(V)


def test_fit_or_refine_failing_after_the_simplify_keeps_the_cage(tmp_path):
    """Issue 12 item 7: the cage already computed is kept (as an incomplete
    result: nothing under the final names), the file fails in the later
    step, the message names the file, what was kept and the cause."""
    core.write_obj(tmp_path / "ball.obj", *bumpy_sphere(3))
    for step, extra in (("fit_cage", ["--fit"]), ("bind", ["--refine", "1"])):
        proc = run_broken(step, ["ball.obj", "--faces", "100", "--out", step, "--report",
                                 f"{step}.json", *extra], tmp_path)
        assert proc.returncode == 1, proc.stdout + proc.stderr
        assert sorted(os.listdir(tmp_path / step)) == ["incomplete"]
        assert os.listdir(tmp_path / step / "incomplete") == ["ball_cage.obj"]
        r = json.loads((tmp_path / f"{step}.json").read_text())["files"][0]
        want = ("ball.obj: fit failed (the cage without the fit was kept as "
                "incomplete/ball_cage.obj): " if step == "fit_cage" else
                "ball.obj: bind failed (the cage was kept as incomplete/ball_cage.obj): ")
        assert r["error"] == want + "subdivision_operator: 3 non-manifold vertices"
        assert r["outputs"] == [] and r["incomplete"] == [str(tmp_path / step / "incomplete" /
                                                              "ball_cage.obj")]
        assert r["faces_out"] == 100 and r["status"] == "failed"
        assert core.read_obj(r["incomplete"][0])[1].shape == (100, 3)


BROKEN = f"""
import sys
sys.path.insert(0, {os.path.join(ROOT, 'scripts')!r})
import meshadjust_batch
pkg = meshadjust_batch.checkout_package()
from meshadjust import core
from meshadjust.cli import batch
def broken(*a, **k):
    raise core.InvalidMeshError("subdivision_operator: 3 non-manifold vertices")
setattr(core, sys.argv[1], broken)
# the workers convert: they run this script too, with the same function broken
sys.exit(batch.main(sys.argv[2:], entry=[__file__, sys.argv[1]]))
"""


def run_broken(function, args, tmp_path):
    """The batch with the core's ``function`` failing as a subdivision does
    (in the batch's process and its workers')."""
    script = tmp_path / "broken_batch.py"
    script.write_text(BROKEN)
    return subprocess.run([sys.executable, str(script), function, *map(str, args)],
                          capture_output=True, text=True, cwd=tmp_path, timeout=120)


def _start(args, tmp_path):
    # SIGINT back to its default in the child: a test run started in the background
    # of a non-interactive shell ignores SIGINT, and children inherit that (the batch
    # would then never see the Ctrl-C these tests send)
    env = dict(os.environ, HOME=str(tmp_path))
    return subprocess.Popen([sys.executable, SCRIPT, *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env, cwd=str(tmp_path),
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


@pytest.mark.parametrize("mode, sig", [(["--jobs", "2"], signal.SIGINT),
                                       (["--jobs", "1"], signal.SIGINT),
                                       (["--dask", "local", "--jobs", "2"], signal.SIGINT),
                                       (["--jobs", "2"], signal.SIGTERM),
                                       (["--jobs", "1"], signal.SIGTERM)],
                         ids=["jobs2", "serial", "dask", "jobs2-sigterm", "serial-sigterm"])
def test_ctrl_c_stops_the_workers_prints_the_summary_and_exits_130(tmp_path, mode, sig):
    """Ctrl-C, or SIGTERM (``kill``, ``timeout``, Slurm, ``docker stop``: it had
    killed the batch with no summary or report, its worker left running):
    the workers stopped, the summary printed, the report written, exit 130
    (143 for SIGTERM)."""
    if "--dask" in mode:
        pytest.importorskip("distributed", reason="dask.distributed is not installed")
    V, F = core.read_obj(shared_mesh_path("stanford-bunny.obj"))   # ~5 s each with fit + refine
    for k in range(4):
        core.write_obj(tmp_path / f"b{k}.obj", V, F)
    proc = _start([f"b{k}.obj" for k in range(4)] + ["--faces", "1000", "--fit", "--refine", "2",
                  *mode, "--out", "out", "--report", "r.json"], tmp_path)
    time.sleep(2.5)
    t = time.perf_counter()
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=60)
    status = 130 if sig == signal.SIGINT else 143
    assert proc.returncode == status, out + err
    assert time.perf_counter() - t < 15
    assert "Traceback" not in err and "interrupted" in err
    body = rows(out)
    assert len(body) == 4 and sum(r.endswith("| cancelled |") for r in body) >= 2
    assert "cancelled; output in out" in out
    rep = json.loads((tmp_path / "r.json").read_text())
    assert rep["interrupted"] and rep["exit_status"] == status
    assert not [n for n in os.listdir(tmp_path / "out") if ".part" in n]   # no half-written file
    for r in rep["files"]:
        for path in r["outputs"]:
            assert core.read_obj(path)[1].shape[0] > 0


def test_dask_local_cluster_batch_with_a_broken_file(tmp_path):
    pytest.importorskip("distributed", reason="dask.distributed is not installed "
                                              "(scripts/setup installs it into .venv)")
    for k in range(3):
        core.write_obj(tmp_path / f"s{k}.obj", *bumpy_sphere(3))
    (tmp_path / "broken.obj").write_text("v 0 0 0\nf 1 2 3\n")
    proc = run_batch([".", "--faces", "100", "--dask", "local", "--jobs", "2", "--out", "out",
                      "--report", "r.json"], tmp_path)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    body = rows(proc.stdout)
    assert [r.split(" | ")[0] for r in body] == ["| broken.obj", "| s0.obj", "| s1.obj", "| s2.obj"]
    assert "refers to a missing vertex" in body[0] and all(r.endswith("| ok |") for r in body[1:])
    assert "3 converted, 1 failed" in proc.stdout
    assert "4/4" in proc.stderr                          # the progress bar reached the end
    assert out_files(tmp_path / "out") == [f"s{k}_cage.obj" for k in range(3)]
    rep = json.loads((tmp_path / "r.json").read_text())
    assert [f["status"] for f in rep["files"]] == ["failed", "ok", "ok", "ok"]


def test_help_and_bad_arguments(tmp_path):
    proc = run_batch(["--help"], tmp_path)
    assert proc.returncode == 0
    for opt in ("--faces", "--ratio", "--max-error", "--fit", "--refine", "--scheme", "--out",
                "--format", "--jobs", "--dask", "--report", "--log", "--skip-existing",
                "--strict", "--timeout", ".smf"):
        assert opt in proc.stdout, opt
    proc = run_batch(["x.obj", "--ratio", "2"], tmp_path)
    assert proc.returncode == 2 and "--ratio" in proc.stderr
    proc = run_batch(["x.obj", "--faces", "10", "--format", "fbx"], tmp_path)
    assert proc.returncode == 2 and "--format" in proc.stderr


def test_real_meshes_through_smf_with_fit_and_refine(tmp_path):
    for name in ("cow.obj", "spot.obj"):
        V, F = core.read_obj(shared_mesh_path(name))
        core.write_smf(tmp_path / name.replace(".obj", ".smf"), V, F)
    proc = run_batch(["cow.smf", "spot.smf", shared_mesh_path("beetle.obj"), "--ratio", "0.1",
                      "--fit", "--refine", "1", "--out", "out", "--report", "r.json"], tmp_path)
    files = json.loads((tmp_path / "r.json").read_text())["files"]
    cow, spot, beetle = files
    assert (cow["faces_in"], cow["target_faces"]) == (5804, 580) and cow["status"] == "ok"
    assert (spot["faces_in"], spot["target_faces"]) == (5856, 586) and spot["status"] == "ok"
    for f in (cow, spot):
        assert abs(f["faces_out"] - f["target_faces"]) <= 1
        assert f["refined_faces"] == 4 * f["faces_out"]
        assert f["fit"]["mean_after_pct"] < f["fit"]["mean_before_pct"]
        assert len(f["outputs"]) == 2 and all(os.path.exists(p) for p in f["outputs"])
    # beetle: converted, or failed in a step after the simplify with its cage written
    assert beetle["faces_in"] == 2053 and os.path.exists(tmp_path / "out" / "beetle_cage.obj")
    assert beetle["status"] in ("ok", "warn") or beetle["failed_step"] in ("fit", "bind", "refine")
    assert proc.returncode == (1 if beetle["status"] == "failed" else 0), proc.stdout + proc.stderr


def test_dask_scheduler_and_worker_processes(tmp_path):
    """--dask ADDRESS with a scheduler and a worker in processes of their own
    that cannot import meshadjust: the task travels by value and runs the
    checkout's script through the shared path."""
    pytest.importorskip("distributed", reason="dask.distributed is not installed")
    import socket
    from distributed import Client
    dask = os.path.join(os.path.dirname(sys.executable), "dask")
    if not os.path.exists(dask):
        pytest.skip("the dask command is not installed beside this Python")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    address = f"tcp://127.0.0.1:{port}"
    env = dict(os.environ, PYTHONPATH="")          # the cluster sees no checkout on its path
    procs = [subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", str(port),
                               "--no-dashboard"], cwd=tmp_path, env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        procs.append(subprocess.Popen([dask, "worker", address, "--no-nanny", "--nthreads",
                                       "2", "--no-dashboard"], cwd=tmp_path, env=env,
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        with Client(address, timeout="30s") as client:
            client.wait_for_workers(1, timeout=60)
        core.write_obj(tmp_path / "a.obj", *bumpy_sphere(3))
        core.write_smf(tmp_path / "b.smf", *bumpy_sphere(3))
        proc = run_batch(["a.obj", "b.smf", "--faces", "100", "--dask", address, "--out", "out"],
                         tmp_path)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        assert "2 converted, 0 failed" in proc.stdout
        assert out_files(tmp_path / "out") == ["a_cage.obj", "b_cage.smf"]
    finally:
        for p in reversed(procs):
            p.terminate()
            p.wait(timeout=30)


def test_a_cage_of_slivers_is_a_warning(tmp_path):
    """A CAD cylinder's cage keeps its long thin side faces: the row warns
    (and --strict fails), naming the count and what to do."""
    core.write_obj(tmp_path / "cyl.obj", *cad_cylinder(600))
    proc = run_batch(["cyl.obj", "--faces", "200", "--out", "out", "--report", "r.json"], tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    rep = json.loads((tmp_path / "r.json").read_text())["files"][0]
    assert rep["status"] == "warn" and rep["faces_out"] == 200
    assert any(w.startswith("the cage: ") and "faces are slivers" in w for w in rep["warnings"])
    strict = run_batch(["cyl.obj", "--faces", "200", "--out", "out2", "--strict"], tmp_path)
    assert strict.returncode == 1


def test_outputs_are_named_by_their_files_and_the_run_leaves_nothing_outside_out(tmp_path):
    # found by a fuzz of the batch tool: a GLB stored its temporary file's name (so two
    # runs differed), a 240-character stem's temporary name was too long for the file
    # system, every process left Blender's session folder in the temporary folder, and
    # a link sorted before the file it points to took the file's row and outputs' names
    V, F = octahedron()
    long_stem = "n" * 240
    core.write_obj(tmp_path / f"{long_stem}.obj", V, F)
    core.write_obj(tmp_path / "zeta.obj", V, F)
    os.symlink(tmp_path / "zeta.obj", tmp_path / "a_link_to_zeta.obj")
    temp = tmp_path / "temp"
    temp.mkdir()
    outs = []
    for k in (1, 2):
        env = dict(os.environ, HOME=str(tmp_path), BLENDER_USER_RESOURCES=str(tmp_path),
                   TMPDIR=str(temp), TEMP=str(temp), TMP=str(temp))
        proc = subprocess.run([sys.executable, SCRIPT, ".", "--faces", "4", "--format", "glb",
                               "--out", f"out{k}"], capture_output=True, text=True, env=env,
                              timeout=300, cwd=str(tmp_path))
        assert proc.returncode == 0, proc.stdout + proc.stderr
        assert os.listdir(temp) == []                       # Blender's session folder removed
        names = out_files(tmp_path / f"out{k}")
        assert names == sorted([f"{long_stem}_cage.glb", "zeta_cage.glb"])   # no link's row
        outs.append({n: (tmp_path / f"out{k}" / n).read_bytes() for n in names})
    assert outs[0] == outs[1]                               # the same bytes, run after run
    assert b'"name":"zeta_cage"' in outs[0]["zeta_cage.glb"]
    assert b".part" not in outs[0]["zeta_cage.glb"]


def test_an_stl_cage_whose_split_bow_tie_would_be_joined_again_warns(tmp_path):
    """Two spheres touching at one vertex (a bow-tie): the cleaning splits it,
    so the cage has two vertices at one position, which STL (no
    connectivity) cannot keep apart: the STL output warns and says what to
    write instead; OBJ keeps them and does not warn."""
    V, F = icosphere(2)
    G = F[:, ::-1] + V.shape[0]                   # the second: reflected through V[0]
    G[G == V.shape[0]] = 0                        # and sharing vertex 0
    core.write_obj(tmp_path / "pair.obj", np.vstack([V, 2.0 * V[0] - V]), np.vstack([F, G]))
    # (near the input's 640 faces the split vertices stay where they are)
    proc = run_batch(["pair.obj", "--faces", "600", "--format", "stl", "--report", "stl.json"],
                     tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    rep = json.loads((tmp_path / "stl.json").read_text())["files"][0]
    assert rep["cleaning"]["n_split_vertices"] == 1 and rep["status"] == "warn"
    assert any(w.startswith("pair_cage.stl: 1 of its vertices share a position with another")
               and "--format obj" in w for w in rep["warnings"])
    proc = run_batch(["pair.obj", "--faces", "600", "--out", "o", "--report", "obj.json"], tmp_path)
    rep = json.loads((tmp_path / "obj.json").read_text())["files"][0]
    assert not any("share a position" in w for w in rep["warnings"])


def test_a_closing_cluster_logs_nothing_below_critical():
    """A Dask cluster's shutdown races its own messages and distributed logs
    each closed comm with a traceback: while the batch closes it, the
    ``distributed`` loggers (the parent and every child, even one with its
    own level) take only CRITICAL, and get their levels back after."""
    import logging
    from cli.dask_runner import quiet_logs
    parent, child = logging.getLogger("distributed"), logging.getLogger("distributed.batched")
    other = logging.getLogger("distributedness")
    child.setLevel(logging.INFO)
    before = (parent.level, child.level, other.level)
    with quiet_logs("distributed"):
        assert not child.isEnabledFor(logging.ERROR) and not parent.isEnabledFor(logging.ERROR)
        assert child.isEnabledFor(logging.CRITICAL)
        assert other.level == before[2]
    assert (parent.level, child.level, other.level) == before


def test_the_dask_task_travels_by_value(tmp_path):
    """The function each Dask task runs loads in a Python that cannot import
    this package (a cluster's scheduler and workers only run the tool):
    nothing of cli/ goes by reference, though it now spans two modules."""
    cloudpickle = pytest.importorskip("cloudpickle", reason="cloudpickle (with dask) is not "
                                      "installed (scripts/setup installs it into .venv)")
    from cli.dask_runner import task_function
    blob = tmp_path / "task.pickle"
    blob.write_bytes(cloudpickle.dumps(task_function()))
    probe = ("import pickle, sys\n"
             "for name in ('cli', 'meshadjust'):\n"
             "    try:\n"
             "        __import__(name)\n"
             "        sys.exit(name + ' is importable here: the probe proves nothing')\n"
             "    except ImportError:\n"
             "        pass\n"
             f"task = pickle.loads(open({str(blob)!r}, 'rb').read())\n"
             "print(task.__code__.co_names)\n")
    run = subprocess.run([sys.executable, "-I", "-c", probe], cwd=tmp_path,
                         capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr[-2000:] + run.stdout
    assert "_dask_task" in run.stdout


def test_a_symmetric_cage_off_the_bound_says_why(tmp_path):
    """A sphere holed on one side only, ``--symmetry X --max-error 0.1``: the
    mirrored cage lies 12x the bound off the input. The warning said "the bound
    holds against the input as cleaned, which the cage is 1.199% off"; now
    the simplify's own reason (turn symmetry off to meet the bound)."""
    from tests.mesh_factory import icosphere
    V, F = icosphere(3)
    centres = V[F].mean(axis=1)
    core.write_obj(tmp_path / "holed.obj", V,
                   np.delete(F, np.flatnonzero(centres[:, 0] > 0.3)[::40], axis=0))
    proc = run_batch(["holed.obj", "--max-error", "0.1", "--symmetry", "X", "--out", "out",
                      "--report", "rep.json"], tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    r = json.loads((tmp_path / "rep.json").read_text())["files"][0]
    off = [w for w in r["warnings"] if "more than the 0.1% asked" in w]
    assert len(off) == 1 and "turn symmetry off to meet the bound" in off[0], r["warnings"]
    assert "the bound holds against the input as cleaned" not in off[0]
    assert not any("came back unchanged" in w for w in r["warnings"])


def test_an_uncollapsed_symmetric_cage_is_not_said_to_be_unchanged():
    # a symmetric cage no collapse could shrink is the positive side mirrored, often more
    # faces than the input (1,268 -> 1,288): "came back unchanged" was not true
    from types import SimpleNamespace
    sys.path.insert(0, os.path.join(ROOT, "scripts"))
    import meshadjust_batch
    meshadjust_batch.checkout_package()
    from meshadjust.cli import convert
    for asymmetry, want in ((None, "the cage came back unchanged, no collapse possible"),
                            (0.0, "the cage is the input's positive side mirrored, no collapse "
                                  "possible")):
        res = SimpleNamespace(n_clean_faces=1268, stopped_because="max_error", message="m",
                              asymmetry=asymmetry)
        r = {"faces_out": 1288, "target_faces": None, "warnings": []}
        convert._check_target(r, res)
        assert r["warnings"] == [f"{want} (max error): m"]
