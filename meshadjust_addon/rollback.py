"""All or nothing for the Blender side of a step (undo is unavailable headless).

The steps check everything that can fail before they write, so a commit
normally cannot fail half-way; :func:`all_or_nothing` is the safety net for
the case where it does anyway. On an exception it puts back what the block
changed and re-raises:

* the objects and meshes created inside the block are removed;
* the mesh, transform, visibility and MeshAdjust state (the
  :class:`~.properties.MeshAdjustObjectState` values) of every object with a
  MeshAdjust role, and of those registered with :meth:`Rollback.keep_object`,
  as they were when the block began (or was told);
* for the meshes registered with :meth:`Rollback.keep` (or :func:`keep`),
  their vertex positions, shape keys (those added removed, the others'
  shapes put back) and MeshAdjust attributes (the
  binding's, the rest shape, the crease flags: ``meshadjust_*``);
* every object's and mesh's name, as it was when the block began (a step
  renames the data it writes: the detail mesh after its edited original);
* the caches of what the block wrote are dropped (:func:`on_undo`);
* meshes the block retired (:func:`retire`: an object's old mesh, the old
  detail data) are only removed when it succeeds, so a failure can give
  them back (with the detail data of edited originals deleted since,
  :func:`.leftovers.remove_orphan_details`).

A block opened inside another joins it: the outer block is the one
transaction (a Fit that re-binds is undone whole, its bind included).

    with all_or_nothing() as rb:
        rb.keep(cage.data)
        mesh_io.write_positions(cage.data, V)
        ...
"""

import contextlib

import bmesh
import bpy
import numpy as np

from . import leftovers, mesh_io

#: the attributes a step writes and a rollback restores (see :mod:`.store`)
PREFIX = "meshadjust_"

_open = []    #: the Rollback of the block open now (at most one: inner blocks join it)


def _state_of(obj):
    """The values of ``obj.meshadjust`` (``{name: value}``; vectors as tuples)."""
    st = obj.meshadjust
    out = {}
    for prop in st.bl_rna.properties:
        name = prop.identifier
        if name == "rna_type" or prop.is_readonly:
            continue
        value = getattr(st, name)
        out[name] = tuple(value) if getattr(prop, "is_array", False) else value
    return out


def _positions_of(mesh):
    """The mesh's vertex positions (in Edit Mode, its BMesh's)."""
    if mesh.is_editmode:
        return np.array([v.co for v in bmesh.from_edit_mesh(mesh).verts]).reshape(-1, 3)
    return mesh_io.read_positions(mesh)


def _put_positions(mesh, V):
    """Write ``V`` back where :func:`_positions_of` read it (when the count is the same)."""
    if not mesh.is_editmode:
        if len(mesh.vertices) == V.shape[0]:
            mesh_io.write_positions(mesh, V)
        return
    bm = bmesh.from_edit_mesh(mesh)
    if len(bm.verts) == V.shape[0]:
        for v, co in zip(bm.verts, V.tolist()):
            v.co = co
        bmesh.update_edit_mesh(mesh, loop_triangles=False, destructive=False)


def _key_shapes(mesh):
    """``{name: co}`` of the mesh's shape keys (float32, flat), None without keys."""
    sk = mesh.shape_keys
    if sk is None:
        return None
    out = {}
    for kb in sk.key_blocks:
        out[kb.name] = mesh_io.read_key(kb)
    return out


def _object_record(obj):
    """What a step may change on ``obj``: its mesh, transform, visibility and state."""
    return (obj.data, obj.matrix_world.copy(), obj.hide_get() if obj.name in
            bpy.context.view_layer.objects else None, _state_of(obj))


def _restore_object(obj, record):
    data, matrix, hidden, state = record
    if obj.data is not data:
        obj.data = data
    if obj.matrix_world != matrix:
        obj.matrix_world = matrix
    if hidden is not None and obj.name in bpy.context.view_layer.objects \
            and obj.hide_get() != hidden:
        obj.hide_set(hidden)
    st = obj.meshadjust
    for name, value in state.items():
        if getattr(st, name) != value and not (isinstance(value, tuple)
                                               and tuple(getattr(st, name)) == value):
            setattr(st, name, value)


