"""Input files Blender's importers would read wrong or fail on with a
traceback, found before Blender reads them and named with what is wrong:
ASCII STL cut short or with a UTF-8 name, PLY holding more than its header
declares, glTF buffers shorter than their JSON says."""

import json
import struct

import numpy as np

from tests.cli.test_batch import rows, run_batch
from tests.cli.gltf_writer import write_gltf
from tests.mesh_factory import icosphere, out_files, write_ply


def write_ascii_stl(path, V, F, *, name="ball"):
    """An ASCII STL file of the triangles ``V[F]``, ``solid NAME`` first (UTF-8)."""
    T = V[F]
    N = np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0])
    facet = ("  facet normal {:e} {:e} {:e}\n    outer loop\n" + "      vertex {:e} {:e} {:e}\n" * 3
             + "    endloop\n  endfacet\n")
    body = "".join(facet.format(*n, *t.ravel()) for n, t in zip(N, T))
    path.write_text(f"solid {name}\n{body}endsolid {name}\n", encoding="utf-8")


def test_an_ascii_stl_cut_short_is_refused_or_warned_naming_the_file(tmp_path):
    V, F = icosphere(2)                                   # 320 triangles
    write_ascii_stl(tmp_path / "whole.stl", V, F)
    text = (tmp_path / "whole.stl").read_text()
    facet_161 = text.split("endfacet\n")[:160]
    cut_at = sum(map(len, facet_161)) + 160 * len("endfacet\n") + 60
    (tmp_path / "cut.stl").write_text(text[:cut_at])      # 60 characters into the 161st facet
    (tmp_path / "open.stl").write_text(text[:text.rindex("endsolid")])    # no endsolid
    proc = run_batch(["whole.stl", "cut.stl", "open.stl", "--faces", "100", "--format", "obj",
                      "--out", "out", "--report", "r.json"], tmp_path)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    whole, cut, opened = json.loads((tmp_path / "r.json").read_text())["files"]
    assert whole["status"] == "ok" and whole["faces_in"] == 320
    assert cut["status"] == "failed" and cut["outputs"] == [] and cut["error"] == (
        "cut.stl: read failed: cut.stl: ends inside facet 161 (file truncated?): an ASCII STL "
        "file's facets each end with 'endfacet', the last one does not")
    assert opened["status"] == "warn" and opened["faces_in"] == 320
    assert opened["warnings"] == ["open.stl: ends after facet 320 without 'endsolid' (file "
                                  "truncated?): read the 320 whole facets"]
    assert out_files(tmp_path / "out") == ["open_cage.obj",
                                                                    "whole_cage.obj"]


