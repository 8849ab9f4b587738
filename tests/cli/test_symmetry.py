"""The batch CLI's --symmetry: a mirror-symmetric cage, kept so by --fit."""

import json
import os

import numpy as np

import core
from core.mirror import mirror_partners
from tests.cli.test_batch import bumpy_sphere, run_batch
from tests.mesh_factory import out_files


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


def test_symmetry_of_an_input_off_its_mirror_plane_is_refused(tmp_path):
    """An input whose sides differ by more than the core's ASYMMETRY_NOTE (5%)
    gets no symmetric cage: the cage would lie between the sides and its
    refinement fold into near-zero faces (1e-15 of the median's area, 6 of
    them, for this ball 0.5 off its plane). The file fails naming the
    measured asymmetry; the cage is kept as incomplete, nothing refined."""
    V, F = bumpy_sphere(3)
    V = V * (1 + 0.05 * np.cos(7 * V[:, 1:2]))
    core.write_obj(tmp_path / "off.obj", V + [0.3, 0.0, 0.0], F)    # its plane is X = 0.3
    core.write_obj(tmp_path / "near.obj", V + [0.02, 0.0, 0.0], F)  # 1.4% apart: taken
    proc = run_batch(["off.obj", "near.obj", "--faces", "200", "--symmetry", "X", "--refine",
                      "2", "--out", "out", "--report", "rep.json"], tmp_path)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    off, near = json.loads((tmp_path / "rep.json").read_text())["files"]
    assert off["status"] == "failed" and off["failed_step"] == "symmetry"
    assert off["error"] == (
        "off.obj: symmetry failed (the symmetric cage was kept as incomplete/off_cage.obj): the "
        "input is not mirror-symmetric about the plane X = 0: its two sides differ by up to "
        "15.6% of its size (a symmetric cage takes at most 5%; beyond, it lies between them and "
        "its refinement folds into near-zero faces): center it on its mirror plane, or leave "
        "out --symmetry")
    assert off["outputs"] == [] and off["refined_faces"] is None
    assert near["status"] == "ok" and near["refined_faces"] == 16 * near["faces_out"]
    assert out_files(tmp_path / "out") == ["incomplete", "near_cage.obj",
                                                    "near_refined.obj"]
    assert os.listdir(tmp_path / "out" / "incomplete") == ["off_cage.obj"]
