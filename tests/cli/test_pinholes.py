"""The batch CLI on a scan full of tiny holes: by default they are capped when
they keep the cage from its target, and the report counts them;
``--keep-pinholes`` keeps them, and the cage then misses the target and says
so (a warning, not ``ok``)."""

import json

import core
from tests.cli.test_batch import run_batch
from tests.core.test_pinholes import without
from tests.mesh_factory import apart_faces, icosphere


def test_pinholes_are_capped_unless_kept(tmp_path):
    V, F = icosphere(4)
    core.write_obj(tmp_path / "holed.obj", V, without(F, apart_faces(F, 300, seed=2)))
    proc = run_batch(["holed.obj", "--faces", "60", "--report", "capped.json"], tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    row = json.loads((tmp_path / "capped.json").read_text())["files"][0]
    assert row["stopped_because"] == "target" and row["faces_out"] <= 60
    assert row["cleaning"]["n_pinholes"] == 300 and row["cleaning"]["n_pinhole_faces"] == 300
    assert "closed 300 pinholes (300 faces)" in row["message"]
    proc = run_batch(["holed.obj", "--faces", "60", "--keep-pinholes", "--report", "kept.json",
                      "--out", "kept"], tmp_path)
    row = json.loads((tmp_path / "kept.json").read_text())["files"][0]
    assert row["status"] == "warn" and row["faces_out"] > 60
    assert row["cleaning"]["n_pinholes"] == 0 and "300 border loops" in row["message"]
