"""Where an edit lands: the edited original, the refined mesh, a shape key.

* The **edited original** is a copy of the source's evaluated mesh (UVs,
  attributes, materials), bound to the cage and deformed by it.
* The **refined mesh** is the subdivided edited cage with the source's detail.
* The **shape key** is the edit written onto the source itself: a key named
  after the cage (value 1.0, relative to the reference key), the reference
  key ("Basis", created from the mesh when the source had no keys) never
  touched. Its positions are the reference key's plus the displacement of
  the edited original from the mesh that was bound, so they equal the edited
  original exactly when the source has no other keys and no modifiers.

Every result is created once and updated in place afterwards; a mesh that
is replaced is removed when nothing else uses it (no orphans). A result
changed since MeshAdjust wrote it (sculpted, its transform applied, a key
edited by hand) is not overwritten: the changed version is kept aside
first, as a copy (:func:`kept_aside`, :func:`key_kept_aside`).
"""

import contextlib
import zlib

import bpy
import mathutils
import numpy as np

from .. import core
from . import mesh_io, names
from .rollback import keep, on_undo, remove_attributes, retire
from .staleness import (cages_of, key_name, own_key_names, pinned_key, record_keys,
                         recorded_keys)


#: ``written`` of a result live mode wrote last (its buffer is in :data:`live_written`)
LIVE = "live"

#: edited object session_uid -> the flat float32 buffer live mode last wrote there
live_written = {}


#: a shape key shows the edit when the source's evaluated mesh is within this share of
#: its size of the edited original (a key is float32: 1e-7 of its coordinates)
KEY_TOLERANCE = 1e-5


def _checksum(buf):
    """``"n:crc"`` of a flat float32 position buffer."""
    return f"{buf.size // 3}:{zlib.crc32(memoryview(np.ascontiguousarray(buf)).cast('B'))}"


def record_written(obj, buf):
    """Remember what MeshAdjust wrote on the result ``obj``: the flat float32
    positions ``buf`` (as :func:`~.mesh_io.write_positions` returns them),
    and where the object was (the place it goes back to when a changed
    version is kept aside, :func:`kept_aside`)."""
    obj.meshadjust.written = _checksum(buf)
    obj.meshadjust.written_matrix = matrix_values(obj.matrix_world)
    _forget_live(obj)


def _forget_live(obj):
    """Drop live mode's buffer of ``obj`` (put back if the step is undone)."""
    uid = obj.session_uid
    live = live_written.pop(uid, None)
    if live is not None:
        on_undo(lambda: live_written.__setitem__(uid, live))


def matrix_values(matrix):
    """The 16 values, row by row, of a Blender 4x4 matrix (as the
    ``source_matrix`` and ``written_matrix`` properties hold them)."""
    return [v for row in matrix for v in row]


def recorded_matrix(values):
    """The (4,4) array of 16 recorded values, or None when they are all 0
    (not recorded)."""
    M = np.array(values, dtype=np.float64).reshape(4, 4)
    return M if M.any() else None


def blender_matrix(M):
    """A (4,4) array as Blender's ``mathutils.Matrix``."""
    return mathutils.Matrix(M.tolist())


def record_live(obj, buf):
    """Remember that live mode wrote the flat float32 positions ``buf`` on
    ``obj`` (kept by reference: live mode updates it in place)."""
    if obj.meshadjust.written != LIVE:
        obj.meshadjust.written = LIVE
        obj.meshadjust.written_matrix = matrix_values(obj.matrix_world)
    live_written[obj.session_uid] = buf


def holds_written(obj, buf):
    """Whether MeshAdjust's last write on the result ``obj`` was the
    positions ``buf``: live mode's buffer (kept by reference), or after a
    save, which turns that mark into a checksum, the same positions. Not
    when a Refine wrote it since (another cage's result: a live update that
    found nothing moved had left it so)."""
    if obj.meshadjust.written == LIVE:
        return live_written.get(obj.session_uid) is buf
    return obj.meshadjust.written == _checksum(buf)


def settle_live_written():
    """Replace the ``live`` marks by the checksums of what live mode wrote
    (before a save: the buffers do not outlive the session)."""
    for obj in bpy.data.objects:
        if obj.type == 'MESH' and obj.meshadjust.written == LIVE:
            buf = live_written.get(obj.session_uid)
            if buf is not None:
                obj.meshadjust.written = _checksum(buf)


