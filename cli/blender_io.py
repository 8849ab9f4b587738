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
    of a PLY file (list properties have the type ``"list"``), or None."""
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
            elements[-1][2].append(("list" if parts[1] == "list" else parts[1], parts[-1]))
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
    for line in dict.fromkeys(_LOG_PREFIX.sub("", x).strip() for x in "".join(log).splitlines()
                              if "WARNING" in x):
        warnings.append(f"Blender: {line[:200]}")
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
