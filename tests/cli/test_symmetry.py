"""The batch CLI's --symmetry: a mirror-symmetric cage, kept so by --fit."""

import json

import numpy as np

import core
from core.mirror import mirror_partners
from tests.cli.test_batch import bumpy_sphere, run_batch


def test_symmetry_option_writes_a_mirror_symmetric_fitted_cage(tmp_path):
    V, F = bumpy_sphere(3)
    V = V * (1 + 0.05 * np.cos(7 * V[:, 1:2]))       # even in x: symmetric about X = 0
    core.write_obj(tmp_path / "ball.obj", V, F)
    proc = run_batch(["ball.obj", "--faces", "200", "--fit", "--symmetry", "X", "--out", "out",
                      "--report", "rep.json"], tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    Vc, Fc = core.read_obj(tmp_path / "out" / "ball_cage.obj")
    assert Fc.shape[0] <= 200
    p = mirror_partners(Vc, "X", tolerance=1e-6)       # as written to the file (text precision)
    assert np.all(Vc[p == np.arange(Vc.shape[0]), 0] == 0.0)
    assert '"symmetry": "X"' in (tmp_path / "rep.json").read_text()
    bad = run_batch(["ball.obj", "--faces", "200", "--symmetry", "W"], tmp_path)
    assert bad.returncode == 2 and "--symmetry" in bad.stderr



def test_symmetry_of_an_input_off_its_mirror_plane_is_a_warning(tmp_path):
    V, F = bumpy_sphere(3)
    V = V * (1 + 0.05 * np.cos(7 * V[:, 1:2])) + [0.3, 0.0, 0.0]   # its plane is X = 0.3
    core.write_obj(tmp_path / "ball.obj", V, F)
    proc = run_batch(["ball.obj", "--faces", "200", "--symmetry", "X", "--out", "out",
                      "--report", "rep.json"], tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    rep = json.loads((tmp_path / "rep.json").read_text())
    f, = rep["files"]
    assert f["status"] == "warn"
    assert any("not mirror-symmetric about the plane" in w for w in f["warnings"]), f["warnings"]
    strict = run_batch(["ball.obj", "--faces", "200", "--symmetry", "X", "--out", "out2",
                        "--strict"], tmp_path)
    assert strict.returncode == 1
