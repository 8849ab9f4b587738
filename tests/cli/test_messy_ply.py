"""PLY files as scanners and exporters write them, damaged in ways Blender's
importer reads on silently or crashes on (found by a fuzz of the batch CLI
on 2026-12-05, second campaign): each is named before Blender reads it, the
other files of the batch still converted."""

import json

import numpy as np
import pytest

from cli.file_check import InputFileError
from cli.ply_file import check, ply_size_problem
from tests.cli.test_batch import errors_beside_a_whole_file, run_batch
from tests.mesh_factory import icosphere, out_files, write_ply


def _ascii_ply(path, V, F, *, replace=None):
    """An ASCII PLY file of ``V``, ``F``; ``replace``: ``{record index: text}``
    (vertices first, then faces) written instead of those records."""
    write_ply(path, V, F, ascii=True)
    head, body = path.read_bytes().split(b"end_header\n")
    lines = body.split(b"\n")
    for k, text in (replace or {}).items():
        lines[k] = text
    path.write_bytes(head + b"end_header\n" + b"\n".join(lines))


def test_an_ascii_ply_record_that_is_not_what_its_properties_say_is_named(tmp_path):
    """Only an element's first and last records were checked: a vertex line
    in the middle with a word that is no number ('0.5 abc 0.5', read as 0),
    two values or four, a decimal comma everywhere (every vertex on an axis:
    'nothing is left after cleaning'), a face with an index of 1.5 or a count
    of 4 with 3 indices (dropped: 'kept 319 of 320 faces') came back ok or
    warned without naming the line."""
    V, F = icosphere(2)                      # 162 vertices, 320 faces; 9 header lines
    cases = {"word.ply": {50: b"0.5 abc 0.5"}, "short.ply": {50: b"0.5 0.5"},
             "long.ply": {50: b"0.5 0.5 0.5 0.5"}, "index.ply": {200: b"3 0 1.5 2"},
             "count.ply": {200: b"4 0 1 2"}}
    for name, replace in cases.items():
        _ascii_ply(tmp_path / name, V, F, replace=replace)
    _ascii_ply(tmp_path / "whole.ply", V, F)
    (tmp_path / "comma.ply").write_bytes((tmp_path / "whole.ply").read_bytes().replace(b".", b","))
    names = [*cases, "comma.ply", "whole.ply"]
    proc = run_batch([*names, "--faces", "100", "--format", "obj", "--out", "out",
                      "--report", "r.json"], tmp_path)
    assert proc.returncode == 1 and "Traceback" not in proc.stdout + proc.stderr
    got = {f["name"]: f for f in json.loads((tmp_path / "r.json").read_text())["files"]}
    said = "its header declares 162 vertex and 320 face elements, but the"
    want = {"word.ply": "vertex record on line 60 ('0.5 abc 0.5') holds 'abc', which is not a "
                        "number: a damaged file",
            "short.ply": "vertex record on line 60 ('0.5 0.5') holds 2 values, not the 3 its "
                         "properties give: a wrong count in the header, or a damaged file",
            "long.ply": "vertex record on line 60 ('0.5 0.5 0.5 0.5') holds 4 values, not the 3",
            "index.ply": "face record on line 210 ('3 0 1.5 2') holds '1.5' in its "
                         "vertex_indices list, whose items are 32-bit integers (int) written "
                         "in digits",
            "count.ply": "face record on line 210 ('4 0 1 2') holds 4 values, not the 5 its "
                         "properties give",
            "comma.ply": "vertex record on line 10 ("}
    for name, text in want.items():
        r = got[name]
        assert r["status"] == "failed" and r["failed_step"] == "read", (name, r)
        assert r["error"].startswith(f"{name}: read failed: {name}: {said} {text}"), r["error"]
    assert "which is not a number (a decimal comma? PLY's numbers take a point)" in \
        got["comma.ply"]["error"]
    assert got["whole.ply"]["status"] == "ok" and got["whole.ply"]["faces_in"] == 320
    assert out_files(tmp_path / "out") == ["whole_cage.obj"]


