"""The batch CLI's --weld-distance, and the automatic weld it replaces: a soup
whose copies of a vertex drifted apart welds back by itself and the report says
so; a weld fixed too narrow for it leaves separate pieces, and the message says
what to do."""

import json

import core
from tests.cli.test_batch import bumpy_sphere, run_batch
from tests.mesh_factory import unwelded


def test_the_weld_is_automatic_or_as_asked(tmp_path):
    V, F = bumpy_sphere(3)
    S, FS = unwelded(V, F, 2e-6, seed=3)
    core.write_obj(tmp_path / "soup.obj", S, FS)
    proc = run_batch(["soup.obj", "--faces", "200", "--report", "auto.json"], tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    row = json.loads((tmp_path / "auto.json").read_text())["files"][0]
    assert row["stopped_because"] == "target" and row["faces_out"] == 200
    assert row["cleaning"]["weld_distance"] == 1e-5
    assert "the input came in pieces" in row["message"]
    proc = run_batch(["soup.obj", "--faces", "200", "--weld-distance", "1e-7", "--report",
                      "narrow.json", "--out", "narrow"], tmp_path)
    row = json.loads((tmp_path / "narrow.json").read_text())["files"][0]
    assert row["stopped_because"] == "topology_floor" and row["faces_out"] == F.shape[0]
    assert "separate pieces: weld it first" in row["message"]
    # a soup's pieces are not measured against themselves (overlapping ones took 28 s)
    assert row.get("deviation_pct") is None
    assert f"the deviation is not measured: the cage is the input's {F.shape[0]:,} separate " \
        f"pieces" in row["notes"]
    for bad in ("-1", "1", "2"):
        proc = run_batch(["soup.obj", "--faces", "200", "--weld-distance", bad], tmp_path)
        assert proc.returncode == 2 and "--weld-distance" in proc.stderr
