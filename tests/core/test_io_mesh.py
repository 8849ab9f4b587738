"""core.io_mesh: OBJ and SMF reading and writing."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import core
from core import InvalidArgumentError, InvalidMeshError
from core.triangulate import triangulate_polygons
from tests.core.test_triangulate import CONCAVE, every_loop, fans, in_3d
from tests.mesh_factory import icosphere, load_shared, tetrahedron


@pytest.mark.parametrize("ext", [".smf", ".obj"])
def test_round_trip_is_bit_exact(tmp_path, ext):
    V, F = icosphere(3)
    rng = np.random.default_rng(7)
    V = V * rng.uniform(1e-3, 1e3, size=V.shape) + rng.normal(size=V.shape) * 1e-9
    V[0] = [1e-300, -5e-324, 1.7976931348623157e308]     # extremes of float64
    path = tmp_path / f"mesh{ext}"
    core.write_mesh(path, V, F)
    m = core.read_mesh(path)
    assert m.V.dtype == np.float64 and m.F.dtype == np.int64
    assert np.array_equal(m.V.view(np.int64), V.view(np.int64))   # every bit, signed zero too
    assert np.array_equal(m.F, F)
    assert m.n_polygons == F.shape[0] and m.skipped == {}


@settings(max_examples=25, deadline=None)
@given(st.lists(st.tuples(*[st.floats(allow_nan=False, allow_infinity=False)] * 3),
                min_size=3, max_size=30))
def test_round_trip_property(tmp_path_factory, rows):
    V = np.array(rows, dtype=np.float64)
    F = np.array([[0, 1, 2], [len(rows) - 1, 0, 1]], dtype=np.int64)
    path = tmp_path_factory.mktemp("rt") / "m.smf"
    core.write_smf(path, V, F)
    V2, F2 = core.read_smf(path)
    assert np.array_equal(V2.view(np.int64), V.view(np.int64)) and np.array_equal(F2, F)


def test_smf_comments_other_keywords_and_polygons(tmp_path):
    path = tmp_path / "quad.smf"
    path.write_text("# QSlim output\nbegin\nv 0 0 0\nv 1 0 0\n\nv 1 1 0\nv 0 1 0\n"
                    "c 1 0 0\nc 0 1 0\nn 0 0 1\nf 1 2 3 4\nf 1 3 4\nend\n"
                    "set vertex_correction 0\n")
    m = core.read_mesh(path)
    assert m.V.shape == (4, 3)
    assert m.F.tolist() == [[0, 1, 2], [0, 2, 3], [0, 2, 3]]   # quad fanned, file order kept
    assert m.n_polygons == 2
    assert m.skipped == {"begin": 1, "c": 2, "n": 1, "end": 1, "set": 1}
    V, F = core.read_smf(path)
    assert np.array_equal(F, m.F)


def test_obj_with_a_byte_order_mark_keeps_its_first_vertex(tmp_path):
    """Windows Notepad saves UTF-8 with a byte-order mark: the first line's
    'v' must still read as a vertex (it read as an unknown keyword, and every
    face then pointed one vertex on)."""
    V, F = tetrahedron()
    text = "".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in V.tolist())
    text += "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in F.tolist())
    (tmp_path / "bom.obj").write_bytes(b"\xef\xbb\xbf" + text.encode())
    V2, F2 = core.read_obj(tmp_path / "bom.obj")[:2]
    assert np.array_equal(V2, V) and np.array_equal(F2, F)


def test_obj_slashes_negative_indices_and_extra_coordinates(tmp_path):
    path = tmp_path / "m.obj"
    path.write_text("o thing\nv 0 0 0 1.0\nv 1 0 0 1.0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n"
                    "f 1/1/1 2/1/1 3/1/1\nv 0 0 1\nf -4//1 -2//1 -1//1\n")
    m = core.read_mesh(path)
    assert m.F.tolist() == [[0, 1, 2], [0, 2, 3]]
    assert m.skipped == {"o": 1, "vt": 1, "vn": 1}
    V, F = core.read_obj(path)          # the old name reads the same
    assert np.array_equal(F, m.F) and V.shape == (4, 3)


@pytest.mark.parametrize("text, lineno, problem", [
    ("v 0 0 0\nv 1 x 3\nv 0 1 0\nf 1 2 3\n", 2, r"'v 1 x 3' is not a number"),
    ("v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n", 3, r"'v nan 1 0' has a coordinate that is not"),
    ("v 0 0 0\nv 1 0 inf\nv 0 1 0\nf 1 2 3\n", 2, r"'v 1 0 inf' .*not a finite number"),
    # a scan's leftover point: the line says no face uses it; of several, a used one is named
    ("v nan nan nan\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 2 3 4\n", 1,
     r"'v nan nan nan' has a coordinate that is not a finite number \(none used by a face"),
    ("v nan 0 0\nv 0 0 0\nv 1 0 0\nv 0 1 inf\nf 2 3 4\n", 4,
     r"'v 0 1 inf' .*finite number \(one of 2 such vertices, 1 used by faces\)$"),
    ("v 0 0\n", 1, r"'v 0 0' needs 3 coordinates"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\n# comment\nf 1 2 9\n", 5,
     r"'f 1 2 9' refers to a missing vertex \(the file has 3\)"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", 4, r"'f 0 1 2' has vertex index 0 \(indices are 1-based\)"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", 4, r"'f 1 2' needs at least 3 vertices"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3.5\n", 4, r"'f 1 2 3\.5' has an index that is not an integer"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3 99\n", 5, r"'f 1 2 3 99' refers to a missing vertex \(the file has 4\)"),
    # beyond 64 bits (NumPy's bare OverflowError before)
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 99999999999999999999999\n", 5,
     r"'f 1 2 99999999999999999999999' refers to a missing vertex \(the file has 3\)"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 -99999999999999999999 3 2\n", 4,
     r"'f 1 -99999999999999999999 3 2' refers to a missing vertex \(the file has 3\)"),
    # digits of other scripts, which Python's numbers take (read as 1, 2, 3 before)
    ("v 0 0 0\nv \u0661 \u0662 \u0663\nv 0 1 0\nf 1 2 3\n", 2,
     r"'v \u0661 \u0662 \u0663' is not a number"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf \uff11 2 3\n", 4,
     r"'f \uff11 2 3' has an index that is not an integer"),
])
def test_bad_lines_are_named(tmp_path, text, lineno, problem):
    path = tmp_path / "scan.smf"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(InvalidMeshError, match=rf"^read_smf: .*scan\.smf line {lineno}: {problem}"):
        core.read_smf(path)
    obj = tmp_path / "scan.obj"
    obj.write_text(text, encoding="utf-8")
    with pytest.raises(InvalidMeshError, match=rf"^read_obj: .*scan\.obj line {lineno}: "):
        core.read_mesh(obj)


@pytest.mark.parametrize("ext", [".obj", ".smf"])
def test_lines_starting_with_no_keyword_are_counted_as_unreadable(tmp_path, ext):
    """NUL bytes, binary garbage and lines cut short were counted as keywords
    ('\\x00\\x00': 1, '1': 1 in the skipped report); they are counted apart,
    with the first one's line number, by the bulk and the line reader alike."""
    from core import io_mesh
    text = (_BASE + "vt 0 0\n\x00\x00\x00\x00\n1 2 3\nf 1 2 3\n").encode() + (
        b"\x01\xff\xfe garbage\nusemtl M\nv\x00 1 2 3\n%s 1\nshadow_obj x.obj\nK9_ 1\n"
        % (b"k" * 17))
    path = tmp_path / f"junk{ext}"
    path.write_bytes(text)
    for m in (core.read_mesh(path), io_mesh._read_bulk(text, ext == ".obj"),
              io_mesh._read_lines(str(path), "read_mesh", ext == ".obj")):
        assert m.skipped == {"vt": 1, "usemtl": 1, "shadow_obj": 1, "K9_": 1}
        assert (m.n_unreadable, m.first_unreadable) == (5, 6)
        assert m.F.tolist() == [[0, 1, 2]] and m.V.shape == (4, 3)
    clean = tmp_path / f"clean{ext}"
    clean.write_text(_BASE + "f 1 2 3\n")
    assert core.read_mesh(clean)[4:] == (0, 0)
    only = tmp_path / f"only{ext}"
    only.write_bytes(b"\x00\x00\nxyz\n")
    with pytest.raises(InvalidMeshError, match=r"has no 'v' or 'f' line \(2 other lines\)"):
        core.read_mesh(only)


