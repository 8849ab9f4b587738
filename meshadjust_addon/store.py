"""Where a binding lives in a .blend: mesh attributes, not custom properties.

* On the **edited original** (a copy of the source that nobody edits by
  hand): per dense vertex, point attributes ``meshadjust_face`` (INT, the fine
  face), ``meshadjust_bary`` and ``meshadjust_offset`` (FLOAT_VECTOR).
* On a small data-only mesh ``<edited>.detail`` (fake user, pointed to from the
  edited object's state, tagged for :mod:`.leftovers`): the per-fine-vertex
  detail as vertex positions, used by the *refined mesh* output.
* On the **cage**: its own topology, the crease edges as the boolean edge
  attribute ``meshadjust_crease``, and its rest shape at bind time (source
  space) as the point attribute ``meshadjust_rest``.
* On the edited object's :class:`MeshAdjustObjectState`: levels, scheme and the
  cage fingerprint.

All of it survives save and reload; a :class:`core.binding.Binding` is rebuilt
from it (and cached for the session, so live edits do not rebuild the
subdivision operator).
"""

import contextlib

import bmesh
import bpy
import numpy as np

from .. import core
from . import leftovers, mesh_io, names, rollback, staleness

FACE = "meshadjust_face"
BARY = "meshadjust_bary"
OFFSET = "meshadjust_offset"
CREASE = "meshadjust_crease"
REST = "meshadjust_rest"

_cache = {}
#: edited original's session_uid -> bindings written on it (or taken back) this session
_bindings_written = {}


def binding_stamp(edited):
    """What changes whenever a binding is written on the edited original
    ``edited`` (or taken back by a failed step's rollback) in this session:
    a step that read its binding compares it at its commit (a Bind made while
    a Refine ran in the background had been overwritten by the Refine's
    result from the binding before). None for no edited original."""
    return None if edited is None else _bindings_written.get(edited.session_uid, 0)


def _written(uid):
    _bindings_written[uid] = _bindings_written.get(uid, 0) + 1


def _set_point_attr(mesh, name, kind, values):
    rollback.keep(mesh)
    attr = mesh.attributes.get(name)
    if attr is not None:
        mesh.attributes.remove(attr)
    attr = mesh.attributes.new(name, kind, 'POINT')
    if kind == 'INT':
        attr.data.foreach_set("value", np.ascontiguousarray(values, dtype=np.int32).ravel())
    else:
        attr.data.foreach_set("vector", np.ascontiguousarray(values, dtype=np.float32).ravel())


def _is_ours(attr, kind):
    """Whether the attribute ``attr`` is per vertex and of the ``kind``
    MeshAdjust writes (Convert Attribute in the Attributes panel changes
    both: a FLOAT one had no vectors to read, a Python traceback)."""
    return attr.domain == 'POINT' and attr.data_type == kind


def _get_point_attr(mesh, name, kind):
    attr = mesh.attributes.get(name)
    if attr is None:
        raise core.MeshAdjustError(f"'{mesh.name}' has no binding attribute '{name}': bind it again")
    if not _is_ours(attr, kind):
        raise core.MeshAdjustError(
            f"'{mesh.name}': its attribute '{name}' is {attr.data_type} on {attr.domain}, not "
            f"the {kind} per vertex MeshAdjust wrote (converted?): bind it again")
    n = len(mesh.vertices)
    if kind == 'INT':
        buf = np.empty(n, dtype=np.int32)
        attr.data.foreach_get("value", buf)
        return buf.astype(np.int64)
    buf = np.empty(3 * n, dtype=np.float32)
    attr.data.foreach_get("vector", buf)
    return buf.reshape(n, 3).astype(np.float64)


@contextlib.contextmanager
def _readable_cage_mesh(cage):
    """The cage's mesh with its attributes readable: the mesh itself, or in
    Edit Mode (where ``attributes`` lists the BMesh layers) a temporary copy
    of it synced from Edit Mode: the original object's ``to_mesh()``, which
    leaves its modifiers out (the evaluated mesh had them: a Subdivision
    Surface preview on the cage refused every step and live mode from Edit
    Mode)."""
    if cage.mode == 'EDIT':
        cage.update_from_editmode()
    if not cage.data.is_editmode:
        yield cage.data
        return
    mesh = cage.to_mesh()
    try:
        yield mesh
    finally:
        cage.to_mesh_clear()


