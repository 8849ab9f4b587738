"""ASCII STL files whose corners Blender's importer misreads without a
word (found by a fuzz of the batch CLI on 2026-12-05, second campaign):
each is named by its line before Blender reads it."""

import json

import numpy as np

from tests.cli.test_batch import errors_beside_a_whole_file, run_batch
from tests.cli.test_file_checks import write_ascii_stl
from tests.mesh_factory import icosphere


def test_an_ascii_stl_corner_that_is_not_three_numbers_is_named_by_its_line(tmp_path):
    """'vertex 1.0 abc 2.0' and 'vertex 1.0 2.0' came back status ok (Blender
    read them on, as 0 or the next line's word); decimal commas gave 'no
    mesh with faces in the file'; a facet with a corner missing was a
    warning that Blender 'removed 1 degenerate triangles'."""
    V, F = icosphere(2)                                   # 320 triangles, 7 lines a facet
    write_ascii_stl(tmp_path / "whole.stl", V, F)
    lines = (tmp_path / "whole.stl").read_text().split("\n")
    assert lines[101].strip().startswith("vertex")        # line 102: facet 15's first corner

    def variant(name, text):
        (tmp_path / name).write_text("\n".join(lines[:101] + text + lines[102:]))
    variant("word.stl", ["      vertex 1.0 abc 2.0"])
    variant("two.stl", ["      vertex 1.0 2.0"])
    variant("corner.stl", [])
    variant("caps.stl", ["      VERTEX 1.0 2.0 NaN"])
    text = (tmp_path / "whole.stl").read_text()
    (tmp_path / "comma.stl").write_text(text.replace(".", ","))
    errors = errors_beside_a_whole_file(
        tmp_path, ["word.stl", "two.stl", "corner.stl", "caps.stl", "comma.stl"], "whole.stl")
    comma = errors.pop("comma.stl")
    assert comma.startswith("comma.stl: read failed: comma.stl: line 4, 'vertex ")
    assert "which is not a number (a decimal comma? STL's numbers take a point)" in comma
    assert errors == {
        "word.stl": "word.stl: read failed: word.stl: line 102, 'vertex 1.0 abc 2.0', holds "
                    "'abc', which is not a number (Blender's importer would misread it)",
        "two.stl": "two.stl: read failed: two.stl: line 102, 'vertex 1.0 2.0', has 2 numbers, "
                   "not the 3 of a corner (Blender's importer would misread it)",
        "corner.stl": "corner.stl: read failed: corner.stl: facet 15 (line 102) has 2 vertices, "
                      "not 3: a damaged file (Blender's importer would drop it as a degenerate "
                      "triangle)",
        "caps.stl": "caps.stl: read failed: caps.stl: 1 facet with a coordinate that is not a "
                    "finite number (NaN or infinity, or beyond a float's range; Blender's "
                    "importer would read them as 0)"}


def test_the_weld_blenders_stl_importer_does_is_reported(tmp_path):
    """STL stores each triangle's corners apart and Blender's importer joins
    those at one position, so the cleaning had nothing to weld: an STL of
    320 triangles (960 corners) reported no weld at all, where the same
    triangles unwelded in a PLY report 'welded 798 vertices'."""
    from tests.mesh_factory import write_binary_stl, write_ply
    V, F = icosphere(2)                                   # 162 vertices
    write_binary_stl(tmp_path / "ball.stl", V, F)
    write_ply(tmp_path / "ball.ply", V[F].reshape(-1, 3), np.arange(960).reshape(-1, 3))
    proc = run_batch(["ball.stl", "ball.ply", "--faces", "100", "--format", "obj", "--out", "out",
                      "--report", "r.json"], tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    stl, ply = json.loads((tmp_path / "r.json").read_text())["files"]
    assert stl["status"] == ply["status"] == "ok"
    assert stl["notes"] == ["Blender's STL importer joined the 960 corners of the file's "
                            "triangles into 162 vertices (those at one position)"]
    assert ply["notes"] == ["cleaning: welded 798 vertices"]
    assert stl["faces_out"] == ply["faces_out"] == 100


def test_a_facet_of_four_corners_is_named_by_its_line(tmp_path):
    """An ASCII STL facet with a fourth corner (a line of the next facet
    copied into it) made Blender read 321 faces from 320 facets, a face
    the file does not hold: the file came back "ok", then with a warning
    that said only "read 321 faces from the file's 320". Now refused as a
    facet of fewer corners is, naming the facet and its line. (STL's facets
    are triangles.)"""
    V, F = icosphere(2)
    write_ascii_stl(tmp_path / "whole.stl", V, F)
    lines = (tmp_path / "whole.stl").read_text().split("\n")
    assert lines[103].strip().startswith("vertex") and lines[108].strip().startswith("vertex")
    (tmp_path / "twice.stl").write_text("\n".join(lines[:104] + [lines[108]] + lines[104:]))
    proc = run_batch(["twice.stl", "whole.stl", "--faces", "100", "--format", "obj", "--out",
                      "out", "--report", "r.json"], tmp_path)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    twice, whole = json.loads((tmp_path / "r.json").read_text())["files"]
    assert whole["status"] == "ok" and whole["warnings"] == []
    assert twice["status"] == "failed" and twice["error"] == (
        "twice.stl: read failed: twice.stl: facet 15 (line 102) has 4 vertices, not 3: a "
        "damaged file (Blender's importer would read it as more than one face)")