def test_unsupported_extension_and_bad_arrays(tmp_path):
    with pytest.raises(InvalidArgumentError, match=r"read_mesh: .*scan\.ply: unsupported "
                                                   r"extension '\.ply' \(use \.obj or \.smf\)"):
        core.read_mesh(tmp_path / "scan.ply")
    V, F = tetrahedron()
    with pytest.raises(InvalidArgumentError, match="write_mesh"):
        core.write_mesh(tmp_path / "x.stl", V, F)
    with pytest.raises(InvalidMeshError, match=r"write_smf: F must be \(m,3\) integers"):
        core.write_smf(tmp_path / "x.smf", V, F.astype(float))
    with pytest.raises(InvalidMeshError, match="write_smf: 3 faces index vertices outside \\[0, 4\\), e.g. face 1"):
        core.write_smf(tmp_path / "x.smf", V, F + 1)


def test_a_path_is_a_file_name_of_any_kind_python_takes(tmp_path):
    """A bytes path was refused by read_mesh and write_mesh ("unsupported
    extension 'b'.obj''") where read_obj took it; None or a number was
    Python's TypeError. A file that cannot be opened is Python's own OSError."""
    V, F = tetrahedron()
    path = bytes(tmp_path / "tet.obj")
    core.write_mesh(path, V, F)
    assert np.array_equal(core.read_mesh(path).V, V) and np.array_equal(core.read_obj(path)[1], F)
    for call in (lambda: core.read_mesh(None), lambda: core.write_obj(3, V, F),
                 lambda: core.read_smf(["tet.smf"])):
        with pytest.raises(InvalidArgumentError, match=r"^(read_mesh|write_obj|read_smf): "
                           r"path must be a file name \(str or os\.PathLike\)"):
            call()
    with pytest.raises(FileNotFoundError):
        core.read_mesh(tmp_path / "missing.obj")


