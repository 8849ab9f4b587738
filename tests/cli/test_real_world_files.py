"""Files as real tools write them, which the batch misread or refused (found
by a fuzz of the batch CLI and the readers on 2026-12-05): STL in capitals or
with bytes after its triangles, mirrored glTF nodes, PLY triangle strips and
short faces, OBJ run as ``python -m cli.batch``."""

import json

import numpy as np

from tests.cli.test_batch import rows, run_batch
from tests.cli.test_file_checks import write_ascii_stl
from tests.mesh_factory import icosphere, out_files, write_binary_stl


def test_stl_in_capitals_or_with_bytes_after_its_triangles_is_read(tmp_path):
    """'VERTEX' in capitals: Blender's importer found no face ('no mesh with
    faces in the file'); a binary file with 22 bytes after the triangles its
    header declares was refused as 'cut short or damaged'; NUL bytes after
    'endsolid' were warned as a file cut short; a file of two solids named
    'faceted_part0' and 'faceted_part1' was refused as 'ends inside facet
    161 (file truncated?)'."""
    V, F = icosphere(2)                                   # 320 triangles
    write_ascii_stl(tmp_path / "caps.stl", V, F)
    (tmp_path / "caps.stl").write_text((tmp_path / "caps.stl").read_text().upper())
    write_binary_stl(tmp_path / "tail.stl", V, F, extra=b"exported by ACME\x00\x00\x00\x00\x00\x00")
    write_ascii_stl(tmp_path / "junk.stl", V, F)
    with open(tmp_path / "junk.stl", "ab") as fh:
        fh.write(b"\x00\x00\x00\x00")
    write_binary_stl(tmp_path / "plus1.stl", V, F, extra=bytes(50))     # a whole triangle more
    for k, half in enumerate((F[:160], F[160:])):      # two solids, 'facet' inside their names
        write_ascii_stl(tmp_path / f"part{k}.stl", V, half, name=f"faceted_part{k}")
    (tmp_path / "parts.stl").write_text((tmp_path / "part0.stl").read_text() +
                                        (tmp_path / "part1.stl").read_text())
    proc = run_batch(["caps.stl", "tail.stl", "junk.stl", "plus1.stl", "parts.stl", "--faces",
                      "100", "--format", "obj", "--out", "out", "--report", "r.json"], tmp_path)
    caps, tail, junk, plus1, parts = json.loads((tmp_path / "r.json").read_text())["files"]
    assert parts["status"] == "ok" and parts["faces_in"] == 320 and parts["warnings"] == []
    assert caps["status"] == "ok" and caps["faces_in"] == 320 and caps["warnings"] == []
    assert tail["status"] == "warn" and tail["faces_in"] == 320
    assert tail["warnings"] == ["tail.stl: 22 bytes follow the 320 triangles its header declares, "
                                "no whole triangle (data appended to the file?): read those 320 "
                                "triangles"]
    assert junk["status"] == "ok" and junk["faces_in"] == 320 and junk["warnings"] == []
    assert plus1["status"] == "failed" and "says 320 triangles, but its size" in plus1["error"]
    assert proc.returncode == 1 and "Traceback" not in proc.stdout + proc.stderr
    assert out_files(tmp_path / "out") == [
        "caps_cage.obj", "junk_cage.obj", "parts_cage.obj", "tail_cage.obj"]


def write_gltf_nodes(path, V, F, nodes, *, in_scene=True):
    """A ``.gltf`` file with one mesh (``V``, ``F``: its buffer a ``data:``
    URI) placed by each of ``nodes`` (glTF node dicts without the mesh),
    which its scene lists (or none of them: ``in_scene=False``)."""
    import base64
    pos, idx = np.asarray(V, "<f4").tobytes(), np.asarray(F, "<u4").tobytes()
    doc = {"asset": {"version": "2.0"}, "scene": 0,
           "scenes": [{"nodes": list(range(len(nodes))) if in_scene else []}],
           "nodes": [dict(n, mesh=0) for n in nodes],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": len(V), "type": "VEC3",
                          "min": np.min(V, 0).tolist(), "max": np.max(V, 0).tolist()},
                         {"bufferView": 1, "componentType": 5125, "count": F.size,
                          "type": "SCALAR"}],
           "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": len(pos)},
                           {"buffer": 0, "byteOffset": len(pos), "byteLength": len(idx)}],
           "buffers": [{"byteLength": len(pos) + len(idx), "uri": "data:application/octet-stream;"
                        "base64," + base64.b64encode(pos + idx).decode()}]}
    path.write_text(json.dumps(doc))


def signed_volumes(V, F, split_x):
    """Signed volume of the faces left and right of ``x = split_x``."""
    T = V[F]
    vol = np.einsum("ij,ij->i", T[:, 0], np.cross(T[:, 1], T[:, 2])) / 6
    left = T[:, :, 0].mean(axis=1) < split_x
    return vol[left].sum(), vol[~left].sum()


