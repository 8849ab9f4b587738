"""glTF in the file's own (Y-up) coordinates: a cage written as OBJ lies
where the glTF's mesh lies, a GLB cage holds the same numbers, and
``--symmetry Y`` is the file's Y."""

import json

import numpy as np

import core
from core.mirror import mirror_partners
from tests.cli.gltf_writer import write_gltf
from tests.cli.test_batch import bumpy_sphere, run_batch


def ellipsoid():
    """A bumpy ellipsoid, semi-axes 1, 2, 3 (x, y, z), mirror-symmetric about
    x = 0, y = 0 and z = 0."""
    V, F = bumpy_sphere(3)
    return V * [1.0, 2.0, 3.0], F


def far_from(path, V, F):
    """Largest distance of the written mesh's vertices to the mesh ``V``, ``F``."""
    Vc, _ = core.read_obj(path)
    return float(core.closest_points(V, F, Vc).distance.max())


def test_a_gltf_cage_lies_where_the_files_mesh_lies(tmp_path):
    V, F = ellipsoid()
    t = np.array([0.0, 5.0, 0.0])                        # the node's translation, along Y
    write_gltf(tmp_path / "egg.gltf", V, F, translation=t)
    proc = run_batch(["egg.gltf", "--faces", "200", "--format", "obj", "--out", "out"], tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    Vc, _ = core.read_obj(tmp_path / "out" / "egg_cage.obj")
    assert np.allclose(Vc.min(axis=0), [-1, 3, -3], atol=0.1), Vc.min(axis=0)
    assert np.allclose(Vc.max(axis=0), [1, 7, 3], atol=0.1), Vc.max(axis=0)
    assert far_from(tmp_path / "out" / "egg_cage.obj", V + t, F) < 0.05
    # glTF out holds the file's numbers too: its cage read back lies there as well
    proc = run_batch(["egg.gltf", "--faces", "200", "--out", "glb"], tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    proc = run_batch(["glb/egg_cage.glb", "--ratio", "1", "--format", "obj", "--out", "back"],
                     tmp_path)
    assert far_from(tmp_path / "back" / "egg_cage_cage.obj", V + t, F) < 0.05


def test_symmetry_is_about_the_files_own_axis(tmp_path):
    V, F = ellipsoid()
    write_gltf(tmp_path / "egg.glb", V, F, translation=(0.0, 0.0, 1.5))   # off z = 0 only
    proc = run_batch(["egg.glb", "--faces", "200", "--symmetry", "Y", "--format", "obj",
                      "--out", "out", "--report", "r.json"], tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    f, = json.loads((tmp_path / "r.json").read_text())["files"]
    assert f["status"] == "ok", f["warnings"]
    Vc, _ = core.read_obj(tmp_path / "out" / "egg_cage.obj")
    p = mirror_partners(Vc, "Y", tolerance=1e-6)
    assert np.all(p >= 0) and np.allclose(Vc[p], Vc * [1, -1, 1], atol=1e-6)
    assert Vc[:, 2].min() > -1.6 and Vc[:, 2].max() > 4.4   # the file's z: -1.5 .. 4.5
    # the file's Z is the axis it is off: refused there, naming that plane
    proc = run_batch(["egg.glb", "--faces", "200", "--symmetry", "Z", "--format", "obj",
                      "--out", "z", "--report", "z.json"], tmp_path)
    f, = json.loads((tmp_path / "z.json").read_text())["files"]
    assert proc.returncode == 1 and f["failed_step"] == "symmetry"
    assert "not mirror-symmetric about the plane Z = 0" in f["error"]
