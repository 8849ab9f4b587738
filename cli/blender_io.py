"""The batch tool's Blender side: PLY, STL and glTF through Blender's own
importers and exporters, with Blender's log kept out of our stdout.

Blender's importers print to the process's file descriptors 1 and 2 from C
(``io.ply | ERROR PLY Importer: ... Could not read row of ASCII property``,
``OBJ import of 'x.obj' took 0.20 ms``) and report only ``failed importing,
unknown error`` to Python. :func:`captured_output` points both descriptors at
a temporary file while Blender runs, so the text can go to ``--log`` or the
report, and an importer's error is quoted with the cause from its log.

Blender's importers also repair silently: a face that indexes a missing
vertex is dropped, a NaN coordinate becomes 0, a file cut short is read up
to where it ends. OBJ and SMF therefore never come here (the core's reader
refuses them, naming the line); PLY, STL and glTF files are checked before
Blender reads them (``ply_file``, ``stl_file``, ``gltf_file``), and the face
count the file declares is compared with what was imported.

Meshes come back in the file's own coordinates: a glTF node's transform is
applied (the faces of a mirroring one reversed, as Blender draws them) and
Blender's turn of glTF's Y-up into its Z-up undone
(``gltf_file.FROM_BLENDER``); glTF is written without that turn, so every
output holds the numbers of its input's frame.
"""

import contextlib
import ctypes
import logging
import os
import re
import sys
import tempfile

import numpy as np

from . import gltf_file, ply_file, stl_file

#: formats that need Blender, and the importer / exporter of each
BLENDER_IMPORT = {".ply": "PLY", ".stl": "STL", ".gltf": "glTF", ".glb": "glTF"}
BLENDER_EXPORT = {"ply", "stl", "glb"}
#: each format's check of the file before Blender reads it (``check(path) -> FileCheck``)
FILE_CHECKS = {".ply": ply_file.check, ".stl": stl_file.check, ".gltf": gltf_file.check,
               ".glb": gltf_file.check}
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


def grouped_warnings(lines):
    """Blender's warnings, one per kind: lines that differ only in their
    numbers (``Invalid PLY vertex index in face 5856 loop 7``, ``... face
    5857 loop 9``) as the first of them and how many more there were."""
    kinds = {}
    for line in lines:
        kinds.setdefault(re.sub(r"\d+", "#", line), []).append(line)
    return [f"{same[0][:200]}" + (f" (and {len(same) - 1:,} more like it)" if len(same) > 1 else "")
            for same in kinds.values()]


def _failure_of(op, log):
    """Run a Blender operator; its error on one line, or None. A Python
    traceback inside the operator (the glTF add-on's) goes to ``log`` and
    comes back as its last line, ``ValueError: buffer is smaller than
    requested size``."""
    try:
        op()
    except RuntimeError as exc:
        text = str(exc)
        if "Traceback (most recent call last)" not in text:
            return " ".join(text.split())
        log.append(text + "\n")
        last = [ln.strip() for ln in text.split("Location:")[0].strip().splitlines()][-1:]
        return f"a Python error in Blender's add-on: {' '.join(last)} (the traceback is in the log)"
    return None


#: what Blender's glTF importer logs for a Draco-compressed primitive it cannot decode (it
#: skips it: the file had failed with "no mesh with faces" alone)
_DRACO_FAILED = "Draco Decoder: Unable to decode"


@contextlib.contextmanager
def _no_handlers_left():
    """Remove the logging handlers added inside the block (Blender's glTF
    importer leaves its own attached when it raises: after 12 failed glTF
    files, each line of a good file's log came 13 times)."""
    def loggers():         # (the root and every named one; placeholders hold no handlers)
        return [logging.getLogger()] + [x for x in logging.Logger.manager.loggerDict.values()
                                        if isinstance(x, logging.Logger)]
    before = {id(x): list(x.handlers) for x in loggers()}
    try:
        yield
    finally:
        for x in loggers():
            for handler in [h for h in x.handlers if h not in before.get(id(x), [])]:
                x.removeHandler(handler)


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
    read = stl_file.for_blender(path) if ext == ".stl" else contextlib.nullcontext(path)
    trace = []
    with read as source, captured_output(log) as cap, _no_handlers_left():
        failure = _failure_of(lambda: ops[ext](filepath=source), trace)
    log.extend(trace)
    if failure is not None:                 # a traceback's own lines are no cause to quote
        raise BlenderIOError(f"Blender's importer failed on {name}: "
                             f"{failure if trace else cap.explain(failure)}")
    made = [o for o in bpy.data.objects if o not in before and o.type == 'MESH'
            and len(o.data.polygons)]
    shown = set(bpy.context.view_layer.objects)
    meshes = [o for o in made if o in shown]      # (a glTF node in no scene is made, not shown)
    if not meshes:
        outside = (f" ({len(made):,} outside the scene it shows: glTF nodes in no scene or in "
                   f"another)" if made else "")
        draco = [ln for ln in cap.causes("") if "Draco" in ln and "rror" in ln]
        raise BlenderIOError(f"{name}: no mesh with faces in the file{outside}" + (
            f": Blender's glTF importer could not decode its Draco-compressed meshes (its log: "
            f"\"{'; '.join(draco)[:300]}\")" if _DRACO_FAILED in cap.text else ""))
    _unmirror_windings(meshes)
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    for o in meshes:
        o.select_set(True)
    bpy.context.view_layer.objects.active = meshes[0]
    if len(meshes) > 1:
        with captured_output(log):
            bpy.ops.object.join()
    return bpy.context.view_layer.objects.active