def _attributes_of(mesh):
    """``{name: (domain, data_type, values)}`` of the mesh's MeshAdjust
    attributes (in Edit Mode, its BMesh's vertex vector layers of that name)."""
    if mesh.is_editmode:
        bm = bmesh.from_edit_mesh(mesh)
        layers = bm.verts.layers.float_vector
        return {name: ('POINT', 'FLOAT_VECTOR', np.array([v[layers[name]] for v in bm.verts]))
                for name in layers.keys() if name.startswith(PREFIX)}
    out = {}
    for attr in mesh.attributes:
        if not attr.name.startswith(PREFIX) or attr.data_type not in _FIELDS:
            continue
        field, width, dtype = _FIELDS[attr.data_type]
        buf = np.empty(len(attr.data) * width, dtype=dtype)
        attr.data.foreach_get(field, buf)
        out[attr.name] = (attr.domain, attr.data_type, buf)
    return out


#: per attribute data type a rollback keeps: the field, its values per element, their dtype
_FIELDS = {'FLOAT_VECTOR': ("vector", 3, np.float32), 'FLOAT': ("value", 1, np.float32),
           'INT': ("value", 1, np.int32), 'BOOLEAN': ("value", 1, bool)}


def remove_attributes(mesh, keep=()):
    """Remove the MeshAdjust attributes (``PREFIX``) of ``mesh`` but those
    named in ``keep`` (by name: a removal moves the others)."""
    attrs = mesh.attributes
    for name in [a.name for a in attrs if a.name.startswith(PREFIX) and a.name not in keep]:
        attrs.remove(attrs[name])


def _restore_attributes(mesh, kept):
    """Put the MeshAdjust attributes of ``mesh`` back to ``kept``
    (:func:`_attributes_of`): those added since removed, the others rewritten."""
    if mesh.is_editmode:
        bm = bmesh.from_edit_mesh(mesh)
        layers = bm.verts.layers.float_vector
        for name in [n for n in layers.keys() if n.startswith(PREFIX) and n not in kept]:
            layers.remove(layers[name])
        for name, (_, _, values) in kept.items():
            layer = layers.get(name) or layers.new(name)
            if len(bm.verts) == values.shape[0]:
                for v, co in zip(bm.verts, values.tolist()):
                    v[layer] = co
        bmesh.update_edit_mesh(mesh, loop_triangles=False, destructive=False)
        return
    remove_attributes(mesh, keep=kept)
    for name, (domain, kind, values) in kept.items():
        attr = mesh.attributes.get(name)
        if attr is None or attr.domain != domain or attr.data_type != kind:
            if attr is not None:
                mesh.attributes.remove(attr)
            attr = mesh.attributes.new(name, kind, domain)
        field, width, _ = _FIELDS[kind]
        if len(attr.data) * width == values.size:
            attr.data.foreach_set(field, values)


def _names():
    """``{ID: name}`` of every object and mesh."""
    return {id_: id_.name for coll in (bpy.data.objects, bpy.data.meshes) for id_ in coll}


def _restore_names(names):
    """Give the objects and meshes of ``names`` (:func:`_names`, those still
    there) their names back: the renamed ones first to a temporary name, so
    two that swapped names do not collide (Blender would add '.001')."""
    changed = [(id_, name) for id_, name in names.items()
               if id_.name_full in bpy.data.objects or id_.name_full in bpy.data.meshes
               if id_.name != name]
    for i, (id_, _) in enumerate(changed):
        id_.name = f".meshadjust_undo_{i}"
    for id_, name in changed:
        id_.name = name