def changed_since_written(obj):
    """Whether the result ``obj``'s mesh is no longer what MeshAdjust last
    wrote there (False when that is not known: nothing recorded, or live
    mode's buffer gone with the session unsaved)."""
    written = obj.meshadjust.written
    now = mesh_io.read_positions32(obj.data)
    if written == LIVE:
        buf = live_written.get(obj.session_uid)
        return buf is not None and not np.array_equal(now, buf.reshape(-1))
    return bool(written) and _checksum(now) != written


def kept_aside(obj, *, changed=False):
    """When the result ``obj`` changed since MeshAdjust wrote it (or
    ``changed``: the caller found another change): a copy of it as it is
    now, beside it, named ``<name>.hand``, with no MeshAdjust state or
    binding data (the copy is the artist's; ``obj`` is then overwritten).
    Returns the copy, or None when nothing changed."""
    if not changed and not changed_since_written(obj):
        return None
    copy = obj.copy()
    obj.meshadjust.written = ""    # (kept: a second look in the same step finds nothing more)
    _forget_live(obj)
    placed = recorded_matrix(obj.meshadjust.written_matrix)
    if placed is not None:         # (the result goes back where MeshAdjust last put it: an
        obj.matrix_world = blender_matrix(placed)       # applied transform stays with the copy)
    copy.data = obj.data.copy()
    copy.name = names.suffixed(obj.name, ".hand")
    copy.data.name = copy.name
    copy.property_unset("meshadjust")
    remove_attributes(copy.data)
    link_like(copy, obj)
    return copy


def key_kept_aside(source, cage, key):
    """When the shape key ``key`` of ``cage`` on ``source`` changed since the
    cage wrote it: a copy of it as it is now, ``<key>.hand`` (value 0, the
    artist's own). Returns the copy, or None when nothing changed."""
    written = cage.meshadjust.key_written
    co = mesh_io.read_key(key)
    if not written or _checksum(co) == written:
        return None
    copy = source.shape_key_add(name=names.suffixed(key.name, ".hand", names.KEY_BYTES),
                                from_mix=False)
    copy.data.foreach_set("co", co)
    copy.relative_key = key.relative_key
    copy.value = 0.0
    # (a version of MeshAdjust's own key: not the artist's source changing, so the
    # binding is not stale, and a re-bind mutes it as it mutes the key itself)
    record_keys(source, recorded_keys(source) | {copy.name})
    return copy


def link_like(obj, like):
    """Link ``obj`` into the collections of ``like`` (or the scene's)."""
    cols = list(like.users_collection) if like is not None else []
    if not cols:
        cols = [bpy.context.scene.collection]
    for col in cols:
        col.objects.link(obj)


@contextlib.contextmanager
def own_keys_muted(source):
    """Mute the shape keys MeshAdjust wrote on ``source`` for the block, so
    its evaluated mesh is the artist's (a re-bind must not bind the edit)."""
    keys = source.data.shape_keys if source is not None and source.type == 'MESH' else None
    muted = []
    if keys is not None:
        own = own_key_names(source)
        muted = [kb for kb in keys.key_blocks if kb.name in own and not kb.mute]
    for kb in muted:
        kb.mute = True
    try:
        yield
    finally:
        for kb in muted:
            kb.mute = False


def _new_source_copy(source, name):
    with own_keys_muted(source):
        depsgraph = bpy.context.evaluated_depsgraph_get()
        mesh = bpy.data.meshes.new_from_object(source.evaluated_get(depsgraph))
    mesh.name = name
    return mesh


def link_back(obj, like):
    """Link the result ``obj``, which the artist deleted (no collection
    left), back beside ``like`` (undone with the step, :func:`~.rollback.on_undo`);
    returns the sentence for the report."""
    link_like(obj, like)
    on_undo(lambda: [col.objects.unlink(obj) for col in list(obj.users_collection)])
    return f"'{obj.name}' had been deleted: linked back"