def test_empty_file(tmp_path):
    path = tmp_path / "empty.smf"
    path.write_text("# nothing\n")
    m = core.read_mesh(path)
    assert m.V.shape == (0, 3) and m.F.shape == (0, 3) and m.n_polygons == 0


def test_real_mesh_through_smf(tmp_path):
    V, F = load_shared("cow.obj")
    core.write_smf(tmp_path / "cow.smf", V, F)
    V2, F2 = core.read_smf(tmp_path / "cow.smf")
    assert np.array_equal(V2, V) and np.array_equal(F2, F) and F.shape == (5804, 3)


_BASE = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n"
#: files the bulk reader reads itself (it must agree with the line reader bit for bit)
_BULK = [_BASE + "f 1 2 3\nf 2 4 3\n", (_BASE + "f 1 2 3\n").replace("\n", "\r\n"),
         "\ufeff" + _BASE + "f 1 2 3\n", _BASE + "f 1 2 3", _BASE + "v 2 2 0\nf 1 2 4 5 3\n",
         _BASE + "f 1/1/1 2/2/2 3/3/3 4/4/4\n", _BASE + "f 1//1 2//2 3//3\n",
         _BASE + "f 1 2 3\nv 5 5 5\nf -1 -2 -3\n",
         _BASE + "vt 0 0\nvn 0 0 1\no thing\ng grp\ns off\nusemtl M\u00e4t\nf 1 2 3\n",
         "v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0 1\nf 1 2 3\n", "# c\n\n" + _BASE + "\n\n",
         "v\t0\t0\t0  \nv +1 -0 .5\nv 1. 0e0 0\nf\t1 2  3 \n",
         # v/vt/vn words of every form, cut at their first "/" up to any separator
         _BASE + "f 1/2/3\t2/x/y\x0b3// 4/\nf -1/1 2 -2//-7\f3/1/1/1\n",
         # lines starting with no keyword: skipped as unreadable
         _BASE + "f 1 2 3\n\x00\n", _BASE + "1 2 3\nv\x00 1 2 3\n\x00\x00\x00\nf 1 2 3\n",
         "v 0 0 0\n%s 1\n{ }\nv 1 0 0\nv 0 1 0\nf 1 2 3\n3ds max\n" % ("k" * 17),
         "v 0 0 0\n-1 \u00e4\nv 1 0 0\nv 0 1 0\nf 1 2 3\n%s\n" % ("k" * 16),
         # a concave quad whose fan folds, ear-clipped in both
         _BASE + "v .25 .25 0\nf 2 5 3 1\nf 2/1 -1/1 3/1 1/1\n"]