def cage_topology(cage):
    """(F_cage, n_cage, creases) of a cage object, read from its mesh (an
    Edit Mode cage is synced first).

    Raises :class:`core.MeshAdjustError` when the cage has faces of more
    than three corners (Edit Mode's Subdivide, Grid Fill or Knife makes
    them; Bind and Fit triangulate them in Object Mode,
    :func:`triangulated_copy`): Blender splits a quad along the diagonal its
    shape favours, which changes as its corners move, so the cage's
    triangles changed under an edit (Refine refused a moved corner as a new
    topology, every Fit was rolled back as "changed topology while the step
    ran") or were folded (a quad with a straight corner split through it: a
    face of no area and an edge of three faces, which Bind named as such)."""
    with _readable_cage_mesh(cage) as mesh:
        creases = mesh_io.get_edge_flags(mesh, CREASE)
    F, split = mesh_io.read_triangles(cage.data)
    if split:
        k = mesh_io.split_polygons(cage.data)
        them = "them" if k != 1 else "it"
        where = "leave Edit Mode and Bind" if cage.mode == 'EDIT' else "Bind"
        raise core.MeshAdjustError(
            f"'{cage.name}' has {k:,} face{'s' if k != 1 else ''} of more than three corners "
            f"(a cage is triangles: Blender splits a quad along the diagonal its shape favours, "
            f"and that changes as its corners move); {where} again, which triangulates {them}, "
            f"or triangulate {them} yourself (Edit Mode: Face > Triangulate Faces, Ctrl+T)")
    return F, len(cage.data.vertices), (creases if creases.shape[0] else None)


def triangulated_copy(mesh):
    """A new mesh: ``mesh`` (not in Edit Mode) with its faces of more than
    three corners split into triangles as Face > Triangulate Faces does
    (Beauty, for quads and n-gons alike). Its vertices (their order), its
    triangles (their order: a split face's first triangle takes its place,
    the others come last), attributes, shape keys and materials are those of
    ``mesh``; the diagonals are new edges, not creased."""
    bm = bmesh.new()
    try:
        bm.from_mesh(mesh)
        bmesh.ops.triangulate(bm, faces=bm.faces[:], quad_method='BEAUTY',
                              ngon_method='BEAUTY')
        copy = mesh.copy()
        bm.to_mesh(copy)
    finally:
        bm.free()
    return copy


def save_rest(cage, V_rest):
    """Keep the cage's rest positions (source space) on the cage, so a
    binding with other levels or scheme can be made after the cage was edited.

    In Edit Mode the attribute is a layer of the BMesh (what the mesh gets back
    when the mode is left), written per vertex: a cage is small."""
    if not cage.data.is_editmode:
        _set_point_attr(cage.data, REST, 'FLOAT_VECTOR', V_rest)
        return
    rollback.keep(cage.data)
    bm = bmesh.from_edit_mesh(cage.data)
    if len(bm.verts) != V_rest.shape[0]:
        raise core.TopologyMismatchError(
            f"save_rest: '{cage.name}' has {len(bm.verts)} vertices in Edit Mode, the rest shape "
            f"{V_rest.shape[0]}")
    layer = bm.verts.layers.float_vector.get(REST) or bm.verts.layers.float_vector.new(REST)
    bm.verts.ensure_lookup_table()
    for v, co in zip(bm.verts, V_rest.tolist()):
        v[layer] = co
    bmesh.update_edit_mesh(cage.data, loop_triangles=False, destructive=False)


def load_rest(cage):
    """The cage's rest positions (source space) saved at bind time."""
    with _readable_cage_mesh(cage) as mesh:
        attr = mesh.attributes.get(REST)
        if attr is None or not _is_ours(attr, 'FLOAT_VECTOR'):     # (converted: as none)
            raise core.MeshAdjustError(f"'{cage.name}' has no rest shape: bind it first")
        return _get_point_attr(mesh, REST, 'FLOAT_VECTOR')


def _rest_or_none(cage):
    """The cage's rest shape, or None when it has none (a binding made before
    the rest shape was kept loads without the fold repair)."""
    try:
        return load_rest(cage)
    except core.MeshAdjustError:
        return None


def save_binding(edited, binding):
    """Write ``binding`` onto the edited-original object ``edited``."""
    mesh = edited.data
    if len(mesh.vertices) != binding.n_dense:
        raise core.MeshAdjustError(
            f"save_binding: '{edited.name}' has {len(mesh.vertices)} vertices, the binding "
            f"{binding.n_dense}")
    _set_point_attr(mesh, FACE, 'INT', binding.fine_face)
    _set_point_attr(mesh, BARY, 'FLOAT_VECTOR', binding.bary)
    _set_point_attr(mesh, OFFSET, 'FLOAT_VECTOR', binding.offset)
    state = edited.meshadjust
    detail = state.detail_mesh
    name = names.suffixed(edited.name, ".detail")
    if detail is not None and len(detail.vertices) == binding.fine_detail.shape[0]:
        rollback.keep(detail)
        mesh_io.write_positions(detail, binding.fine_detail)     # in place: no new data-block
    else:
        old = detail
        detail = mesh_io.new_mesh(name + ".new", binding.fine_detail, np.zeros((0, 3), np.int64))
        detail.use_fake_user = True
        leftovers.tag_detail(detail)     # (removed once its edited original is gone)
        state.detail_mesh = detail
        if old is not None:
            rollback.retire(old, detail, name, ours=True)
    _take_name(detail, name)
    state.fingerprint = binding.fingerprint
    state.dense_vertices = binding.n_dense
    state.cage_counts = (binding.n_cage, binding.F_cage.shape[0])
    state.levels = binding.levels
    state.scheme = binding.scheme
    _cache[edited.session_uid] = binding
    _written(edited.session_uid)
    rollback.on_undo(lambda uid=edited.session_uid: (_cache.pop(uid, None), _written(uid)))