def test_a_binary_ply_of_mixed_faces_cut_short_or_with_bytes_after_them_is_named(tmp_path):
    """Faces of mixed lengths (quads and triangles, as scanners write them)
    were taken on trust: cut 5 bytes short, Blender read the last face from
    past the end (two non-manifold edges, status ok); 8 bytes appended were
    dropped silently, though the same bytes after faces of one length fail."""
    V, F = icosphere(2)
    faces = [list(f) for f in F[:-2]] + [[0, 1, 2, 3]]          # 318 triangles, 1 quad
    write_ply(tmp_path / "whole.ply", V, faces)
    data = (tmp_path / "whole.ply").read_bytes()
    (tmp_path / "cut.ply").write_bytes(data[:-5])
    (tmp_path / "tail.ply").write_bytes(data + b"\x07garbage")
    # a face with a list and a second list of texture coordinates (MeshLab's texcoord)
    head = (b"ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\n"
            b"property float y\nproperty float z\nelement face 2\nproperty list uchar int "
            b"vertex_indices\nproperty list uchar float texcoord\nend_header\n")
    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], "<f4").tobytes()
    tri = b"\x03" + np.array([0, 1, 2], "<i4").tobytes() + b"\x06" + bytes(24)
    (tmp_path / "texcoord.ply").write_bytes(head + quad + tri + tri[:-4])
    assert ply_size_problem(str(tmp_path / "whole.ply")) is None
    assert ply_size_problem(str(tmp_path / "texcoord.ply")) == (
        "texcoord.ply: its header declares 4 vertex and 2 face elements, but the file ends "
        "(324 bytes) after 1 of the 2 face elements: cut short, or a wrong count in the header")
    proc = run_batch(["cut.ply", "tail.ply", "whole.ply", "--faces", "100", "--format", "obj",
                      "--out", "out", "--report", "r.json"], tmp_path)
    cut, tail, whole = json.loads((tmp_path / "r.json").read_text())["files"]
    said = "its header declares 162 vertex and 319 face elements, but the"
    assert cut["status"] == "failed" and cut["error"] == (
        f"cut.ply: read failed: cut.ply: {said} file ends (6,263 bytes) after 318 of the 319 face "
        f"elements: cut short, or a wrong count in the header")
    assert tail["status"] == "failed" and tail["error"] == (
        "tail.ply: read failed: tail.ply: its header declares 162 vertex and 319 face elements, "
        "but 8 bytes follow them (the file is 6,276 bytes, its elements end at byte 6,268): the "
        "file holds more than its header declares (a wrong count, or data appended; Blender's "
        "importer would drop them)")
    assert whole["status"] == "ok" and whole["faces_in"] == 320 and whole["polygons_in"] == 319
    assert proc.returncode == 1 and "Traceback" not in proc.stdout + proc.stderr


def test_a_ply_header_blender_would_crash_on_is_named_and_the_batch_goes_on(tmp_path):
    """Blender's PLY importer aborted the whole batch process on 'element
    vertex' without a count (std::invalid_argument from stoi), and read
    freed memory on a property before any element (a header written
    'ELEMENT vertex 3'): 'Malloc returns null', then a segmentation fault,
    so no file after it was converted and no report written. A header past
    64 KiB (a scanner's comments) had every check skipped; a count of 10^11
    made the NaN check allocate 1 TiB (a MemoryError)."""
    V, F = icosphere(2)
    write_ply(tmp_path / "whole.ply", V, F)
    data = (tmp_path / "whole.ply").read_bytes()
    (tmp_path / "nocount.ply").write_bytes(data.replace(b"element vertex 162", b"element vertex"))
    (tmp_path / "caps.ply").write_bytes(data.replace(b"element", b"ELEMENT"))
    (tmp_path / "huge.ply").write_bytes(data.replace(b"element vertex 162",
                                                     b"element vertex 99999999999"))
    (tmp_path / "half.ply").write_bytes(data.replace(b"property float x", b"property float16 x"))
    comments = b"".join(b"comment %070d\n" % k for k in range(1200))     # 95 kB of header
    (tmp_path / "long.ply").write_bytes(data.replace(b"ply\n", b"ply\n" + comments, 1)[:-13])
    errors = errors_beside_a_whole_file(
        tmp_path, ["nocount.ply", "caps.ply", "huge.ply", "half.ply", "long.ply"], "whole.ply")
    assert errors.pop("half.ply").startswith(
        "half.ply: read failed: half.ply: header line 4, 'property float16 x', is not 'property "
        "TYPE NAME' or 'property list COUNT_TYPE ITEM_TYPE NAME' with PLY's types (char, double,")
    assert errors == {
        "nocount.ply": "nocount.ply: read failed: nocount.ply: header line 3, 'element vertex', "
                       "is not 'element NAME COUNT' with a count of 0 to 2,147,483,647",
        "caps.ply": "caps.ply: read failed: caps.ply: header line 4, 'property float x', comes "
                    "before any 'element' line (Blender's importer would crash on it)",
        "huge.ply": "huge.ply: read failed: huge.ply: header line 3, 'element vertex "
                    "99999999999', is not 'element NAME COUNT' with a count of 0 to "
                    "2,147,483,647",
        "long.ply": "long.ply: read failed: long.ply: its header declares 162 vertex and 320 "
                    "face elements, but the file ends (101,064 bytes) after 319 of the 320 face "
                    "elements: cut short, or a wrong count in the header"}