def _unmirror_windings(objects):
    """Reverse the faces of the mesh objects whose world transform mirrors
    (a negative determinant: a glTF node scaled by -1 on an axis), each on a
    mesh of its own. Blender draws such an object's faces turned, but its
    mesh and a join keep the file's winding, so the batch, which applies the
    transform to the positions, wrote them inside out; glTF's own rule is
    the same (a node whose determinant is negative winds its front faces
    clockwise)."""
    for o in objects:
        if np.linalg.det(np.array([list(r) for r in o.matrix_world])[:3, :3]) < 0:
            if o.data.users > 1:             # (instances of one glTF mesh share it)
                o.data = o.data.copy()
            o.data.flip_normals()


def _empty_scene(log):
    """Blender's module (:func:`_bpy`) with an empty scene loaded."""
    bpy = _bpy(log)
    with captured_output(log):
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    return bpy


def read_with_blender(path, log):
    """``(V, F, n_polygons, notes, warnings)`` of a file read by Blender's
    importer into an empty scene, in the file's own coordinates (see the
    module's docstring). The file is checked first (:data:`FILE_CHECKS`:
    raises ``file_check.InputFileError`` naming it, before Blender is
    loaded); ``notes`` and ``warnings`` hold the check's, faces the importer
    dropped and the warnings in its log."""
    ext = os.path.splitext(path)[1].lower()
    found = FILE_CHECKS[ext](path) if os.path.isfile(path) else None
    _empty_scene(log)
    obj = import_mesh(path, log)
    arrays = _mesh_io().read_object(obj)
    M = np.array([list(row) for row in obj.matrix_world])
    V = arrays.V @ M[:3, :3].T + M[:3, 3]              # a node's transform applied
    if ext in (".gltf", ".glb"):
        V = V @ gltf_file.FROM_BLENDER
    notes, warnings = list(found.notes), list(found.warnings)
    if ext == ".stl" and arrays.V.shape[0] < 3 * arrays.n_polygons:
        # (STL stores each triangle's corners apart; the importer joins those at one position,
        # so the cleaning's report has no weld to tell: say it here)
        notes.append(f"Blender's STL importer joined the {3 * arrays.n_polygons:,} corners of "
                     f"the file's triangles into {arrays.V.shape[0]:,} vertices (those at one "
                     f"position)")
    expected = found.expected_faces
    if expected is not None and arrays.n_polygons < expected:
        warnings.append(f"Blender's {BLENDER_IMPORT[ext]} importer kept "
                        f"{arrays.n_polygons:,} of the file's {expected:,} faces")
    elif expected is not None and arrays.n_polygons > expected:
        # (an ASCII STL with an 'endloop' too many: a face the file does not hold, said nothing)
        warnings.append(f"Blender's {BLENDER_IMPORT[ext]} importer read {arrays.n_polygons:,} "
                        f"faces from the file's {expected:,}: it holds something else than "
                        f"the faces it declares (a damaged file?)")
    for line in grouped_warnings(_LOG_PREFIX.sub("", x).strip()
                                 for x in "".join(log).splitlines() if "WARNING" in x):
        warnings.append(f"Blender: {line}")
    return V, arrays.F, arrays.n_polygons, notes, warnings


def write_with_blender(path, V, F, log, *, name, shown):
    """Write a triangle mesh with Blender's exporter chosen by the extension
    (``.ply``, ``.stl`` or ``.glb``, written as given: glTF without the turn
    to Y-up), its object and mesh named ``name`` (formats that store names,
    as glTF does, keep it: not the path's, which may be a temporary one);
    an error names ``shown``, the path the user asked for."""
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
                                                 export_format='GLB', export_yup=False)
        trace = []
        with captured_output(log) as cap:
            failure = _failure_of(exporters.get(fmt, gltf), trace)
        log.extend(trace)
        if failure is not None:
            raise BlenderIOError(f"Blender's exporter failed on {shown}: "
                                 f"{failure if trace else cap.explain(failure)}")
    finally:
        bpy.data.objects.remove(obj)
        bpy.data.meshes.remove(mesh)
