"""The batch CLI's --max-dihedral: the cage stops before collapses bend it
further, and the row and the report say so."""

import json

import core
from tests.cli.test_batch import bumpy_sphere, rows, run_batch


def test_max_dihedral_stops_early_and_says_why(tmp_path):
    V, F = bumpy_sphere(4)
    core.write_obj(tmp_path / "ball.obj", V, F)
    proc = run_batch(["ball.obj", "--faces", "100", "--max-dihedral", "20", "--out", "out",
                      "--report", "rep.json"], tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    rep = json.loads((tmp_path / "rep.json").read_text())
    ball = rep["files"][0]
    assert ball["stopped_because"] == "max_dihedral"
    assert ball["faces_out"] > 100 and "dihedral" in ball["message"]
    assert ball["status"] == "warn" and any("dihedral" in w for w in ball["warnings"])
    Vc, Fc = core.read_obj(tmp_path / "out" / "ball_cage.obj")
    assert Fc.shape[0] == ball["faces_out"]
    assert len(rows(proc.stdout)) == 1
    for bad in ("0", "180", "-3"):
        proc = run_batch(["ball.obj", "--faces", "100", "--max-dihedral", bad], tmp_path)
        assert proc.returncode == 2 and "--max-dihedral" in proc.stderr