class Rollback:
    """What existed when the block began, and what to put back."""

    def __init__(self):
        self.objects = set(bpy.data.objects)
        # (every object a step writes has a role, but the source Simplify gives one and an
        # object Subdivide replaces in place: those are kept by keep_object)
        self.records = {obj: _object_record(obj) for obj in self.objects
                        if obj.meshadjust.role != 'NONE'}
        self.meshes = set(bpy.data.meshes)
        self.names = _names()
        self.kept = {}          #: mesh -> (positions, shape keys, attributes) before a write
        self.retired = []
        self.forget = []

    def keep(self, mesh):
        """Remember ``mesh``'s positions, shape keys' names and MeshAdjust
        attributes before a write (nothing for a mesh made inside the block:
        an undo removes it)."""
        if mesh is not None and mesh in self.meshes and mesh not in self.kept:
            # (by the mesh, not its name: a step may rename it between two keeps)
            self.kept[mesh] = (_positions_of(mesh), _key_shapes(mesh), _attributes_of(mesh))

    def keep_object(self, obj):
        """Remember ``obj``'s mesh, transform, visibility and state (those of
        an object with a MeshAdjust role are kept from the start)."""
        if obj not in self.records:
            self.records[obj] = _object_record(obj)

    def retire(self, mesh, successor=None, name=None, ours=False):
        """Remove ``mesh`` once the block succeeds (see :func:`retire`; a mesh
        retired twice is removed once, as first said)."""
        if all(mesh != m for m, *_ in self.retired):
            self.retired.append((mesh, successor, name, ours))

    def finish(self):
        """The block succeeded: remove the retired meshes, and the detail data
        of edited originals removed from the file since (:mod:`.leftovers`)."""
        for mesh, *how in self.retired:
            if mesh.name_full in bpy.data.meshes:
                _remove(mesh, *how)
        leftovers.remove_orphan_details()

    def undo(self):
        """The block failed: put back what it changed (see the module's docstring)."""
        for fn in reversed(self.forget):
            fn()
        for obj, record in self.records.items():
            if obj.name_full in bpy.data.objects:
                _restore_object(obj, record)
        for obj in [o for o in bpy.data.objects if o not in self.objects]:
            bpy.data.objects.remove(obj)
        for mesh in [m for m in bpy.data.meshes if m not in self.meshes]:
            bpy.data.meshes.remove(mesh)
        _restore_names(self.names)
        for mesh, (_, shapes, _) in self.kept.items():
            _restore_keys(mesh, shapes)
        for mesh, (V, _, _) in self.kept.items():
            _put_positions(mesh, V)
        for mesh, (_, _, attributes) in self.kept.items():
            _restore_attributes(mesh, attributes)


def _restore_keys(mesh, shapes):
    """Put the shape keys of ``mesh`` back to ``shapes`` (:func:`_key_shapes`):
    those added since removed, the others' shapes rewritten."""
    sk = mesh.shape_keys
    if sk is None:
        return
    owners = [o for o in bpy.data.objects if o.data == mesh]
    for kb in reversed([kb for kb in sk.key_blocks if shapes is None or kb.name not in shapes]):
        if owners:
            owners[0].shape_key_remove(kb)
    for kb in sk.key_blocks if shapes is not None else ():
        co = shapes.get(kb.name)
        if co is not None and len(kb.data) * 3 == co.size:
            kb.data.foreach_set("co", co)


def keep(mesh):
    """:meth:`Rollback.keep` on the open block (nothing outside one)."""
    if _open:
        _open[0].keep(mesh)


def on_undo(fn):
    """Call ``fn`` if the open block is undone (a cache of what it wrote to drop)."""
    if _open:
        _open[0].forget.append(fn)


def retire(mesh, successor=None, name=None, ours=False):
    """Remove ``mesh`` if no user is left (``ours``, a mesh MeshAdjust made:
    but its fake user), ``successor`` then taking its name (or ``name``):
    when the open block succeeds (now, outside one)."""
    if _open:
        _open[0].retire(mesh, successor, name, ours)
    else:
        _remove(mesh, successor, name, ours)


def _remove(mesh, successor, name, ours):
    if mesh.users == (int(mesh.use_fake_user) if ours else 0):
        name = name or mesh.name
        bpy.data.meshes.remove(mesh)
        if successor is not None and name not in bpy.data.meshes:
            successor.name = name


@contextlib.contextmanager
def all_or_nothing():
    """Run a block of Blender writes; on any exception, undo them and re-raise
    (inside another block: join it)."""
    if _open:
        yield _open[0]
        return
    rb = Rollback()
    _open.append(rb)
    try:
        yield rb
    except BaseException:
        rb.undo()
        raise
    finally:
        _open.pop()
    rb.finish()
