"""The batch tool's Blender side: PLY, STL and glTF through Blender's own
importers and exporters, with Blender's log kept out of our stdout.

Blender's importers print to the process's file descriptors 1 and 2 from C
(``io.ply | ERROR PLY Importer: ... Could not read row of ASCII property``,
``OBJ import of 'x.obj' took 0.20 ms``) and report only ``failed importing,
unknown error`` to Python. :func:`captured_output` points both descriptors at
a temporary file while Blender runs, so the text can go to ``--log`` or the
report, and an importer's error is quoted with the cause from its log.

Blender's importers also repair silently: a face that indexes a missing
vertex is dropped, a NaN coordinate becomes 0. OBJ and SMF therefore never
come here (the core's reader refuses them, naming the line); PLY and STL
coordinates are checked in the file before Blender reads it, and the face
count in the file's header is compared with what was imported.
"""

import contextlib
import ctypes
import os
import re
import shutil
import struct
import sys
import tempfile

#: formats that need Blender, and the importer / exporter of each
BLENDER_IMPORT = {".ply": "PLY", ".stl": "STL", ".gltf": "glTF", ".glb": "glTF"}
BLENDER_EXPORT = {"ply", "stl", "glb"}
#: a binary STL file: an 80-byte header and a little-endian uint32 triangle count, then
#: 50 bytes a triangle (normal, three corners: 12 float32, and a uint16)
STL_HEAD, STL_TRIANGLE = 84, 50
_TEXT = frozenset(range(32, 127)) | {9, 10, 12, 13}    #: the bytes of an ASCII STL file
_LOG_LIMIT = 20_000    #: characters of Blender's log kept per file
_LOG_PREFIX = re.compile(r"^\s*\d+:\d+\.\d+\s+\S+\s+\|\s*")
_TIMING = re.compile(r"(import|export) of .* took ")


class BlenderIOError(Exception):
    """Blender's importer or exporter failed; the message quotes its log."""


def _libc_flush():
    """Flush C stdio buffers (Blender's printf) before a descriptor moves."""
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):   # no libc symbols (not Linux/macOS)
        pass


class Capture:
    """Text written to descriptors 1 and 2 inside :func:`captured_output`."""

    def __init__(self):
        self.text = ""

    def explain(self, failure):
        """``failure`` with what the log adds, quoted: ``' (Blender's log:
        "...")'`` (at most 400 characters of it), or nothing."""
        causes = self.causes(failure)
        return f"{failure} (Blender's log: \"{'; '.join(causes)[:400]}\")" if causes else failure

    def causes(self, failure):
        """What the log says besides ``failure`` and timings: its lines
        without the time stamp and channel Blender's log puts first
        (``00:00.372  io.ply  | ``)."""
        lines = (_LOG_PREFIX.sub("", ln).strip() for ln in self.text.splitlines())
        return [ln for ln in dict.fromkeys(lines)
                if ln and ln not in failure and not _TIMING.search(ln)]


@contextlib.contextmanager
def captured_output(sink):
    """Send descriptors 1 and 2 to a temporary file; append its text to
    ``sink`` (a list of str) and yield a :class:`Capture` holding it."""
    cap = Capture()
    sys.stdout.flush()
    sys.stderr.flush()
    _libc_flush()
    saved = os.dup(1), os.dup(2)
    with tempfile.TemporaryFile(mode="w+b") as tmp:
        os.dup2(tmp.fileno(), 1)
        os.dup2(tmp.fileno(), 2)
        try:
            yield cap
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            _libc_flush()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])
            tmp.seek(0)
            cap.text = tmp.read(4 * _LOG_LIMIT).decode("utf-8", "replace")
            if cap.text:
                sink.append(cap.text)


def _bpy(log):
    """The bpy module (imported with its start-up chatter captured)."""
    if "bpy" not in sys.modules:
        with captured_output(log):
            try:
                import bpy  # noqa: F401
            except ImportError:
                raise BlenderIOError("this format needs Blender (the bpy module, e.g. "
                                     "`pip install bpy==5.0.1` on Python 3.11, or run inside "
                                     "blender -b -P); OBJ and SMF need only NumPy") from None
    return sys.modules["bpy"]


def _mesh_io():
    from ..meshadjust_addon import mesh_io   # imports bpy: only here
    return mesh_io


_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2",
              "int16": "i2", "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4",
              "uint": "u4", "uint32": "u4", "float": "f4", "float32": "f4", "double": "f8",
              "float64": "f8"}