def edited_copy(source, cage, n_vertices, faces_key=None):
    """The edited-original object of ``cage`` with ``n_vertices`` vertices
    (and the polygons of the mesh bound, :func:`~.mesh_io.polygon_key`
    ``faces_key``, when given): the existing one, its mesh re-made from the
    source when the source's vertex count, polygons, UV maps, attributes or
    materials changed (:func:`~.mesh_io.artist_data_key`; a version whose
    data was changed by hand kept aside first), or a new copy (also when the
    artist deleted it). Returns ``(edited, note)``, the note saying what was
    re-made or kept aside (empty otherwise).

    Polygons, not triangles: an edit that deforms a quad of the edited
    original can make Blender split it along its other diagonal, and every
    bind re-made it (the artist's paint on it lost) and said so."""
    edited = cage.meshadjust.edited
    name = names.suffixed(source.name, "_edited")
    linked = ""
    if edited is not None and edited.name in bpy.data.objects and not edited.users_collection:
        linked = link_back(edited, source)      # (deleted by the artist: as Refine does)
    if edited is not None and edited.name in bpy.data.objects and edited.users_collection:
        old = edited.data
        same = len(old.vertices) == n_vertices and (
            not faces_key or mesh_io.polygon_key(old) == faces_key)
        mesh = _new_source_copy(source, old.name + ".new")
        data = mesh_io.artist_data_key(mesh)
        if same and mesh_io.artist_data_key(old) == data:
            bpy.data.meshes.remove(mesh)
            edited.meshadjust.data_written = data
            return edited, linked
        notes = [linked]
        if same:
            notes.append(_data_kept_aside(edited))
            why = "its UV maps, attributes or materials changed"
        else:
            why = (f"{len(old.vertices):,} -> {n_vertices:,} vertices, {len(old.polygons):,} -> "
                   f"{len(mesh.polygons):,} faces")
        edited.data = mesh
        edited.meshadjust.data_written = data
        retire(old, mesh)
        notes.append(f"'{edited.name}' re-made from '{source.name}' ({why})")
        return edited, "; ".join(filter(None, notes))
    mesh = _new_source_copy(source, name)
    edited = bpy.data.objects.new(name, mesh)
    edited.matrix_world = source.matrix_world.copy()
    link_like(edited, source)
    for slot, src_slot in enumerate(source.material_slots[:len(edited.material_slots)]):
        edited.material_slots[slot].material = src_slot.material
    st = edited.meshadjust
    st.role = 'EDITED'
    st.source = source
    st.cage = cage
    st.data_written = mesh_io.artist_data_key(mesh)
    cage.meshadjust.edited = edited
    return edited, ""


def _data_kept_aside(edited):
    """When the UV maps, attributes or materials of the edited original
    ``edited`` were changed by hand since MeshAdjust made them (or that is
    not known), a copy of it as it is, ``<name>.hand`` (as :func:`kept_aside`);
    returns the sentence for the report, or ""."""
    recorded = edited.meshadjust.data_written
    if recorded and mesh_io.artist_data_key(edited.data) == recorded:
        return ""
    copy = kept_aside(edited, changed=True)
    return (f"'{edited.name}' had its UV maps, attributes or materials changed since MeshAdjust "
            f"made it: that version is kept as '{copy.name}'")


def write_refined(cage, source, Vr, Fr, notes=None):
    """Create or update the refined-mesh object of ``cage`` (a version of
    it changed since it was written kept aside first, said in ``notes``)."""
    cs = cage.meshadjust
    refined = cs.refined
    if refined is not None and refined.name not in bpy.data.objects:
        refined = None
    if refined is not None and not refined.users_collection:   # deleted by the artist
        note = link_back(refined, source)
        if notes is not None:
            notes.append(note)
    elif refined is not None:
        aside_note(kept_aside(refined), refined, notes)
    if refined is not None and len(refined.data.vertices) == Vr.shape[0] \
            and len(refined.data.polygons) == Fr.shape[0]:
        keep(refined.data)
        record_written(refined, mesh_io.write_positions(refined.data, Vr))
        return refined
    name = names.suffixed(source.name, "_refined")
    mesh = mesh_io.new_mesh(name, Vr, Fr)
    if refined is None:
        refined = bpy.data.objects.new(name, mesh)
        refined.matrix_world = source.matrix_world.copy()
        link_like(refined, source)
        refined.meshadjust.role = 'REFINED'
        refined.meshadjust.source = source
        refined.meshadjust.cage = cage
        cs.refined = refined
    else:
        old = refined.data
        refined.data = mesh
        retire(old, mesh)
    record_written(refined, np.ascontiguousarray(Vr, dtype=np.float32).reshape(-1))
    return refined


def aside_note(copy, obj, notes):
    """Add to ``notes`` (a list, or None) the sentence saying that ``obj``'s
    changed version was kept as ``copy`` (nothing when ``copy`` is None)."""
    if copy is not None and notes is not None:
        notes.append(f"'{obj.name}' had been changed since MeshAdjust wrote it: that version is "
                     f"kept as '{copy.name}'")


