"""Input files Blender's importers would read wrong or fail on with a
traceback, found before Blender reads them and named with what is wrong:
ASCII STL cut short or with a UTF-8 name, PLY holding more than its header
declares, glTF buffers shorter than their JSON says."""

import json
import struct

import numpy as np
import pytest

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


# ---- a campaign of 2026-12-06, late night: files that came back "ok" with wrong geometry,
# valid files refused, Blender's tracebacks and a log that grew with every failure ----

def _check(path):
    """The batch's own check of ``path`` (before Blender): its FileCheck, or
    the InputFileError's message."""
    from cli import blender_io
    from cli.file_check import InputFileError
    try:
        return blender_io.FILE_CHECKS[path.suffix.lower()](str(path))
    except InputFileError as exc:
        return str(exc)


def _ascii_ply(path, V, F, *, vertex_props="property float x\nproperty float y\n"
               "property float z\n", vertex_line="{x!r} {y!r} {z!r}", face_line="3 {a} {b} {c}"):
    head = (f"ply\nformat ascii 1.0\nelement vertex {len(V)}\n{vertex_props}element face "
            f"{len(F)}\nproperty list uchar int vertex_indices\nend_header\n")
    body = "".join(vertex_line.format(x=x, y=y, z=z) + "\n" for x, y, z in V.tolist())
    path.write_text(head + body + "".join(face_line.format(a=a, b=b, c=c) + "\n"
                                          for a, b, c in F.tolist()))


def test_ply_coordinates_blender_would_read_as_zero_are_named(tmp_path):
    """A NaN in a vertex element with a list property (its coordinates had
    not been read at all), a coordinate declared twice, and 1e39 in a float
    property (finite in float64; Blender stores it as 0): each came back
    "ok"; 1e39 in a double property is a coordinate."""
    V, F = icosphere(1)
    V[5, 1] = np.nan
    xyz = "property float x\nproperty float y\nproperty float z\n"
    _ascii_ply(tmp_path / "extras.ply", V, F, vertex_props=xyz + "property list uchar float u\n",
               vertex_line="{x!r} {y!r} {z!r} 2 0.5 0.25")
    assert _check(tmp_path / "extras.ply").endswith(
        "extras.ply: 1 vertex with a coordinate that is not a finite number (NaN or infinity, or "
        "beyond a float's range; Blender's importer would read them as 0)")
    _ascii_ply(tmp_path / "twice.ply", V, F, vertex_props=xyz + "property float x\n",
               vertex_line="{x!r} {y!r} {z!r} 0")
    assert _check(tmp_path / "twice.ply") == (
        "twice.ply: its header declares the vertices' property 'x' 2 times: which one is the "
        "coordinate is not clear (a damaged header)")
    V[5, 1] = 1e39
    _ascii_ply(tmp_path / "big.ply", V, F)
    assert "big.ply: 1 vertex with a coordinate that is not a finite number" in \
        _check(tmp_path / "big.ply")
    _ascii_ply(tmp_path / "double.ply", V, F, vertex_props=xyz.replace("float", "double"))
    assert _check(tmp_path / "double.ply").expected_faces == 80


@pytest.mark.parametrize("line, word", [("3.0 {a} {b} {c}", "3.0"), ("3 {a} {b} {c}.0", ".0"),
                                        ("3 {a} {b} 0.42e2", "0.42e2"),
                                        ("3 {a} {b} 2147483648", "2147483648")])
def test_ply_face_words_blender_reads_otherwise_are_named(tmp_path, line, word):
    """A count or index written as a float (Blender read no faces, or
    scrambled ones) or beyond 32 bits (read as vertex 0, "ok")."""
    V, F = icosphere(1)
    _ascii_ply(tmp_path / "odd.ply", V, F, face_line=line)
    got = _check(tmp_path / "odd.ply")
    assert isinstance(got, str) and "the face record on line 52" in got and word in got, got


def test_ply_bad_first_index_and_triangle_strips_are_read_as_they_are(tmp_path):
    """A binary PLY whose first face has an index out of range (a later one
    is a warning) was refused as "a wrong count"; a file of faces and
    triangle strips had its faces read compared with its face records alone
    ("read 320 faces from the file's 160")."""
    V, F = icosphere(2)
    bad = F.copy()
    bad[0, 1] = 100_000
    write_ply(tmp_path / "first.ply", V, bad)
    assert _check(tmp_path / "first.ply").expected_faces == 320
    text = (tmp_path / "strips.ply")
    _ascii_ply(text, V, F[:160])
    head, body = text.read_text().split("end_header\n")
    strips = "".join(f"3 {a} {b} {c}\n" for a, b, c in F[160:].tolist())
    text.write_text(head + "element tristrips 160\nproperty list int int vertex_indices\n"
                    "end_header\n" + body + strips)
    assert _check(text).expected_faces is None


def _stl_text(V, F, name):
    T = V[F]
    return (f"solid {name}\n" + "".join(
        " facet normal 0 0 0\n  outer loop\n" + "".join(f"   vertex {x!r} {y!r} {z!r}\n"
                                                        for x, y, z in t.tolist())
        + "  endloop\n endfacet\n" for t in T) + f"endsolid {name}\n")