def _ply_header(path):
    """``(format, header length in bytes, [(element, count, [(type, name)])])``
    of a PLY file (a list property's type is ``("list", count type, item
    type)``), or None."""
    with open(path, "rb") as fh:
        head = fh.read(1 << 16)
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0:
        return None
    length = head.index(b"\n", end) + 1
    fmt, elements = None, []
    for line in head[:end].decode("ascii", "replace").splitlines():
        parts = line.split()
        if parts[:1] == ["format"] and len(parts) > 1:
            fmt = parts[1]
        elif parts[:1] == ["element"] and len(parts) == 3 and parts[2].isdigit():
            elements.append((parts[1], int(parts[2]), []))
        elif parts[:1] == ["property"] and elements and len(parts) >= 3:
            kind = tuple(parts[1:4]) if parts[1] == "list" and len(parts) == 5 else parts[1]
            elements[-1][2].append((kind, parts[-1]))
    return fmt, length, elements


def stl_triangle_counts(path):
    """``(in_header, by_size)`` triangle counts of a binary STL file, None for
    an ASCII one (a size that is not ``84 + 50 * count``, and text).

    Blender's importer reads a file as binary only when its size is exactly
    ``84 + 50 * count`` and as ASCII otherwise, so a binary file with a wrong
    count came back as "no mesh with faces". Here a count of 0 with a size of
    whole triangles (an exporter that left the field blank) gives the
    triangles the size holds (``in_header`` 0, ``by_size`` k: read a copy
    with k written in, :func:`_with_count`); any other disagreement raises
    :class:`BlenderIOError` naming the file, the header's count and the
    count its size implies."""
    with open(path, "rb") as fh:
        head = fh.read(1024)
        size = os.fstat(fh.fileno()).st_size
    count = struct.unpack("<I", head[80:84])[0] if size >= STL_HEAD else None
    if count is not None and size == STL_HEAD + STL_TRIANGLE * count:
        return count, count                      # binary, as Blender's importer decides
    if head and set(head) <= _TEXT:
        return None
    name = os.path.basename(path)
    if count is None:
        raise BlenderIOError(f"{name}: {size:,} bytes, neither ASCII STL nor a binary STL file "
                             f"(at least {STL_HEAD} bytes of header and triangle count)")
    by_size, extra = divmod(size - STL_HEAD, STL_TRIANGLE)
    if extra:
        raise BlenderIOError(
            f"{name}: a binary STL file of {size:,} bytes, which is no whole number of triangles "
            f"({STL_HEAD} bytes of header and count, then {STL_TRIANGLE} a triangle; its header "
            f"says {count:,}): cut short or damaged")
    if count not in (by_size, 0):
        raise BlenderIOError(
            f"{name}: the header of this binary STL file says {count:,} triangles, but its size "
            f"({size:,} bytes) holds {by_size:,} ({STL_HEAD} bytes of header and count, then "
            f"{STL_TRIANGLE} a triangle): cut short, or a wrong count")
    return count, by_size


@contextlib.contextmanager
def _with_count(path, counts):
    """``path``, or when its STL header's triangle count is blank
    (:func:`stl_triangle_counts` ``counts``) a temporary copy of the same name
    with the count its size implies written in (the file itself is never changed)."""
    if counts is None or counts[0] == counts[1]:
        yield path
        return
    with tempfile.TemporaryDirectory(prefix="meshadjust-stl-") as folder:
        copy = os.path.join(folder, os.path.basename(path))
        shutil.copyfile(path, copy)
        with open(copy, "r+b") as fh:
            fh.seek(80)
            fh.write(struct.pack("<I", counts[1]))
        yield copy


def header_face_count(path):
    """Faces the file says it holds (PLY header, STL count: for a binary STL
    whose count is blank, what its size holds), or None."""
    ext = os.path.splitext(path)[1].lower()
    try:
        if ext == ".ply":
            header = _ply_header(path)
            counts = {name: n for name, n, _ in header[2]} if header else {}
            return counts.get("face")
        if ext == ".stl":
            counts = stl_triangle_counts(path)
            if counts is not None:
                return counts[1]                                      # binary STL
            with open(path, "rb") as fh:
                return sum(line.lstrip().startswith(b"facet") for line in fh)
    except OSError:
        return None
    return None