#: files it leaves to the line reader (which reads them or names the line)
_LINES = ["  v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", _BASE + "f 1 2\n", _BASE + "f 1 2 5\n",
          _BASE + "f 0 1 2\n", _BASE + "f 1 2 3.5\n", _BASE + "f 1_0 2 3\n",
          "v 0 0 nan\n" + _BASE + "f 1 2 3\n", "v 0 0 0 # c\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
          "v 0 0\r0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "v 0 0 0\nv 1\u00a00 0\nv 0 1 0\nf 1 2 3\n",
          _BASE + "f 99999999999999999999 1 2\n", "", "# only\n",
          # found by a differential fuzz of the two readers (2026-12-05): a word "/1", a
          # no-break space inside a v/vt/vn word, a last line of just "v"
          _BASE + "f 1/1 /1 2 3\n", _BASE + "f 1/\u00a01 2//2 3//3\n", _BASE + "f 1 2 3\nv",
          # (a CLI fuzz: control bytes 0x1c-0x1f separate words in text mode)
          _BASE + "f 1/1\x1c2/2 3/3 4/4\n", _BASE + "f 1 2 3/1\x1f-4\n",
          # a control byte that separates no words (the line reader keeps it in the word)
          _BASE + "f 1/1\x01 2 3\n", _BASE + "f 1\x01/1 2 3\n",
          # a first word with a byte outside ASCII where a keyword may end (a no-break space?)
          _BASE + "x\u00e4 1\nf 1 2 3\n", _BASE + "%s\u00a0\nf 1 2 3\n" % ("k" * 16)]


@pytest.mark.parametrize("text", _BULK + _LINES)
@pytest.mark.parametrize("obj", [True, False])
def test_the_bulk_reader_agrees_with_the_line_reader_or_leaves_the_file_to_it(
        tmp_path, text, obj):
    from core import io_mesh
    path = tmp_path / ("m.obj" if obj else "m.smf")
    path.write_bytes(text.encode())
    fn = "read_obj" if obj else "read_smf"

    def outcome(read):
        try:
            return read(str(path), fn, obj)
        except InvalidMeshError as exc:
            return str(exc)
    bulk = io_mesh._read_bulk(path.read_bytes(), obj)
    faces = " ".join(line for line in text.splitlines() if line.startswith("f"))
    smf_too = "/" not in faces and "-" not in faces     # (SMF: no v/vt/vn, no relative index)
    assert (bulk is not None) == (text in _BULK and (obj or smf_too))
    got, want = outcome(io_mesh._read), outcome(io_mesh._read_lines)
    if isinstance(want, str):
        assert got == want
    else:
        assert np.array_equal(got.V.view(np.int64), want.V.view(np.int64))
        assert np.array_equal(got.F, want.F) and got.F.dtype == np.int64
        assert (got.n_polygons, got.skipped) == (want.n_polygons, want.skipped)


def test_shared_meshes_and_written_files_are_read_in_bulk(tmp_path):
    # (the bulk reader is the one that runs: a 1.1M-face OBJ in about 1 s, 4 s line by line)
    from core import io_mesh
    V, F = icosphere(4)
    core.write_obj(tmp_path / "w.obj", V * 1.234567e-3, F)
    paths = [tmp_path / "w.obj"] + [p for p in (_shared(n) for n in ("spot.obj", "fandisk.obj"))
                                    if p is not None]
    for p in paths:
        bulk = io_mesh._read_bulk(open(p, "rb").read(), True)
        lines = io_mesh._read_lines(str(p), "read_obj", True)
        assert bulk is not None and np.array_equal(bulk.V, lines.V)
        assert np.array_equal(bulk.F, lines.F) and bulk.skipped == lines.skipped