def _take_name(detail, name):
    """Name the detail mesh ``detail`` ``name``: now when it is free, when the
    step succeeds when the detail data of a deleted edited original holds it
    (removed then, :mod:`.leftovers`); else it keeps its name."""
    taken = bpy.data.meshes.get(name)
    if taken is None:
        detail.name = name
    elif taken != detail and taken in leftovers.orphan_details():
        rollback.retire(taken, detail, name, ours=True)


def binding_misfit(edited):
    """Why the binding stored on the edited original ``edited`` no longer
    fits its mesh (another vertex count than was bound), or None."""
    n, bound = len(edited.data.vertices), edited.meshadjust.dense_vertices
    if not bound or n == bound:
        return None
    return (f"'{edited.name}' has {n:,} vertices, {bound:,} were bound: its mesh was changed (a "
            f"modifier applied, vertices added or removed) and its binding data no longer fits it")


def _bound_triangles(edited):
    """(m,3) int64: the triangles ``edited`` was bound with (its fold repair's).

    Blender splits a quad or an n-gon as its positions say, and the edited
    original's are deformed: read back from it (a binding rebuilt after a
    reload), a deformed quad could be split along its other diagonal than
    when it was bound, and the fold repair ran on other triangles than in
    the session it was made in (results 2% of the size apart). The source's
    own triangles are those that were bound while its polygons are the
    edited original's and it is readable (else the edited original's)."""
    own = mesh_io.read_triangles(edited.data)[0]
    source = edited.meshadjust.source
    if 3 * len(edited.data.polygons) == len(edited.data.loops) or source is None:
        return own                                  # (triangles only: no choice was made)
    from .cage_steps import read_source             # (cage_steps imports this module)
    try:
        arrays, _ = read_source(source)
    except core.MeshAdjustError:
        return own
    same = arrays.faces_key == mesh_io.polygon_key(edited.data) and arrays.F.shape == own.shape
    return arrays.F if same else own


def load_binding(edited, cage):
    """The :class:`core.binding.Binding` stored on ``edited`` for ``cage``.

    Raises
    ------
    core.TopologyMismatchError
        The cage's topology changed since the binding was made.
    core.MeshAdjustError
        The binding data is missing.
    """
    state = edited.meshadjust
    misfit = binding_misfit(edited)
    if misfit:
        raise core.MeshAdjustError(f"{misfit}; Bind again to re-make it (your version is kept "
                                   f"aside)")
    F_cage, n_cage, creases = cage_topology(cage)
    cached = _cache.get(edited.session_uid)
    if (cached is not None and cached.n_cage == n_cage and cached.F_cage.shape == F_cage.shape
            and np.array_equal(cached.F_cage, F_cage) and cached.fingerprint == state.fingerprint
            and cached.n_dense == len(edited.data.vertices)):
        return cached
    detail = state.detail_mesh
    if detail is None:
        raise core.MeshAdjustError(f"the detail data of '{edited.name}' is missing: bind again")
    arrays = {
        "fine_face": _get_point_attr(edited.data, FACE, 'INT'),
        "bary": _get_point_attr(edited.data, BARY, 'FLOAT_VECTOR'),
        "offset": _get_point_attr(edited.data, OFFSET, 'FLOAT_VECTOR'),
        "fine_detail": mesh_io.read_positions(detail),
        "F_cage": F_cage, "n_cage": n_cage, "levels": state.levels, "scheme": state.scheme,
        "creases": creases if creases is not None else np.zeros((0, 2), np.int64),
        "fingerprint": state.fingerprint,
        # for the fold repair: the edited copy has the source's faces, the cage its rest shape
        "F_dense": _bound_triangles(edited),
        "V_cage_rest": _rest_or_none(cage),
    }
    try:
        binding = core.Binding.from_arrays(arrays)
    except core.TopologyMismatchError as exc:
        what = staleness.cage_change(cage, edited, fresh=True) or "its topology changed"
        raise core.TopologyMismatchError(
            f"the cage '{cage.name}' changed since '{edited.name}' was bound to it ({what}): "
            f"re-bind to use its new topology (the edit is kept)") from exc
    _cache[edited.session_uid] = binding
    return binding