def test_an_ascii_stl_named_in_utf8_is_read(tmp_path):
    V, F = icosphere(2)
    write_ascii_stl(tmp_path / "kugel.stl", V, F, name="Kugel größe 球")
    proc = run_batch(["kugel.stl", "--faces", "100", "--format", "obj", "--out", "out"], tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    row, = rows(proc.stdout)
    assert row.startswith("| kugel.stl | 320 | 100 | 100 |") and row.endswith("| ok |")
    assert (tmp_path / "out" / "kugel_cage.obj").exists()


def test_a_ply_holding_more_than_its_header_declares_is_named_before_blender(tmp_path):
    V, F = icosphere(2)                                  # 162 vertices, 320 triangles
    write_ply(tmp_path / "faces.ply", V, F, counts=(162, 300))
    write_ply(tmp_path / "lines.ply", V, F, counts=(162, 300), ascii=True)
    write_ply(tmp_path / "shifted.ply", V, F, counts=(172, 310), ascii=True)
    write_ply(tmp_path / "whole.ply", V, F, ascii=True)
    (tmp_path / "padded.ply").write_bytes(
        (tmp_path / "whole.ply").read_bytes() + b"\n\n")  # blank lines after: padding
    proc = run_batch(["faces.ply", "lines.ply", "shifted.ply", "padded.ply", "--faces", "100",
                      "--format", "obj", "--out", "out"], tmp_path)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    faces, lines, shifted, padded = rows(proc.stdout)
    # 300 triangles of 13 bytes end at byte 6,017; the other 20 (260 bytes) follow
    assert ("FAILED: faces.ply: read failed: faces.ply: its header declares 162 vertex and 300 "
            "face elements, but 260 bytes follow them (the file is 6,277 bytes, its elements end "
            "at byte 6,017): the file holds more than its header declares (a wrong count, or "
            "data appended; Blender's importer would drop them) |") in faces
    assert ("lines.ply: its header declares 162 vertex and 300 face elements, a line each (462), "
            "but 20 more lines with values follow them: the file holds more than its header "
            "declares") in lines
    # the header's 163rd vertex is the file's first face line, "3 ..." (4 values, not 3)
    assert ("shifted.ply: its header declares 172 vertex and 310 face elements, but the vertex "
            "record on line 172 ('3 0 46 43') holds 4 values, not the 3 its properties give") \
        in shifted
    assert padded.startswith("| padded.ply | 320 | 100 |") and padded.endswith("| ok |")
    assert out_files(tmp_path / "out") == ["padded_cage.obj"]


def _cut_glb_bin(data, short):
    """A GLB whose BIN chunk is ``short`` bytes shorter, its lengths mended
    (a consistent file whose buffer holds less than its JSON says)."""
    json_len = struct.unpack_from("<I", data, 12)[0]
    at = 20 + json_len                                    # the BIN chunk's header
    bin_len = struct.unpack_from("<I", data, at)[0] - short
    body = data[at + 8:at + 8 + bin_len]
    head = data[:8] + struct.pack("<I", at + 8 + bin_len) + data[12:at]
    return head + struct.pack("<II", bin_len, 0x004E4942) + body


def test_a_gltf_buffer_shorter_than_its_json_says_is_named_not_a_traceback(tmp_path):
    V, F = icosphere(2)
    write_gltf(tmp_path / "ball.gltf", V, F)
    write_gltf(tmp_path / "ball.glb", V, F)
    (tmp_path / "short").mkdir()
    (tmp_path / "short" / "ball.gltf").write_text((tmp_path / "ball.gltf").read_text())
    size = (tmp_path / "ball.bin").stat().st_size
    (tmp_path / "short" / "ball.bin").write_bytes((tmp_path / "ball.bin").read_bytes()[:4000])
    (tmp_path / "chunk.glb").write_bytes(_cut_glb_bin((tmp_path / "ball.glb").read_bytes(), 400))
    (tmp_path / "cut.glb").write_bytes((tmp_path / "ball.glb").read_bytes()[:-100])
    proc = run_batch(["ball.gltf", "short/ball.gltf", "chunk.glb", "cut.glb", "--faces", "100",
                      "--format", "obj", "--out", "out", "--report", "r.json"], tmp_path)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stdout + proc.stderr
    ok, short, chunk, cut = json.loads((tmp_path / "r.json").read_text())["files"]
    assert ok["status"] == "ok" and ok["faces_in"] == 320
    assert short["error"] == (f"short/ball.gltf: read failed: ball.gltf: buffer 0 (ball.bin) "
                              f"holds 4,000 bytes, the file says {size:,} (file truncated?)")
    glb_bin = size + (-size) % 4                          # the BIN chunk is padded to 4 bytes
    assert chunk["error"] == (f"chunk.glb: read failed: chunk.glb: buffer 0 (the GLB's BIN "
                              f"chunk) holds {glb_bin - 400:,} bytes, the file says {size:,} "
                              f"(file truncated?)")
    full = (tmp_path / "ball.glb").stat().st_size
    assert cut["error"] == (f"cut.glb: read failed: cut.glb: its GLB header says {full:,} bytes, "
                            f"the file has {full - 100:,} (file truncated?)")
    assert out_files(tmp_path / "out") == ["ball_gltf_cage.obj"]


def test_a_python_error_in_blenders_gltf_importer_is_one_line_naming_the_file(tmp_path):
    V, F = icosphere(1)
    write_gltf(tmp_path / "ball.gltf", V, F)
    doc = json.loads((tmp_path / "ball.gltf").read_text())
    doc["meshes"][0]["primitives"][0]["indices"] = 99     # no such accessor: an IndexError
    (tmp_path / "ball.gltf").write_text(json.dumps(doc))
    proc = run_batch(["ball.gltf", "--faces", "20", "--out", "out", "--log", "log.txt"], tmp_path)
    assert proc.returncode == 1
    row, = rows(proc.stdout)
    assert row.endswith(
        "| FAILED: ball.gltf: read failed: Blender's importer failed on ball.gltf: a Python "
        "error in Blender's add-on: IndexError: list index out of range (the traceback is in "
        "the log) |")
    assert "Traceback (most recent call last)" in (tmp_path / "log.txt").read_text()