def copied_from(cage):
    """The cage ``cage`` is a copy of (duplicated with its MeshAdjust state,
    so it points to that cage's results), or None."""
    edited = cage.meshadjust.edited
    owner = edited.meshadjust.cage if edited is not None else None
    return owner if owner is not None and owner != cage else None


def copy_problem(cage):
    """Why ``cage`` cannot write results (it is a copy of another cage and
    shares its results: they would be overwritten), or None."""
    owner = copied_from(cage)
    if owner is None:
        return None
    return (f"'{cage.name}' is a copy of '{owner.name}' and shares its results: Bind "
            f"'{cage.name}' to give it results of its own")


def edit_mode_problem(*objects):
    """Why MeshAdjust cannot write the results ``objects`` (None ones
    skipped), or None: one is in Edit Mode, its own or a linked duplicate's,
    or in Sculpt Mode with Dynamic Topology (its mesh is a BMesh's until the
    mode is left, which would put the artist's edit back over the write)."""
    for obj in objects:
        if obj is not None and obj.mode == 'SCULPT' and obj.use_dynamic_topology_sculpting:
            return (f"'{obj.name}' is in Sculpt Mode with Dynamic Topology, where MeshAdjust "
                    f"cannot write it (leaving the mode would put the sculpt back over the "
                    f"write): leave Sculpt Mode on '{obj.name}' first")
        if obj is not None and obj.data.is_editmode:
            who = obj.name if obj.mode == 'EDIT' else next(
                (o.name for o in bpy.data.objects if o.data == obj.data and o.mode == 'EDIT'),
                obj.name)                              # (a linked duplicate of it)
            return (f"'{who}' is in Edit Mode, where MeshAdjust cannot write "
                    + ("it" if who == obj.name else f"'{obj.name}', whose mesh it shares")
                    + f": leave Edit Mode on '{who}' first")
    return None


def keyed_problem(result):
    """Why the result ``result`` (the edited original or the refined mesh)
    cannot take the positions MeshAdjust writes, or None: shape keys of its
    own (its mesh is written, and Blender shows the keys' mix over it: a
    Refine said "deformed" or "refined" and nothing moved)."""
    keys = result.data.shape_keys
    if keys is not None and len(keys.key_blocks):
        return (f"'{result.name}' has shape keys, which hide the mesh Refine writes: delete them "
                f"(Shape Keys > Delete All Shape Keys), or add your keys to a copy of it")
    return None


def shape_key_unavailable(source, n_dense, cage=None, *, binding=False):
    """Why the edit cannot be a shape key of ``source`` (None when it can);
    with ``cage``, also when its key became the reference key
    (:func:`reference_key_problem`). ``binding``: asked by a bind of
    ``n_dense`` vertices, which a re-bind cannot fix."""
    lost = reference_key_problem(source, cage) if cage is not None else None
    if lost:
        return lost
    if source.mode == 'EDIT':
        return (f"'{source.name}' is in Edit Mode: a shape key written now would be lost when it "
                f"leaves; leave Edit Mode on '{source.name}' first")
    if not source.data.is_editable or source.library is not None:
        return (f"'{source.name}' is linked from a library: a shape key on it would not be "
                f"saved; make it local first (Object > Relations > Make Local)")
    keys = source.data.shape_keys
    if keys is not None and not keys.use_relative:
        return (f"'{source.name}' has absolute shape keys (Relative off): there a key is a step "
                f"of the sequence its evaluation time plays, not a shape at value 1, so the edit "
                f"would not show; turn Relative on, or use the edited original")
    users = source.data.users - int(source.data.use_fake_user)
    if users > 1:
        return (f"'{source.name}' shares its mesh with {users - 1:,} other "
                f"object(s): a shape key would change them too; make it single-user first "
                f"(Object > Relations > Make Single User > Object & Data)")
    if len(source.data.vertices) != n_dense:
        head = (f"'{source.name}' has {len(source.data.vertices):,} vertices in its mesh but "
                f"{n_dense:,}")
        if binding:
            return (f"{head} in what its modifiers show, which a bind binds: the edit cannot be "
                    f"a shape key of it; to bind, delete that shape key or those modifiers first")
        return (f"{head} were bound (its modifiers change the vertex count, or vertices were "
                f"added or removed since the bind): the edit cannot be a shape key of it; use "
                f"the edited original, or re-bind")
    return None


