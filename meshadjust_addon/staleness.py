"""Is a binding still about the meshes it was made from? Cheap checks.

Two fingerprints are stored with a binding (on the edited original's state)
and compared with the objects as they are now:

* the **source fingerprint**: vertex and face counts, a CRC-32 of the base
  mesh's positions (its reference key's when it has keys) and corners, one of
  every other shape key (but the ones MeshAdjust writes itself, named after a
  cage) with its value and vertex group (and of the evaluation time of
  absolute keys, and of the key pinned to show alone), and one of
  every modifier with its settings, so a message can say which changed. It changes when the evaluated mesh the binding
  was made from can have changed: the mesh edited, a shape key's value or a
  modifier's level changed. (A modifier that follows another object, such as
  a lattice, is not followed.)
* the **cage topology key**: vertex, edge and face counts and a CRC-32 of
  the cage's sorted directed half-edges (independent of face order and of
  each face's first corner), so a message can tell a deleted vertex from a
  rotated edge. It works in Edit Mode (read from the BMesh).

Both are recomputed only when the object changed: a ``depsgraph_update_post``
handler counts geometry updates per object, and the results are memoised
against that count, so the panel can ask on every redraw.
"""

import zlib
from typing import NamedTuple

import bmesh
import bpy
import numpy as np

from . import app_handlers, mesh_io

_generation = {}      #: object session_uid -> geometry updates seen
_memo = {}            #: (what, session_uid) -> (generation, value)


def _crc(*arrays, start=0):
    c = start
    for a in arrays:
        c = zlib.crc32(memoryview(np.ascontiguousarray(a)).cast("B"), c)   # no copy
    return c


def _generation_of(obj):
    return _generation.get(obj.session_uid, 0)


def _memoised(what, obj, compute):
    key = (what, obj.session_uid)
    gen = _generation_of(obj)
    hit = _memo.get(key)
    if hit is not None and hit[0] == gen:
        return hit[1]
    value = compute(obj)
    _memo[key] = (gen, value)
    return value


# ------------------------------------------------------------------ source
def _rna_values(struct):
    """The simple (non-pointer, non-collection) RNA values of a struct, as text."""
    out = []
    for prop in struct.bl_rna.properties:
        if prop.type in ('POINTER', 'COLLECTION') or prop.identifier == "rna_type":
            continue
        try:
            value = getattr(struct, prop.identifier)
        except AttributeError:
            continue
        if prop.type in ('INT', 'FLOAT', 'BOOLEAN') and getattr(prop, "array_length", 0):
            value = tuple(value)
        out.append(f"{prop.identifier}={value!r}")
    return ";".join(out)


def own_key_names(source):
    """Names of the shape keys MeshAdjust wrote on ``source`` (one per cage,
    and those of cages deleted since: recorded on the source when written,
    so another cage's bind never reads them as the artist's, and bakes them)."""
    return {key_name(o) for o in cages_of(source)} | recorded_keys(source)


def cages_of(source):
    """The MeshAdjust cages of ``source``."""
    return [o for o in bpy.data.objects
            if o.type == 'MESH' and o.meshadjust.role == 'CAGE' and o.meshadjust.source == source]


def recorded_keys(source):
    """The shape keys recorded on ``source`` as written by its cages (its
    ``own_keys``, a name a line)."""
    return set(filter(None, source.meshadjust.own_keys.split("\n")))


def record_keys(source, names):
    """Record the shape keys ``names`` (a set) as the ones MeshAdjust wrote on
    ``source`` (its ``own_keys``, read by :func:`recorded_keys`)."""
    source.meshadjust.own_keys = "\n".join(sorted(names))


def pinned_key(source, own):
    """The artist's shape key ``source`` shows alone, at full whatever its value
    (Shape Key Lock, the pin), or None (no pin, or the key is one of ``own``,
    MeshAdjust's)."""
    key = source.active_shape_key if source.show_only_shape_key else None
    return key if key is not None and key.name not in own else None


def key_name(cage):
    """The name of the shape key ``cage`` writes on its source: the one it
    first wrote (kept when the cage is renamed), else the cage's name."""
    return cage.meshadjust.key_name or cage.name