def test_ascii_stl_names_encodings_and_coordinates(tmp_path):
    """A solid named 'scan facet model' or 'vertex colours' (its endsolid line
    repeats the name: "ends inside facet 81", or a corner Blender read: a
    face too many), a Latin-1 name (refused as a damaged binary file), a
    corner at 1e39 (read as 0, "ok") and a facet of 4 corners."""
    from cli import stl_file
    V, F = icosphere(1)
    for name in ("scan facet model", "vertex colours"):
        path = tmp_path / f"{name.split()[0]}.stl"
        path.write_text(_stl_text(V, F, name))
        assert _check(path).expected_faces == 80
        with stl_file.for_blender(str(path)) as copy:
            with open(copy, "rb") as fh:
                text = fh.read()
        assert text.count(b"vertex") == 240 and text.count(b"endsolid\n") == 1
    latin = tmp_path / "latin.stl"
    latin.write_bytes(_stl_text(V, F, "Größe").encode("latin-1"))
    assert _check(latin).expected_faces == 80
    big = V.copy()
    big[3, 0] = 1e39
    (tmp_path / "big.stl").write_text(_stl_text(big, F, "big"))
    assert _check(tmp_path / "big.stl").startswith("big.stl: 5 facets with a coordinate that is "
                                                   "not a finite number")
    four = _stl_text(V, F, "four").replace("  endloop", "   vertex 0 0 0\n  endloop", 1)
    (tmp_path / "four.stl").write_text(four)
    assert _check(tmp_path / "four.stl") == (
        "four.stl: facet 1 (line 4) has 4 vertices, not 3: a damaged file (Blender's importer "
        "would read it as more than one face)")


def _gltf(path, change=None):
    """A glTF of an icosphere, its buffer a data: URI (positions, indices,
    then room for a sparse substitution), ``change(doc)`` applied."""
    import base64
    import copy
    V, F = icosphere(1)
    pos, idx = V.astype("<f4").tobytes(), F.astype("<u4").tobytes()
    data = pos + idx + np.array([5], "<u4").tobytes() + np.array([np.nan, 0, 0], "<f4").tobytes()
    doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
           "nodes": [{"mesh": 0}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
           "buffers": [{"byteLength": len(data), "uri": "data:application/octet-stream;base64,"
                        + base64.b64encode(data).decode()}],
           "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": len(pos)},
                           {"buffer": 0, "byteOffset": len(pos), "byteLength": len(idx)},
                           {"buffer": 0, "byteOffset": len(pos) + len(idx), "byteLength": 4},
                           {"buffer": 0, "byteOffset": len(pos) + len(idx) + 4,
                            "byteLength": 12}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": len(V),
                          "type": "VEC3", "min": [-1, -1, -1], "max": [1, 1, 1]},
                         {"bufferView": 1, "componentType": 5125, "count": F.size,
                          "type": "SCALAR"}]}
    doc = copy.deepcopy(doc)
    if change is not None:
        change(doc)
    path.write_text(json.dumps(doc))
    return path


_SPARSE = {"count": 1, "indices": {"bufferView": 2, "componentType": 5125},
           "values": {"bufferView": 3}}


@pytest.mark.parametrize("change, message", [
    (lambda d: d["accessors"][0].update(sparse=_SPARSE),
     "mesh 0 primitive 0 has 1 vertex with a coordinate that is not a finite number"),
    (lambda d: d["accessors"][0].update(sparse=dict(_SPARSE, count=10)),
     "accessor 0's sparse indices reads 40 bytes of bufferView 2, which holds 4"),
    (lambda d: d["bufferViews"][0].update(byteStride=4),
     "bufferView 0 has a byteStride of 4 bytes, less than the 12 of each element of accessor 0"),
    (lambda d: d["nodes"][0].update(children=[0]), "node 0 is the child of itself"),
    (lambda d: (d["nodes"].extend([{"children": [0]}, {"children": [0]}]),
                d["scenes"][0].update(nodes=[1, 2])), "node 0 is the child of two nodes"),
    (lambda d: d["nodes"].extend([{"children": [2]}, {"children": [1]}]),
     "node 1 is its own ancestor"),
    (lambda d: d.update(scene=3), "its default scene 3 is not one of its 1 scenes"),
    (lambda d: d["accessors"][1].update(componentType=5126),
     "mesh 0 primitive 0's indices are not unsigned integers"),
])
def test_gltf_files_blender_reads_wrong_or_fails_on_are_named(tmp_path, change, message):
    """A NaN through a sparse accessor and a byteStride smaller than an
    element came back "ok" (0, or overlapping positions); the others were a
    bare RecursionError, AssertionError, IndexError or ValueError from
    Blender's add-on."""
    got = _check(_gltf(tmp_path / "odd.gltf", change))
    assert isinstance(got, str) and got.startswith(f"odd.gltf: {message}"), got


def test_an_index_past_the_positions_and_a_failed_import_leave_no_trace(tmp_path):
    """An index past the vertices (Blender's IndexError) is named; a glTF
    Blender's add-on fails on left its logger's handler behind, so each
    later glTF's log repeated every line once per failure before it."""
    def past(d):
        import base64
        V, F = icosphere(1)
        F[10, 1] = 9999
        data = V.astype("<f4").tobytes() + F.astype("<u4").tobytes()
        d["buffers"][0] = {"byteLength": len(data), "uri": "data:;base64,"
                           + base64.b64encode(data).decode()}
        d["bufferViews"] = d["bufferViews"][:2]
    assert _check(_gltf(tmp_path / "past.gltf", past)) == \
        "past.gltf: mesh 0 primitive 0 has an index 9,999, past its 42 vertices (a damaged file)"
    for k in range(3):            # (no such accessor: the add-on's IndexError)
        _gltf(tmp_path / f"bad{k}.gltf",
              lambda d: d["meshes"][0]["primitives"][0].update(indices=99))
    _gltf(tmp_path / "zz_good.gltf")
    proc = run_batch(["bad0.gltf", "bad1.gltf", "bad2.gltf", "zz_good.gltf", "--faces", "20",
                      "--out", "out", "--report", "r.json"], tmp_path)
    assert proc.returncode == 1
    good = json.loads((tmp_path / "r.json").read_text())["files"][-1]
    assert good["status"] == "ok" and good["log"].count("glTF import finished") == 1, good["log"]