def test_an_ascii_ply_face_of_no_corners_or_more_than_255_is_named_by_its_line(tmp_path):
    """Blender's importer fails on such a face with 'Invalid face size, must
    be between 1 and 255', naming neither the line nor which face."""
    V, F = icosphere(1)                                   # 42 vertices, 80 faces
    _ascii_ply(tmp_path / "empty_face.ply", V, F, replace={42 + 7: b"0"})
    t = np.linspace(0, 2 * np.pi, 300, endpoint=False)
    ring = np.stack([np.cos(t), np.sin(t), 0 * t], axis=1)
    write_ply(tmp_path / "disk.ply", ring, [list(range(300))], ascii=True)
    assert ply_size_problem(str(tmp_path / "empty_face.ply")) == (
        "empty_face.ply: its header declares 42 vertex and 80 face elements, but the face record "
        "on line 59 ('0') is a face of 0 corners: a damaged file")
    assert ply_size_problem(str(tmp_path / "disk.ply")).endswith(
        "but the face record on line 310 ('300 0 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 18 19 "
        "20 ...') is a face of 300 corners, and Blender's PLY importer reads faces of at most "
        "255: triangulate the file's polygons first (e.g. save it as OBJ)")


def test_a_nan_vertex_after_the_faces_is_refused_not_read_as_0(tmp_path):
    """The NaN check read the vertices only when they were the file's first
    element: a file writing its faces first had its NaN read as 0 by
    Blender, status ok (ASCII and binary)."""
    V, F = icosphere(1)                                   # 42 vertices, 80 faces
    head = ("ply\nformat {} 1.0\nelement face 80\nproperty list uchar int vertex_indices\n"
            "element vertex 42\nproperty float x\nproperty float y\nproperty float z\n"
            "end_header\n")
    Vn = np.array(V, dtype="<f4")
    Vn[5, 0] = np.nan
    (tmp_path / "text.ply").write_text(head.format("ascii") + "".join(
        f"3 {a} {b} {c}\n" for a, b, c in F) + "".join(f"{x} {y} {z}\n" for x, y, z in Vn))
    (tmp_path / "binary.ply").write_bytes(head.format("binary_little_endian").encode() + b"".join(
        b"\x03" + np.asarray(f, "<i4").tobytes() for f in F) + Vn.tobytes())
    for name in ("text.ply", "binary.ply"):
        with pytest.raises(InputFileError, match=f"^{name}: 1 vertex with a coordinate that is "
                           "not a finite number"):
            check(str(tmp_path / name))
    Vn[5, 0] = 0.5
    (tmp_path / "binary.ply").write_bytes(head.format("binary_little_endian").encode() + b"".join(
        b"\x03" + np.asarray(f, "<i4").tobytes() for f in F) + Vn.tobytes())
    assert check(str(tmp_path / "binary.ply")).expected_faces == 80


def test_a_fraction_in_an_integer_vertex_property_is_read_as_blender_reads_it(tmp_path):
    """Blender reads '0.5' under 'property int x' as 0.5 (and a face index
    '1.5' not at all): only list items are held to whole numbers."""
    head = ("ply\nformat ascii 1.0\nelement vertex 3\nproperty int x\nproperty int y\n"
            "property int z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n")
    (tmp_path / "half.ply").write_text(head + "0.5 0 0\n10 0 0\n0 10.7 0\n3 0 1 2\n")
    assert ply_size_problem(str(tmp_path / "half.ply")) is None
    (tmp_path / "index.ply").write_text(head + "0.5 0 0\n10 0 0\n0 10.7 0\n3 0 1 2.5\n")
    assert "holds '2.5' in its vertex_indices list" in ply_size_problem(str(tmp_path / "index.ply"))