def source_fingerprint(source):
    """The source fingerprint of ``source`` now (a short string)."""
    mesh = source.data
    if mesh.is_editmode:   # its mesh arrays are stale until it leaves Edit Mode
        return None
    n, m = len(mesh.vertices), len(mesh.polygons)
    pos = np.empty(3 * n, np.float32)
    corners = np.empty(len(mesh.loops), np.int32)
    if n:
        mesh.attributes["position"].data.foreach_get("vector", pos)
    if len(corners):
        mesh.attributes[".corner_vert"].data.foreach_get("value", corners)
    keys = mesh.shape_keys
    if keys is not None:   # the reference key is the base shape (the mesh follows it)
        keys.reference_key.data.foreach_get("co", pos)
    c_mesh = _crc(pos, corners)
    c_keys = 0
    if keys is not None:
        own = own_key_names(source)
        if not keys.use_relative:     # (absolute keys: the time, not the values, picks the shape)
            c_keys = zlib.crc32(f"absolute|{keys.eval_time}".encode())
        pinned = pinned_key(source, own)
        if pinned is not None:
            c_keys = zlib.crc32(f"pinned|{pinned.name}".encode(), c_keys)
        for kb in keys.key_blocks:
            if kb.name in own or kb == keys.reference_key:
                continue
            # (a vertex group limits the key: only said when set, so older fingerprints hold)
            group = f"|{kb.vertex_group}" if kb.vertex_group else ""
            c_keys = _crc(mesh_io.read_key(kb), start=zlib.crc32(f"{kb.name}|{kb.value}|{kb.mute}|"
                                               f"{kb.relative_key.name}{group}".encode(), c_keys))
    c_mods = 0
    for mod in source.modifiers:
        c_mods = zlib.crc32(f"{mod.type}|{_rna_values(mod)}".encode(), c_mods)
    return f"{n}:{m}:{c_mesh:08x}:{c_keys:08x}:{c_mods:08x}"


class SourceFields(NamedTuple):
    """The fields of a :func:`source_fingerprint` (strings, as written)."""

    vertices: str     #: the mesh's vertex count
    faces: str        #: its face count
    mesh: str         #: the checksum of its base shape and corners
    keys: str         #: of its other shape keys (not MeshAdjust's)
    modifiers: str    #: of its modifiers


def fingerprint_fields(fingerprint):
    """The :class:`SourceFields` of a :func:`source_fingerprint` string, or
    None when it has not their number of fields."""
    parts = fingerprint.split(":")
    return SourceFields(*parts) if len(parts) == len(SourceFields._fields) else None


def source_change(source, stored, *, fresh=False):
    """What changed in ``source`` since its fingerprint was ``stored``: a
    sentence, or None when nothing did (or nothing was stored, or the source
    is in Edit Mode). ``fresh`` recomputes instead of using the memo."""
    if not stored:
        return None
    now = source_fingerprint(source) if fresh else _memoised("source", source, source_fingerprint)
    if now is None or now == stored:
        return None
    was, new = fingerprint_fields(stored), fingerprint_fields(now)
    if was is None or new is None:
        return f"'{source.name}' may have changed since it was bound"
    what = []
    if was[:3] != new[:3]:
        if was[:2] != new[:2]:
            what.append(f"its mesh was edited ({int(was.vertices):,} -> {int(new.vertices):,} "
                        f"vertices, {int(was.faces):,} -> {int(new.faces):,} faces)")
        else:
            what.append("its mesh was edited (vertices moved)")
    if was.keys != new.keys:
        what.append("its shape keys changed")
    if was.modifiers != new.modifiers:
        what.append("its modifiers changed")
    return f"'{source.name}' changed since it was bound: " + ", ".join(what)


def source_data_key(source):
    """:func:`~.mesh_io.artist_data_key` of what ``source`` shows (its
    evaluated mesh when it has modifiers), or None when that cannot be read
    (in Edit Mode, or disabled in the viewport with modifiers)."""
    if source.data.is_editmode:
        return None
    if not source.modifiers:
        return mesh_io.artist_data_key(source.data)
    if mesh_io.disabled_in_viewport(source):      # (its modifiers are not evaluated)
        return None
    ob_eval = source.evaluated_get(bpy.context.evaluated_depsgraph_get())
    try:
        return mesh_io.artist_data_key(ob_eval.to_mesh())
    finally:
        ob_eval.to_mesh_clear()


def bound_mesh_warning(source, edited, *, fresh=False):
    """The warning a result of ``edited`` gets when ``source`` changed since
    it was bound (:func:`source_change`: the result is of the mesh that was
    bound), or None. ``fresh`` recomputes instead of using the memo (a live
    update uses it: the source is not what a live edit changes)."""
    stale = source_change(source, edited.meshadjust.source_fingerprint, fresh=fresh)
    return f"{stale}: the result uses the mesh that was bound; re-bind to use the new one" \
        if stale else None


