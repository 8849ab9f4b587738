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
come here (the core's reader refuses them, naming the line); for PLY and STL
the face count in the file's header is compared with what was imported.
"""

import contextlib
import ctypes
import os
import re
import struct
import sys
import tempfile

#: formats that need Blender, and the importer / exporter of each
BLENDER_IMPORT = {".ply": "PLY", ".stl": "STL", ".gltf": "glTF", ".glb": "glTF"}
BLENDER_EXPORT = {"ply", "stl", "glb"}
_LOG_LIMIT = 20_000    #: characters of Blender's log kept per file
_LOG_PREFIX = re.compile(r"^\s*\d+:\d+\.\d+\s+\S+\s+\|\s*")


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

    def lines(self, *words):
        """Log lines containing any of ``words``, without the time stamp and
        channel Blender's log puts first (``00:00.372  io.ply  | ``)."""
        return [_LOG_PREFIX.sub("", ln).strip() for ln in self.text.splitlines()
                if any(w in ln for w in words)]


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


def header_face_count(path):
    """Faces the file says it holds (PLY header, STL count), or None."""
    ext = os.path.splitext(path)[1].lower()
    try:
        with open(path, "rb") as fh:
            head = fh.read(1 << 16)
            size = os.fstat(fh.fileno()).st_size
    except OSError:
        return None
    if ext == ".ply":
        end = head.find(b"end_header")
        for line in head[:end if end >= 0 else len(head)].splitlines():
            parts = line.split()
            if len(parts) == 3 and parts[:2] == [b"element", b"face"] and parts[2].isdigit():
                return int(parts[2])
    elif ext == ".stl":
        if len(head) >= 84:
            (n,) = struct.unpack("<I", head[80:84])
            if 84 + 50 * n == size:          # binary STL
                return n
        if head.lstrip().lower().startswith(b"solid"):
            with open(path, "rb") as fh:
                return sum(line.lstrip().startswith(b"facet") for line in fh)
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
    before = set(bpy.data.objects)
    with captured_output(log) as cap:
        try:
            ops[ext](filepath=path)
        except RuntimeError as exc:
            failure = " ".join(str(exc).split())
        else:
            failure = None
    if failure is not None:
        causes = [c for c in cap.lines("ERROR", "Error", "error") if c not in failure]
        cause = f' (Blender\'s log: "{"; ".join(causes)[:400]}")' if causes else ""
        raise BlenderIOError(f"Blender's importer failed on {name}: {failure}{cause}")
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


def read_with_blender(path, log):
    """``(V, F, n_polygons, warnings)`` of a file read by Blender's importer
    into an empty scene; ``warnings`` names faces the importer dropped and
    quotes the warnings in its log."""
    bpy = _bpy(log)
    with captured_output(log):
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
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
    warnings = []
    expected = header_face_count(path)
    if expected is not None and arrays.n_polygons < expected:
        warnings.append(f"Blender's {BLENDER_IMPORT.get(os.path.splitext(path)[1].lower())} "
                        f"importer kept {arrays.n_polygons:,} of the file's {expected:,} faces")
    for line in dict.fromkeys(_LOG_PREFIX.sub("", x).strip() for x in "".join(log).splitlines()
                              if "WARNING" in x):
        warnings.append(f"Blender: {line[:200]}")
    return V, arrays.F, arrays.n_polygons, warnings


def write_with_blender(path, V, F, log):
    """Write a triangle mesh with Blender's exporter chosen by the extension
    (``.ply``, ``.stl`` or ``.glb``)."""
    bpy = _bpy(log)
    fmt = os.path.splitext(path)[1].lower()
    mesh = _mesh_io().new_mesh(os.path.splitext(os.path.basename(path))[0], V, F)
    obj = bpy.data.objects.new(mesh.name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    try:
        with captured_output(log) as cap:
            try:
                if fmt == ".ply":
                    bpy.ops.wm.ply_export(filepath=path, export_selected_objects=True)
                elif fmt == ".stl":
                    bpy.ops.wm.stl_export(filepath=path, export_selected_objects=True)
                else:
                    bpy.ops.export_scene.gltf(filepath=path, use_selection=True,
                                              export_format='GLB')
            except RuntimeError as exc:
                failure = " ".join(str(exc).split())
            else:
                failure = None
        if failure is not None:
            causes = cap.lines("ERROR", "Error")
            raise BlenderIOError(f"Blender's exporter failed on {os.path.basename(path)}: "
                                 f"{failure}" + (f" ({'; '.join(causes)[:400]})" if causes else ""))
    finally:
        bpy.data.objects.remove(obj)
        bpy.data.meshes.remove(mesh)