def test_a_mirrored_gltf_node_keeps_its_faces_outward(tmp_path):
    """glTF winds the front faces of a node whose transform mirrors (a
    negative determinant) clockwise, and Blender draws them so, but its
    importer keeps the file's winding in the mesh: the batch applied the
    transform and wrote the mirrored instance inside out (its cage's volume
    negative). Both instances share one mesh: only the mirrored one turns."""
    import core
    V, F = icosphere(2)                                   # outward, volume > 0
    write_gltf_nodes(tmp_path / "pair.gltf", V, F,
                     [{"translation": [-3.0, 0.0, 0.0]},
                      {"translation": [3.0, 0.0, 0.0], "scale": [-1.0, 1.0, 1.0]}])
    write_gltf_nodes(tmp_path / "flip.gltf", V, F, [{"matrix": [1, 0, 0, 0, 0, 0, 1, 0, 0, 1, 0,
                                                                 0, 0, 0, 0, 1]}])
    proc = run_batch(["pair.gltf", "flip.gltf", "--faces", "200", "--format", "obj", "--out",
                      "out"], tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    Vc, Fc = core.read_obj(tmp_path / "out" / "pair_cage.obj")
    left, right = signed_volumes(Vc, Fc, 0.0)
    assert left > 3.5 and right > 3.5                     # (a unit ball: 4.19; the cage a bit less)
    Vc, Fc = core.read_obj(tmp_path / "out" / "flip_cage.obj")   # y and z swapped: a mirror
    assert sum(signed_volumes(Vc, Fc, 0.0)) > 3.5


def write_binary_ply(path, V, element, rows, count_type="uchar"):
    """A binary little-endian PLY file of the vertices ``V`` (float32) and
    the list ``element`` (``face`` or ``tristrips``) of ``rows`` (int32)."""
    ct = {"uchar": "<u1", "int": "<i4"}[count_type]
    head = (f"ply\nformat binary_little_endian 1.0\ncomment written by a scanner\n"
            f"element vertex {len(V)}\nproperty float x\nproperty float y\nproperty float z\n"
            f"element {element} {len(rows)}\nproperty list {count_type} int vertex_indices\n"
            f"end_header\n").encode()
    body = b"".join(np.array([len(r)], ct).tobytes() + np.asarray(r, "<i4").tobytes()
                    for r in rows)
    path.write_bytes(head + np.asarray(V, "<f4").tobytes() + body)


def test_binary_ply_triangle_strips_and_faces_of_two_corners_are_read(tmp_path):
    """A binary PLY of triangle strips (one record of 605 indices, -1 ending
    each strip) was refused before Blender read it ('the first tristrips
    record holds no valid tristrips ... or the file is damaged'), and so was
    a whole file with a face of 2 corners among its triangles ('the file
    ends before its 82 face elements: cut short'); Blender's importer reads
    both (and skips the short faces, which the report says)."""
    nx, ny = 150, 2
    x, y = np.meshgrid(np.arange(nx + 1.0), np.arange(ny + 1.0))
    grid = np.stack([x.ravel(), y.ravel(), 0.1 * np.sin(x.ravel())], axis=1)
    strips = []
    for j in range(ny):
        row = np.stack([j * (nx + 1) + np.arange(nx + 1), (j + 1) * (nx + 1) + np.arange(nx + 1)],
                       axis=1).ravel()
        strips += row.tolist() + [-1]
    write_binary_ply(tmp_path / "strips.ply", grid, "tristrips", [strips[:-1]], "int")
    V, F = icosphere(1)
    write_binary_ply(tmp_path / "short.ply", V, "face", F.tolist() + [[0, 1], [2]])
    proc = run_batch(["strips.ply", "short.ply", "--faces", "60", "--format", "obj", "--out",
                      "out", "--report", "r.json"], tmp_path)
    strips_r, short = json.loads((tmp_path / "r.json").read_text())["files"]
    assert strips_r["status"] == "ok", strips_r
    assert strips_r["faces_in"] == 2 * nx * ny and strips_r["faces_out"] == 60
    assert short["status"] == "warn" and short["faces_in"] == 80, short
    assert short["warnings"][0] == "Blender's PLY importer kept 80 of the file's 82 faces"
    assert proc.returncode == 0 and "Traceback" not in proc.stdout + proc.stderr


def test_python_m_cli_batch_in_a_checkout_runs_the_tool(tmp_path):
    """`python -m cli.batch` from the checkout's folder ended in an ImportError
    traceback ('attempted relative import beyond top-level package'): it runs
    the tool now, as the checkout's script does (workers too)."""
    import os
    import subprocess
    import sys
    import core
    from tests.cli.test_batch import ROOT
    V, F = icosphere(2)
    core.write_obj(tmp_path / "ball.obj", V, F)
    core.write_obj(tmp_path / "ball2.obj", V * 2, F)
    env = dict(os.environ, HOME=str(tmp_path))
    proc = subprocess.run([sys.executable, "-m", "cli.batch", str(tmp_path / "ball.obj"),
                           str(tmp_path / "ball2.obj"), "--faces", "100", "--jobs", "2",
                           "--out", str(tmp_path / "out")], capture_output=True, text=True,
                          cwd=ROOT, env=env, timeout=300)
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stdout + proc.stderr
    assert [r.split(" | ")[-1] for r in rows(proc.stdout)] == ["ok |", "ok |"]
    assert out_files(tmp_path / "out") == ["ball2_cage.obj",
                                                                    "ball_cage.obj"]


def test_a_gltf_whose_scene_shows_no_mesh_fails_saying_so(tmp_path):
    """A glTF node that no scene lists: Blender's importer makes its object
    outside the view layer, and the batch failed selecting it ('RuntimeError:
    Error: Object 'Mesh_0' cannot be selected because it is not in View
    Layer'); it says what the file holds now, and the batch goes on."""
    V, F = icosphere(1)
    write_gltf_nodes(tmp_path / "orphan.gltf", V, F, [{}], in_scene=False)
    write_gltf_nodes(tmp_path / "shown.gltf", V, F, [{}])
    proc = run_batch(["orphan.gltf", "shown.gltf", "--faces", "40", "--format", "obj", "--out",
                      "out"], tmp_path)
    orphan, shown = rows(proc.stdout)
    assert ("FAILED: orphan.gltf: read failed: orphan.gltf: no mesh with faces in the file (1 "
            "outside the scene it shows: glTF nodes in no scene or in another) |") in orphan
    assert shown.endswith("| ok |") and proc.returncode == 1
    assert "RuntimeError" not in proc.stdout and "Traceback" not in proc.stdout + proc.stderr


def test_obj_continuations_and_a_folder_named_like_a_mesh_in_a_batch(tmp_path):
    """In a folder given to the batch: an OBJ with a continued face line and
    comments after its numbers is read (it failed: "'f 1 2 \\' has an index
    that is not an integer"), and a folder named 'scan.obj' fails as a
    folder (it said 'no such file'), the batch going on."""
    import core
    V, F = icosphere(2)
    text = "".join(f"v {x!r} {y!r} {z!r} # a point\n" for x, y, z in V.tolist())
    text += "".join(f"f {a + 1} {b + 1} \\\n {c + 1} # a tri\n" for a, b, c in F)
    (tmp_path / "scans").mkdir()
    (tmp_path / "scans" / "cont.obj").write_text(text.replace("\n", "\r\n"))
    (tmp_path / "scans" / "scan.obj").mkdir()
    proc = run_batch(["scans", "--faces", "100", "--out", "out"], tmp_path)
    cont, folder = rows(proc.stdout)
    assert cont.startswith("| cont.obj | 320 | 100 | 100 |") and cont.endswith("| ok |"), cont
    assert "FAILED: scan.obj: read failed: a folder, not a mesh file: " in folder
    assert proc.returncode == 1 and "Traceback" not in proc.stdout + proc.stderr
    assert core.read_obj(tmp_path / "out" / "cont_cage.obj")[1].shape == (100, 3)


def test_an_ascii_ply_with_a_blank_line_among_its_records_says_so(tmp_path):
    """A blank line between an ASCII PLY's vertices and faces (Blender's
    importer takes it for a face: 'Invalid face size') was refused as 'the
    file holds more than its header declares (a wrong count)', though its
    counts are right: the message names the blank line."""
    from cli.ply_file import ply_size_problem
    from tests.mesh_factory import write_ply
    V, F = icosphere(1)                                   # 42 vertices, 80 faces
    write_ply(tmp_path / "blank.ply", V, F, ascii=True)
    head, body = (tmp_path / "blank.ply").read_bytes().split(b"end_header\n")
    lines = body.split(b"\n")
    (tmp_path / "blank.ply").write_bytes(head + b"end_header\n" + b"\n".join(
        lines[:42] + [b""] + lines[42:]))
    assert ply_size_problem(str(tmp_path / "blank.ply")) == (
        "blank.ply: its header declares 42 vertex and 80 face elements, a line each, but line 52 "
        "among them is blank: Blender's importer would take it for a record and misread the "
        "rest; delete the blank lines")


def test_a_binary_ply_whose_first_face_has_more_than_255_corners_says_so(tmp_path):
    """Blender's PLY importer reads faces of at most 255 corners; a binary
    file whose first face is a 300-gon (an int corner count) was refused as
    'holds no valid face: ... a wrong count, or the file is damaged'."""
    from cli.ply_file import ply_size_problem
    t = np.linspace(0, 2 * np.pi, 300, endpoint=False)
    V = np.vstack([np.stack([np.cos(t), np.sin(t), np.zeros(300)], axis=1), [[0.0, 0.0, 1.0]]])
    faces = [np.arange(300)] + [np.array([300, i, (i + 1) % 300]) for i in range(300)]
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(V)}\nproperty float x\n"
            f"property float y\nproperty float z\nelement face {len(faces)}\n"
            "property list int int vertex_indices\nend_header\n").encode()
    body = np.asarray(V, "<f4").tobytes() + b"".join(
        np.int32(len(f)).tobytes() + np.asarray(f, "<i4").tobytes() for f in faces)
    (tmp_path / "disk.ply").write_bytes(head + body)
    why = ply_size_problem(str(tmp_path / "disk.ply"))
    assert why.startswith("disk.ply: its first face (at byte ") and "more than 255 corners" in why
    assert "wrong count" not in why