def ply_size_problem(path):
    """Why a PLY file cannot hold what its header declares, in words that name
    the file and the counts (a file cut short, or a count too large), or None.

    Blender's importer reads such a file on: it takes the next element's
    bytes for this one's and fails with "Invalid face size, must be between 1
    and 255", or reads past the end and keeps what it could with a warning per
    bad index. Checked here, before Blender: ASCII, a line per element;
    binary, the bytes of each fixed-size element and of an element with one
    list property (faces) whose records all have the first one's length (all
    triangles, all quads), and for mixed records at least 3 indices a face
    (1 item a record of another list) and a first record that is a face (a
    count of 1-255, indices of declared vertices)."""
    header = _ply_header(path)
    if not header or not header[2]:
        return None
    fmt, length, elements = header
    size = os.path.getsize(path)
    name = os.path.basename(path)
    declared = " and ".join(f"{n:,} {e}" for e, n, _ in elements)
    if fmt == "ascii":
        lines = _ascii_lines(path, length)
        need = sum(n for _, n, _ in elements)
        if lines < need:
            return (f"{name}: its header declares {declared} elements, a line each ({need:,}), "
                    f"but the file has {lines:,} lines after its header: cut short, or a wrong "
                    f"count in the header")
        return None
    order = {"binary_little_endian": "<", "binary_big_endian": ">"}.get(fmt)
    if order is None or any(not _known_ply_type(t) for _, _, props in elements for t, _ in props):
        return None
    pos = length
    n_vertices = {e: n for e, n, _ in elements}.get("vertex", 2**63 - 1)
    for element, count, props in elements:
        layout = _ply_records(path, order, props, pos, count, size, n_vertices,
                              element == "face")
        if layout is None:
            return None          # records of mixed lengths, no sign of a problem
        got, end, bad_first = layout
        if bad_first:
            return (f"{name}: its header declares {declared} elements, but the first {element} "
                    f"record (at byte {pos:,}) holds no valid {element}: the data before it is "
                    f"not the size the header's counts give (a wrong count), or the file is "
                    f"damaged")
        if got is None or got < count:
            where = (f"before its {count:,} {element} elements" if got is None else
                     f"after {got:,} of the {count:,} {element} elements")
            return (f"{name}: its header declares {declared} elements, but the file ends "
                    f"({size:,} bytes) {where}: cut short, or a wrong count in the header")
        pos = end
    return None


def _known_ply_type(t):
    return t in _PLY_TYPES or (isinstance(t, tuple) and t[1] in _PLY_TYPES and t[2] in _PLY_TYPES)


def _ascii_lines(path, start):
    """Lines of a text file after its first ``start`` bytes (a last line
    without a newline counted)."""
    import numpy as np
    data = np.memmap(path, dtype=np.uint8, mode="r") if os.path.getsize(path) else np.zeros(0, np.uint8)
    body = data[start:]
    return int(np.count_nonzero(body == 10)) + int(body.size > 0 and body[-1] != 10)