def source_data_change(source, edited, *, fresh=False):
    """A sentence when the UV maps, attributes or materials of ``source``
    changed since ``edited`` was made from it (its ``data_written``), or
    None (also when that was not recorded). ``fresh`` recomputes instead of
    using the memo."""
    stored = edited.meshadjust.data_written
    if not stored:
        return None
    now = source_data_key(source) if fresh else _memoised("data", source, source_data_key)
    if now is None or now == stored:
        return None
    return (f"'{source.name}' changed since it was bound: its UV maps, attributes or materials "
            f"changed (the edited original has the old ones)")


# ------------------------------------------------------------------ cage
def _half_edges_of_mesh(mesh):
    n_l = len(mesh.loops)
    corners = np.empty(n_l, np.int32)
    start = np.empty(len(mesh.polygons), np.int32)
    total = np.empty(len(mesh.polygons), np.int32)
    if n_l:
        mesh.attributes[".corner_vert"].data.foreach_get("value", corners)
    mesh.polygons.foreach_get("loop_start", start)
    mesh.polygons.foreach_get("loop_total", total)
    c = np.arange(n_l, dtype=np.int64)
    s = np.repeat(start.astype(np.int64), total)
    t = np.repeat(total.astype(np.int64), total)
    nxt = s + (c - s + 1) % np.maximum(t, 1)
    return corners.astype(np.int64), corners[nxt].astype(np.int64)


def topology_key(cage):
    """``(vertices, edges, faces, checksum)`` of the cage as it is now (also
    in Edit Mode, from its BMesh)."""
    mesh = cage.data
    if mesh.is_editmode:
        bm = bmesh.from_edit_mesh(mesh)
        bm.verts.index_update()
        pairs = np.array([(lp.vert.index, lp.link_loop_next.vert.index)
                          for f in bm.faces for lp in f.loops], dtype=np.int64).reshape(-1, 2)
        counts = (len(bm.verts), len(bm.edges), len(bm.faces))
        a, b = pairs[:, 0], pairs[:, 1]
    else:
        counts = (len(mesh.vertices), len(mesh.edges), len(mesh.polygons))
        a, b = _half_edges_of_mesh(mesh)
    keys = np.sort(a * max(counts[0], 1) + b)
    return counts + (f"{_crc(keys):08x}",)


def cage_topology_key(cage):
    """:func:`topology_key`, memoised against the cage's geometry updates."""
    return _memoised("cage", cage, topology_key)


def describe_change(before, after):
    """A sentence saying how topology ``after`` differs from ``before``
    (both :func:`topology_key` tuples), or None when it does not."""
    if tuple(before) == tuple(after):
        return None
    parts = []
    for k, (noun, plural) in enumerate((("vertex", "vertices"), ("edge", "edges"),
                                        ("face", "faces"))):
        d = after[k] - before[k]
        if d:
            parts.append(f"{abs(d):,} {noun if abs(d) == 1 else plural} "
                         f"{'added' if d > 0 else 'removed'}")
    if parts:
        return ", ".join(parts)
    return ("the same vertices, edges and faces connected differently (an edge rotated, faces "
            "flipped or re-filled)")


def cage_change(cage, edited, *, fresh=False):
    """How ``cage``'s topology changed since ``edited`` was bound to it: a
    sentence, or None. ``fresh`` recomputes instead of using the memo."""
    st = edited.meshadjust
    if not st.cage_topology:
        return None
    before = (st.cage_counts[0], st.cage_edges, st.cage_counts[1], st.cage_topology)
    return describe_change(before, topology_key(cage) if fresh else cage_topology_key(cage))


# ------------------------------------------------------------------ updates
@bpy.app.handlers.persistent
def _on_depsgraph_update(_scene, depsgraph):
    for update in depsgraph.updates:
        if update.is_updated_geometry and isinstance(update.id, bpy.types.Object):
            uid = update.id.original.session_uid
            _generation[uid] = _generation.get(uid, 0) + 1


def touched(obj):
    """Forget what is known about ``obj`` (after MeshAdjust changed it)."""
    _generation[obj.session_uid] = _generation.get(obj.session_uid, 0) + 1


_HANDLERS = (("depsgraph_update_post", _on_depsgraph_update),)


def register():
    app_handlers.add(_HANDLERS)


def unregister():
    app_handlers.remove(_HANDLERS)
    _generation.clear()
    _memo.clear()