def _shared(name):
    from tests.mesh_factory import SHARED_MESHES
    import os
    path = os.path.join(SHARED_MESHES, name)
    return path if os.path.exists(path) else None


@pytest.mark.parametrize("name", sorted(CONCAVE))
@pytest.mark.parametrize("ext", [".obj", ".smf"])
def test_concave_polygons_are_triangulated_without_folds(tmp_path, name, ext):
    """A concave polygon was fanned from its first vertex into overlapping,
    flipped triangles; a file's polygons, from every first vertex and both
    windings, give the triangles of ``triangulate_polygons`` (ear-clipped
    where the fan folds: tested in test_triangulate.py), by the bulk and the
    line reader alike."""
    from core import io_mesh
    X = in_3d(np.array(CONCAVE[name], dtype=np.float64))
    loops = every_loop(len(X))
    text = "".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in X.tolist())
    text += "".join("f " + " ".join(str(i + 1) for i in loop) + "\n" for loop in loops)
    path = tmp_path / f"{name}{ext}"
    path.write_text(text)
    m = core.read_mesh(path)
    lines = io_mesh._read_lines(str(path), "read_mesh", ext == ".obj")
    assert io_mesh._read_bulk(path.read_bytes(), ext == ".obj") is not None
    F, sizes = fans(loops)
    T = triangulate_polygons(X, F, sizes)
    assert np.array_equal(m.V, X) and m.n_polygons == len(loops)
    assert np.array_equal(m.F, lines.F) and np.array_equal(m.F, T) and not np.array_equal(T, F)


def test_obj_line_continuations_and_comments_after_the_numbers(tmp_path):
    """A backslash at a line's end continues it on the next, and a '#' after
    a 'v' or 'f' line's numbers starts a comment, as the OBJ specification
    and Blender's importer have them (found by a fuzz of the readers: both
    failed, 'f 1 2 \\' has an index that is not an integer; CRLF too)."""
    V, F = icosphere(1)
    quads = [[0, 11, 5, 1]]                          # one polygon continued over two lines
    plain = "".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in V.tolist())
    plain += "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in F)
    plain += "".join("f " + " ".join(str(i + 1) for i in q) + "\n" for q in quads)
    (tmp_path / "plain.obj").write_text(plain)
    text = "".join(f"v {x!r} \\\n {y!r} {z!r} # vertex {k}\n" for k, (x, y, z) in
                   enumerate(V.tolist()))
    text += "".join(f"f {a + 1}/1 {b + 1}/1 \\\n{c + 1}/1 # a tri\n" for a, b, c in F)
    text += "".join("f " + " ".join(str(i + 1) for i in q[:2]) + " \\\n" +
                    " ".join(str(i + 1) for i in q[2:]) + "\n" for q in quads)
    want = core.read_mesh(tmp_path / "plain.obj")
    for name, data in (("cont.obj", text), ("crlf.obj", text.replace("\n", "\r\n"))):
        (tmp_path / name).write_bytes(data.encode())
        m = core.read_mesh(tmp_path / name)
        assert np.array_equal(m.V, want.V) and np.array_equal(m.F, want.F), name
        assert m.n_polygons == want.n_polygons == len(F) + 1 and m.skipped == {}, name
    # a comment right after a slash ends the face there too, in bulk as line by line
    (tmp_path / "hash.obj").write_text(plain + "f 1/1# 2 3\n")
    with pytest.raises(InvalidMeshError, match=r"line 124: 'f 1/1# 2 3' needs at least 3"):
        core.read_mesh(tmp_path / "hash.obj")
    # a bad index on a continued line is named by the line it starts on
    (tmp_path / "bad.obj").write_text(plain + "f 1 2 \\\n x\n")
    with pytest.raises(InvalidMeshError, match=r"line 124: 'f 1 2 \\' has an index that is not"):
        core.read_mesh(tmp_path / "bad.obj")