def _ply_records(path, order, props, pos, count, size, n_vertices, face):
    """``(whole records in the file or None when unknown, end byte, first
    record invalid)`` of a binary PLY element of ``count`` records at byte
    ``pos`` (see :func:`ply_size_problem`; ``n_vertices``: the vertices
    declared, bounding a face's indices; ``face``: the element is the faces,
    whose records hold at least 3 indices); None for records of mixed
    lengths that the file may hold."""
    import numpy as np
    itemsize = {t: np.dtype(_PLY_TYPES[t]).itemsize for t in _PLY_TYPES}
    lists = [k for k, (t, _) in enumerate(props) if isinstance(t, tuple)]
    if not lists:
        rec = sum(itemsize[t] for t, _ in props)
        return (min(count, (size - pos) // rec) if rec else count), pos + count * rec, False
    if count == 0:
        return 0, pos, False
    if len(lists) > 1:
        return None
    k = lists[0]
    before = sum(itemsize[t] for t, _ in props[:k])
    after = sum(itemsize[t] for t, _ in props[k + 1:])
    _, ct, it = props[k][0]
    at = pos + before + itemsize[ct]                    # the first record's indices
    if at > size:
        return 0, pos, False
    data = np.memmap(path, dtype=np.uint8, mode="r")
    c0 = int(np.frombuffer(data, dtype=order + _PLY_TYPES[ct], count=1, offset=at - itemsize[ct])[0])
    first = np.frombuffer(data, dtype=order + _PLY_TYPES[it], offset=at,
                          count=max(0, min(c0, (size - at) // itemsize[it])))
    if not 1 <= c0 <= 255 or (first.size and (first.min() < 0 or first.max() >= n_vertices)):
        return 0, pos, True
    rec = before + itemsize[ct] + c0 * itemsize[it] + after
    fits = min(count, (size - pos) // rec)
    counts = np.frombuffer(data, offset=pos, count=fits, dtype=np.dtype(
        {"names": ["c"], "formats": [order + _PLY_TYPES[ct]], "offsets": [before],
         "itemsize": rec}))["c"]
    # the least a record can be: a face has 3 corners, another list 1 item
    least = before + itemsize[ct] + (3 if face else 1) * itemsize[it] + after
    if (counts == c0).all():
        if fits == count:
            return fits, pos + count * rec, False
        if pos + fits * rec + (count - fits) * least > size:   # short even if the rest were least
            return fits, pos + count * rec, False
        return None
    return (None, pos, False) if pos + count * least > size else None


def grouped_warnings(lines):
    """Blender's warnings, one per kind: lines that differ only in their
    numbers (``Invalid PLY vertex index in face 5856 loop 7``, ``... face
    5857 loop 9``) as the first of them and how many more there were."""
    kinds = {}
    for line in lines:
        kinds.setdefault(re.sub(r"\d+", "#", line), []).append(line)
    return [f"{same[0][:200]}" + (f" (and {len(same) - 1:,} more like it)" if len(same) > 1 else "")
            for same in kinds.values()]


def count_nonfinite(path):
    """Vertices (PLY) or facets (STL) with a coordinate that is NaN or
    infinite, read from the file itself (Blender's importers turn those into
    0); None when the layout is not one read here (vertices not the first
    PLY element, list properties on them)."""
    import numpy as np
    ext = os.path.splitext(path)[1].lower()
    if ext == ".stl":
        counts = stl_triangle_counts(path)
        if counts is not None:
            rec = np.dtype([("normal", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
            v = np.fromfile(path, dtype=rec, count=counts[1], offset=STL_HEAD)["v"]
            return int((~np.isfinite(v).all(axis=(1, 2))).sum())
        with open(path, "rb") as fh:
            rows = [ln.split()[1:4] for ln in fh if ln.lstrip().startswith(b"vertex")]
        try:
            V = np.array(rows, dtype=np.float64).reshape(-1, 3)
        except ValueError:
            return None
        return int((~np.isfinite(V).all(axis=1).reshape(-1, 3).all(axis=1)).sum()) \
            if V.shape[0] % 3 == 0 else None
    header = _ply_header(path) if ext == ".ply" else None
    if not header or not header[2] or header[2][0][0] != "vertex":
        return None
    fmt, length, ((_, n, props), *_) = header
    if any(t not in _PLY_TYPES for t, _ in props) or not {"x", "y", "z"} <= {p for _, p in props}:
        return None
    if fmt == "ascii":
        with open(path, "rb") as fh:
            fh.seek(length)
            rows = [fh.readline().split() for _ in range(n)]
        try:
            table = np.array(rows, dtype=np.float64).reshape(n, len(props))
        except ValueError:
            return None
        cols = [k for k, (_, name) in enumerate(props) if name in ("x", "y", "z")]
        return int((~np.isfinite(table[:, cols]).all(axis=1)).sum())
    order = {"binary_little_endian": "<", "binary_big_endian": ">"}.get(fmt)
    if order is None:
        return None
    rec = np.dtype([(name, order + _PLY_TYPES[t]) for t, name in props])
    table = np.fromfile(path, dtype=rec, count=n, offset=length)
    if table.shape[0] < n:
        return None     # truncated: the importer says so
    xyz = np.stack([table[c].astype(np.float64) for c in ("x", "y", "z")], axis=1)
    return int((~np.isfinite(xyz).all(axis=1)).sum())


def _failure_of(op):
    """Run a Blender operator; its error on one line, or None."""
    try:
        op()
    except RuntimeError as exc:
        return " ".join(str(exc).split())
    return None


def import_mesh(path, log=None):
    """Import ``path`` with Blender's importer into the current scene and
    return one mesh object (several meshes in the file are joined).

    Raises :class:`BlenderIOError` quoting the importer's own log when it
    fails, and ``FileNotFoundError`` for a missing file."""
    log = [] if log is None else log
    bpy = _bpy(log)
    ext = os.path.splitext(path)[1].lower()
    name = os.path.basename(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"no such file: {path}")
    ops = {".obj": bpy.ops.wm.obj_import, ".ply": bpy.ops.wm.ply_import,
           ".stl": bpy.ops.wm.stl_import, ".gltf": bpy.ops.import_scene.gltf,
           ".glb": bpy.ops.import_scene.gltf}
    if ext not in ops:
        raise BlenderIOError(f"{name}: unsupported file type '{ext}'")
    counts = stl_triangle_counts(path) if ext == ".stl" else None
    before = set(bpy.data.objects)
    with _with_count(path, counts) as source, captured_output(log) as cap:
        failure = _failure_of(lambda: ops[ext](filepath=source))
    if failure is not None:
        raise BlenderIOError(f"Blender's importer failed on {name}: {cap.explain(failure)}")
    meshes = [o for o in bpy.data.objects if o not in before and o.type == 'MESH'
              and len(o.data.polygons)]
    if not meshes:
        raise BlenderIOError(f"{name}: no mesh with faces in the file")
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    for o in meshes:
        o.select_set(True)
    bpy.context.view_layer.objects.active = meshes[0]
    if len(meshes) > 1:
        with captured_output(log):
            bpy.ops.object.join()
    return bpy.context.view_layer.objects.active


def _empty_scene(log):
    """Blender's module (:func:`_bpy`) with an empty scene loaded."""
    bpy = _bpy(log)
    with captured_output(log):
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    return bpy


def read_with_blender(path, log):
    """``(V, F, n_polygons, notes, warnings)`` of a file read by Blender's
    importer into an empty scene; ``notes`` says when a binary STL's blank
    triangle count was taken from its size, ``warnings`` names faces the
    importer dropped and quotes the warnings in its log. A binary STL whose
    count disagrees with its size otherwise raises :class:`BlenderIOError`
    (:func:`stl_triangle_counts`), before Blender is loaded."""
    bad = count_nonfinite(path) if os.path.isfile(path) else None
    if bad:
        what = (("vertex", "vertices") if path.lower().endswith(".ply") else
                ("facet", "facets"))[bad != 1]
        raise BlenderIOError(f"{os.path.basename(path)}: {bad:,} {what} with a coordinate that "
                             f"is not a finite number (NaN or infinity; Blender's importer would "
                             f"read them as 0)")
    problem = ply_size_problem(path) if path.lower().endswith(".ply") and os.path.isfile(path) \
        else None
    if problem:
        raise BlenderIOError(problem)
    _empty_scene(log)
    obj = import_mesh(path, log)
    arrays = _mesh_io().read_object(obj)
    # in the file's (world) space: a glTF node's transform is applied
    M = [list(row) for row in obj.matrix_world]
    V = arrays.V
    if M != [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0],
             [0.0, 0.0, 0.0, 1.0]]:
        import numpy as np
        M = np.array(M)
        V = V @ M[:3, :3].T + M[:3, 3]
    notes, warnings = [], []
    counts = stl_triangle_counts(path) if path.lower().endswith(".stl") else None
    if counts is not None and counts[0] != counts[1]:
        notes.append(f"the binary STL header's triangle count is 0 (left blank by its "
                     f"exporter?): read the {counts[1]:,} triangles its size holds")
    expected = header_face_count(path)
    if expected is not None and arrays.n_polygons < expected:
        warnings.append(f"Blender's {BLENDER_IMPORT.get(os.path.splitext(path)[1].lower())} "
                        f"importer kept {arrays.n_polygons:,} of the file's {expected:,} faces")
    for line in grouped_warnings(_LOG_PREFIX.sub("", x).strip()
                                 for x in "".join(log).splitlines() if "WARNING" in x):
        warnings.append(f"Blender: {line}")
    return V, arrays.F, arrays.n_polygons, notes, warnings


def write_with_blender(path, V, F, log, name):
    """Write a triangle mesh with Blender's exporter chosen by the extension
    (``.ply``, ``.stl`` or ``.glb``), its object and mesh named ``name``
    (formats that store names, as glTF does, keep it: not the path's, which
    may be a temporary one)."""
    # an empty scene, as for reading: the view layer of a scene whose objects an
    # earlier write removed can still list them (None, or a crash when touched:
    # a PLY input with --refine failed writing the refined mesh, or segfaulted)
    bpy = _empty_scene(log)
    fmt = os.path.splitext(path)[1].lower()
    mesh = _mesh_io().new_mesh(name, V, F)
    obj = bpy.data.objects.new(mesh.name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    try:
        exporters = {".ply": lambda: bpy.ops.wm.ply_export(filepath=path,
                                                            export_selected_objects=True),
                     ".stl": lambda: bpy.ops.wm.stl_export(filepath=path,
                                                            export_selected_objects=True)}
        gltf = lambda: bpy.ops.export_scene.gltf(filepath=path, use_selection=True,  # noqa: E731
                                                 export_format='GLB')
        with captured_output(log) as cap:
            failure = _failure_of(exporters.get(fmt, gltf))
        if failure is not None:
            raise BlenderIOError(f"Blender's exporter failed on {os.path.basename(path)}: "
                                 f"{cap.explain(failure)}")
    finally:
        bpy.data.objects.remove(obj)
        bpy.data.meshes.remove(mesh)