def test_a_comment_that_mentions_end_header_does_not_end_the_header(tmp_path):
    """'comment see end_header below' ended the header there for the checks
    (not for Blender), so none ran: the file cut short came back with only
    Blender's warning of an invalid index."""
    V, F = icosphere(2)
    write_ply(tmp_path / "ball.ply", V, F)
    data = (tmp_path / "ball.ply").read_bytes().replace(
        b"ply\n", b"ply\ncomment exported; see end_header below\n", 1)
    (tmp_path / "cut.ply").write_bytes(data[:-20])
    assert ply_size_problem(str(tmp_path / "cut.ply")) == (
        "cut.ply: its header declares 162 vertex and 320 face elements, but the file ends "
        f"({len(data) - 20:,} bytes) after 318 of the 320 face elements: cut short, or a wrong "
        "count in the header")
    (tmp_path / "whole.ply").write_bytes(data)
    assert ply_size_problem(str(tmp_path / "whole.ply")) is None
    assert check(str(tmp_path / "whole.ply")).expected_faces == 320


def test_an_ascii_ply_whose_last_records_are_blank_is_named(tmp_path):
    """Faces written as blank lines (the lines there, their numbers not)
    made the record check fail on itself ('IndexError: index -1 is out of
    bounds', as the cause)."""
    head = ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
            "property float z\nelement face 2\nproperty list uchar int vertex_indices\n"
            "end_header\n0 0 0\n1 0 0\n0 1 0\n")
    (tmp_path / "blank.ply").write_text(head + "  \n\t\n")
    (tmp_path / "one.ply").write_text(head.replace("face 2", "face 1") + "\n")
    for name, n in (("blank.ply", 2), ("one.ply", 1)):
        assert ply_size_problem(str(tmp_path / name)) == (
            f"{name}: its header declares 3 vertex and {n} face elements, but the face record "
            f"on line 13 ('') is blank: a damaged file, or one written by a tool that does not "
            f"follow PLY (Blender's importer would misread it)")


def test_a_ply_header_without_its_end_header_line_is_refused_before_blender(tmp_path):
    """'end_header' glued to the line before it ('... vertex_indicesend_header')
    ended no header for the checks, which then ran none, and Blender's
    importer read the data as header lines: a segmentation fault or an abort
    of the whole process (14 of 500 mutated headers)."""
    V, F = icosphere(1)
    write_ply(tmp_path / "ball.ply", V, F)
    data = (tmp_path / "ball.ply").read_bytes()
    (tmp_path / "glued.ply").write_bytes(data.replace(b"\nend_header", b"end_header"))
    (tmp_path / "none.ply").write_bytes(b"ply\nformat ascii 1.0\nelement vertex 3\n")
    with pytest.raises(InputFileError, match=r"^glued.ply: its header has no 'end_header' line "
                       r"\(found glued to the end of another line\): a damaged file"):
        check(str(tmp_path / "glued.ply"))
    with pytest.raises(InputFileError, match=r"^none.ply: its header has no 'end_header' line: "):
        check(str(tmp_path / "none.ply"))
    (tmp_path / "tail.ply").write_bytes(data.replace(b"end_header\n", b"end_header \r\n"))
    assert check(str(tmp_path / "tail.ply")).expected_faces == 80


def test_a_ply_of_zero_bytes_or_without_its_first_word_is_named_before_blender(tmp_path):
    """A ``.ply`` of zero bytes (a copy cut short where the file system had
    reserved its space) crashed Blender's importer: the worker died
    (SIGABRT) and the batch could only say so. Named before Blender reads it,
    as is a file that does not begin with 'ply'."""
    (tmp_path / "zeros.ply").write_bytes(bytes(100_000))
    (tmp_path / "text.ply").write_text("not a ply file\n")
    write_ply(tmp_path / "whole.ply", *icosphere(2))
    errors = errors_beside_a_whole_file(tmp_path, ["zeros.ply", "text.ply"], "whole.ply")
    assert errors["zeros.ply"].endswith("zeros.ply: not a PLY file: its first bytes are zeros (a "
                                        "copy cut short, or a file never written)")
    assert errors["text.ply"].endswith("text.ply: not a PLY file: it does not begin with 'ply'")
    for name in ("zeros.ply", "text.ply"):
        with pytest.raises(InputFileError, match="not a PLY file"):
            check(tmp_path / name)