def shape_key_of(source, cage):
    """The shape key ``cage`` writes on ``source``, or None: by the name it
    wrote it under, or, when the artist renamed it, the key holding exactly
    what the cage last wrote (:func:`_renamed_key`). A cage that never wrote
    a key has none: a key of its name is the artist's own, or a deleted
    cage's (its first write makes a key of its own beside it)."""
    keys = source.data.shape_keys
    if keys is None or not cage.meshadjust.key_name:
        return None
    key = keys.key_blocks.get(key_name(cage))
    if key is not None:
        return key
    return _renamed_key(keys, cage, _other_cages_keys(source, cage))


def reference_key_problem(source, cage):
    """Why ``cage`` cannot write its shape key on ``source``: the key is the
    reference key (the artist deleted the Basis, and Blender made the first
    remaining key the base shape that the mesh and the other keys follow:
    writing it would change the source itself), or None."""
    keys = source.data.shape_keys
    key = shape_key_of(source, cage) if keys is not None else None
    if key is None or key != keys.reference_key:
        return None
    return (f"'{key.name}' is now the reference key of '{source.name}' (its Basis "
            f"was deleted, and Blender made the first remaining key, MeshAdjust's, the base shape "
            f"of '{source.name}'): MeshAdjust does not write over it. Restore Basis (MeshAdjust > "
            f"Edit Cage) puts the Basis back from the mesh that was bound, or Undo the deletion; "
            f"to keep the edit as the shape of '{source.name}', rename the key and Bind with "
            f"Keep edit off")


def _other_cages_keys(source, cage):
    """The names of the keys the other cages of ``source`` write."""
    return {o.meshadjust.key_name for o in cages_of(source) if o != cage and o.meshadjust.key_name}


def _renamed_key(keys, cage, others):
    """The one key of ``keys`` (the reference key and the keys of the other
    cages, ``others``, aside) whose shape is the one ``cage`` last wrote
    (``key_written``), or None (also when several are)."""
    written = cage.meshadjust.key_written
    if not written:
        return None
    found = []
    for kb in keys.key_blocks[1:]:
        if kb.name in others or kb == keys.reference_key:
            continue
        if _checksum(mesh_io.read_key(kb)) == written:
            found.append(kb)
    return found[0] if len(found) == 1 else None


def follow_renamed_keys(source):
    """:func:`follow_renamed_key` for every cage of ``source`` (before its
    evaluated mesh is read for a bind: a renamed key of any cage is muted)."""
    if source.data.shape_keys is None:
        return
    for cage in cages_of(source):
        follow_renamed_key(source, cage)


def follow_renamed_key(source, cage):
    """When the artist renamed the key ``cage`` writes on ``source``: record
    its new name on the cage and among the source's own keys (so a bind
    mutes it and the fingerprint leaves it out, as the key itself)."""
    key = shape_key_of(source, cage)
    if key is not None and key.name != key_name(cage):
        own = recorded_keys(source) - {key_name(cage)}
        cage.meshadjust.key_name = key.name
        record_keys(source, own | {key.name})


def write_shape_key(source, cage, V_edited, V_bound, notes=None):
    """Write the edit as the shape key of ``cage`` on ``source`` (named after
    the cage when first written, :func:`~.staleness.key_name`).

    ``V_edited`` (n,3): the edited original's positions; ``V_bound`` (n,3):
    the positions that were bound (the source's evaluated mesh at bind time),
    or None when they are the reference key's (no other keys, no modifiers).
    """
    why = shape_key_unavailable(source, V_edited.shape[0], cage)
    if why:
        raise core.MeshAdjustError(f"the shape key of '{cage.name}': {why}")
    keep(source.data)
    if source.data.shape_keys is None:
        source.shape_key_add(name="Basis", from_mix=False)
    keys = source.data.shape_keys
    follow_renamed_key(source, cage)
    key = shape_key_of(source, cage)
    if key is not None:
        aside = key_kept_aside(source, cage, key)
        if aside is not None and notes is not None:
            notes.append(f"shape key '{key.name}' had been changed since MeshAdjust wrote it: "
                         f"that version is kept as '{aside.name}' (value 0)")
    if key is None:
        wanted = names.key_name_for(cage.name)      # (as Blender keeps it: 63 bytes at most)
        key = source.shape_key_add(name=wanted, from_mix=False)
        key.relative_key = keys.reference_key
        key.value = 1.0
        if key.name != wanted and notes is not None:
            notes.append(f"a shape key '{wanted}' MeshAdjust did not write is kept as it is: "
                         f"the edit is the key '{key.name}'")
        cage.meshadjust.key_name = key.name       # (renaming the cage keeps its key)
        record_keys(source, recorded_keys(source) | {key.name})
    co = _key_shape(keys, key, V_edited, V_bound)
    co = np.ascontiguousarray(co, dtype=np.float32).ravel()
    key.data.foreach_set("co", co)
    cage.meshadjust.key_written = _checksum(co)
    source.data.update()
    return key


def key_miss(source, V_edited, own_key=None):
    """A warning when the source with its shape keys and modifiers as they
    are now does not show the edit ``V_edited`` (n,3, its local space): a
    key is applied before the modifiers, so where they turn the vertices
    (an Armature's pose, a Simple Deform) the key's offsets, measured on the
    shape they make, are turned too (a posed arm lifted up moved sideways,
    reported as done); other keys shown with it (``own_key``: the name of
    the one written) add theirs (an artist's key relative to MeshAdjust's at
    0.5 took half the edit back, reported as updated). None when it shows
    it (to a ``KEY_TOLERANCE`` share of its size), or has no modifiers and
    no other key shown."""
    others = _other_keys_shown(source, own_key)
    if not source.modifiers and not others:
        return None
    depsgraph = bpy.context.evaluated_depsgraph_get()
    depsgraph.update()
    shown = mesh_io.read_object(source, depsgraph=depsgraph, evaluated=True).V
    if shown.shape != V_edited.shape:
        return None                       # (refused before a key is written)
    size = core.bbox_diagonal(V_edited) if V_edited.shape[0] else 0.0
    off = float(np.linalg.norm(shown - V_edited, axis=1).max()) if V_edited.shape[0] else 0.0
    if not off > KEY_TOLERANCE * size:
        return None
    far = f"up to {off:.3g} ({100 * off / size:.2g}% of its size) off the edited original"
    if not source.modifiers:
        listed = ", ".join(f"'{name}'" for name in others[:3]) + (", ..." if len(others) > 3 else "")
        return (f"'{source.name}' shows other shape keys with the edit ({listed}): {far}; set "
                f"them to 0 to see the edit alone")
    kinds = ", ".join(sorted({m.type.replace("_", " ").title() for m in source.modifiers}))
    return (f"'{source.name}' shows its shape key through its modifiers ({kinds}), which "
            f"Blender applies after it: where they turn the mesh the edit is turned too, {far}; "
            f"use the edited original, or apply the modifiers first")


def _other_keys_shown(source, own_key):
    """The names of the shape keys of ``source`` other than its reference
    key and ``own_key`` that change what it shows (not muted, a value other
    than 0; every one when a key is pinned to show alone: the check then
    compares what is shown)."""
    keys = source.data.shape_keys
    if keys is None:
        return []
    return [kb.name for kb in keys.key_blocks
            if kb != keys.reference_key and kb.name != own_key and not kb.mute and kb.value != 0.0]


def _key_shape(keys, key, V_edited, V_bound):
    """The positions of ``key`` that show the edit ``V_edited - V_bound``
    (``V_bound`` None: the reference key's positions) over the key it is
    relative to (the reference key unless the artist chose another)."""
    def shape(kb):
        return mesh_io.read_key(kb).reshape(-1, 3).astype(np.float64)
    relative = key.relative_key
    if relative == keys.reference_key or relative == key:
        return V_edited if V_bound is None else shape(relative) + (V_edited - V_bound)
    bound = shape(keys.reference_key) if V_bound is None else V_bound
    return shape(relative) + (V_edited - bound)


def only_own_keys_and_no_modifiers(source):
    """True when the source's evaluated mesh (own keys muted) is its reference key."""
    if source.modifiers:
        return False
    keys = source.data.shape_keys
    if keys is None:
        return True
    if not keys.use_relative:        # (absolute keys: the evaluation time picks the shape)
        return False
    own = own_key_names(source)
    if pinned_key(source, own) is not None:     # (shown alone at full, whatever its value)
        return False
    return all(kb.name in own or kb == keys.reference_key or kb.mute or kb.value == 0.0
               for kb in keys.key_blocks)
