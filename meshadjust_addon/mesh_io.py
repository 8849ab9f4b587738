"""Moving mesh data between Blender and the NumPy core, fast.

Positions and corner indices move through ``mesh.attributes`` with
``foreach_get`` / ``foreach_set`` on contiguous float32 / int32 buffers (a
million vertices in milliseconds); nothing here loops over elements in Python.
The core works in float64 / int64, so dtypes are cast once, here.
"""

import zlib
from typing import NamedTuple

import bpy
import numpy as np

from .. import core


class MeshArrays(NamedTuple):
    """A Blender mesh as core arrays, in the object's local space."""

    V: np.ndarray          #: (n,3) float64
    F: np.ndarray          #: (m,3) int64 triangles
    n_polygons: int        #: polygons in the Blender mesh (before triangulation)
    triangulated: bool     #: True when n-gons or quads were split for the core
    evaluated: bool        #: True when modifiers or shape keys were applied
    n_split: int = 0       #: the polygons of more than 3 corners (those split for the core)
    faces_key: str = ""    #: :func:`polygon_key` of the mesh read (its polygons, not its triangles)


def read_positions(mesh):
    """(n,3) float64 vertex positions of a ``bpy.types.Mesh``."""
    return read_positions32(mesh).reshape(-1, 3).astype(np.float64)


def write_positions(mesh, V):
    """Overwrite the vertex positions of ``mesh`` (same vertex count); returns
    the flat float32 buffer written."""
    V = np.ascontiguousarray(V, dtype=np.float32).reshape(-1)
    if V.size != 3 * len(mesh.vertices):
        raise core.TopologyMismatchError(f"write_positions: {V.size // 3} positions for "
                                         f"'{mesh.name}', which has {len(mesh.vertices)} vertices")
    if V.size:
        mesh.attributes["position"].data.foreach_set("vector", V)
        tag_positions_changed(mesh)
    mesh.update()
    return V


def tag_positions_changed(mesh):
    """Tell Blender that the positions of ``mesh`` changed, after a
    ``foreach_set`` on its position attribute, which does not: Blender kept
    its triangles of quads and n-gons (drawn, read by ``loop_triangles``:
    a deformed quad stayed split along a diagonal that now folds it) and,
    with ``update_tag()`` alone (live mode), its normals, so the edited
    original was shaded with its old normals while the cage was edited.
    Setting one vertex's position through its own property tags them all
    (its update clears those caches); the value written is the one read,
    bit for bit."""
    if len(mesh.vertices):
        v = mesh.vertices[0]
        v.co = v.co


def read_positions32(mesh):
    """The flat float32 vertex positions of ``mesh`` as Blender holds them
    (what :func:`write_positions` wrote, bit for bit)."""
    n = len(mesh.vertices)
    buf = np.empty(n * 3, dtype=np.float32)
    if n and mesh.is_editmode:
        # in Edit Mode ``attributes`` lists the BMesh layers; the synced mesh
        # arrays are reached through the element collections
        mesh.vertices.foreach_get("co", buf)
    elif n:
        mesh.attributes["position"].data.foreach_get("vector", buf)
    return buf


def read_key(kb):
    """The flat float32 positions of the shape key ``kb`` (as written, bit for bit)."""
    co = np.empty(3 * len(kb.data), dtype=np.float32)
    kb.data.foreach_get("co", co)
    return co


def read_triangles(mesh):
    """(m,3) int64 triangles of ``mesh`` and whether polygons had to be split.

    An all-triangle mesh is read straight from the corner attribute; otherwise
    Blender's own loop triangulation is used (so n-gons split as Blender shows
    them).
    """
    n_loops = len(mesh.loops)
    n_polys = len(mesh.polygons)
    if n_polys == 0:
        return np.zeros((0, 3), dtype=np.int64), False
    if n_loops == 3 * n_polys:
        buf = np.empty(n_loops, dtype=np.int32)
        if mesh.is_editmode:   # see read_positions
            mesh.loops.foreach_get("vertex_index", buf)
        else:
            mesh.attributes[".corner_vert"].data.foreach_get("value", buf)
        return buf.reshape(-1, 3).astype(np.int64), False
    mesh.calc_loop_triangles()
    buf = np.empty(3 * len(mesh.loop_triangles), dtype=np.int32)
    mesh.loop_triangles.foreach_get("vertices", buf)
    return buf.reshape(-1, 3).astype(np.int64), True


def polygon_key(mesh):
    """A short string that changes when the polygons of ``mesh`` (their
    corners' vertices, in order) change, and not when its vertices move:
    Blender's triangles of a quad or an n-gon follow the positions (a
    deformed quad can be split along its other diagonal)."""
    corners = np.empty(len(mesh.loops), dtype=np.int32)
    total = np.empty(len(mesh.polygons), dtype=np.int32)
    if len(corners):
        if mesh.is_editmode:   # see read_positions
            mesh.loops.foreach_get("vertex_index", corners)
        else:
            mesh.attributes[".corner_vert"].data.foreach_get("value", corners)
    mesh.polygons.foreach_get("loop_total", total)
    crc = zlib.crc32(memoryview(total).cast("B"), zlib.crc32(memoryview(corners).cast("B")))
    return f"{len(mesh.vertices)}:{len(total)}:{len(corners)}:{crc:08x}"


def split_polygons(mesh):
    """How many polygons of ``mesh`` have more than three corners (the quads
    and n-gons :func:`read_triangles` splits)."""
    total = np.empty(len(mesh.polygons), dtype=np.int32)
    mesh.polygons.foreach_get("loop_total", total)
    return int(np.count_nonzero(total > 3))


def triangle_polygons(mesh):
    """(m,) int64: the polygon of each triangle :func:`read_triangles` gives."""
    n_polys = len(mesh.polygons)
    if len(mesh.loops) == 3 * n_polys:
        return np.arange(n_polys, dtype=np.int64)
    mesh.calc_loop_triangles()
    buf = np.empty(len(mesh.loop_triangles), dtype=np.int32)
    mesh.loop_triangles.foreach_get("polygon_index", buf)
    return buf.astype(np.int64)


def has_deformers(obj):
    """True when the object's visible shape differs from its mesh data
    (modifiers or shape keys)."""
    return bool(obj.modifiers) or bool(obj.data.shape_keys)


def disabled_in_viewport(obj, view_layer=None):
    """Whether ``obj`` is disabled in the viewports of ``view_layer`` (the
    context's): disabled itself, or in no collection that is enabled there
    (every collection holding it excluded, or disabled in viewports itself or
    through a parent collection). Hidden (the eye) is not disabled: Blender
    still evaluates its modifiers."""
    if obj.hide_viewport:
        return True
    view_layer = view_layer or bpy.context.view_layer

    def enabled_in(lc, disabled):
        disabled = disabled or lc.exclude or lc.collection.hide_viewport
        if not disabled and lc.collection.objects.get(obj.name) == obj:
            return True
        return any(enabled_in(child, disabled) for child in lc.children)

    return not enabled_in(view_layer.layer_collection, False)


def read_object(obj, *, depsgraph=None, evaluated=None):
    """The object's mesh as :class:`MeshArrays` in its local space.

    ``evaluated=None`` (default) uses the evaluated mesh (modifiers and shape
    keys applied, what the user sees) only when the object has any, and says
    so in the result; True / False force it. An object Blender does not
    evaluate (disabled in the viewport) cannot give its evaluated mesh:
    :class:`core.InvalidMeshError`.
    """
    if obj is None or obj.type != 'MESH':
        kind = "nothing" if obj is None else obj.type.lower()
        raise core.InvalidMeshError(f"expected a mesh object, got {kind}")
    use_eval = has_deformers(obj) if evaluated is None else evaluated
    if use_eval:
        depsgraph = depsgraph or bpy.context.evaluated_depsgraph_get()
        ob_eval = obj.evaluated_get(depsgraph)
        if not obj.users_collection and not obj.users_scene:
            raise core.InvalidMeshError(   # (it was "disabled in the viewport: enable it")
                f"'{obj.name}' was deleted from the scene (Blender keeps it while MeshAdjust "
                f"points to it), so its modifiers and shape keys are not evaluated: undo the "
                f"delete, or link it back into a collection")
        if not ob_eval.is_evaluated or disabled_in_viewport(obj):
            # (its base mesh would come back: the modifiers silently left out; an object a
            # cage points to is in the depsgraph, evaluated without them)
            raise core.InvalidMeshError(
                f"'{obj.name}' is disabled in the viewport (the object, or a collection it is "
                f"in, is disabled or excluded), so Blender does not evaluate its modifiers and "
                f"shape keys: enable it in the viewport first")
        mesh = ob_eval.to_mesh()
        try:
            V = read_positions(mesh)
            F, tri = read_triangles(mesh)
            n_poly, n_split = len(mesh.polygons), (split_polygons(mesh) if tri else 0)
            key = polygon_key(mesh)
        finally:
            ob_eval.to_mesh_clear()
    else:
        mesh = obj.data
        V = read_positions(mesh)
        F, tri = read_triangles(mesh)
        n_poly, n_split = len(mesh.polygons), (split_polygons(mesh) if tri else 0)
        key = polygon_key(mesh)
    return MeshArrays(V, F, n_poly, tri, bool(use_eval), n_split, key)


def new_mesh(name, V, F):
    """A new ``bpy.types.Mesh`` from core arrays (triangles), built with
    attribute writes, not ``from_pydata`` (10x faster)."""
    V = np.ascontiguousarray(V, dtype=np.float32)
    F = np.ascontiguousarray(F, dtype=np.int32)
    mesh = bpy.data.meshes.new(name)
    n, m = V.shape[0], F.shape[0]
    mesh.vertices.add(n)
    mesh.loops.add(3 * m)
    mesh.polygons.add(m)
    if n:
        mesh.attributes["position"].data.foreach_set("vector", V.reshape(-1))
    if m:
        mesh.attributes[".corner_vert"].data.foreach_set("value", F.reshape(-1))
        mesh.polygons.foreach_set("loop_start", np.arange(0, 3 * m, 3, dtype=np.int32))
    mesh.update(calc_edges=True)
    return mesh


def set_edge_flags(mesh, E, name):
    """Store a boolean EDGE attribute ``name`` that is True on the edges ``E``
    ((k,2) vertex pairs) and False elsewhere."""
    n_e = len(mesh.edges)
    ev = np.empty(2 * n_e, dtype=np.int32)
    mesh.edges.foreach_get("vertices", ev)
    ev = ev.reshape(-1, 2).astype(np.int64)
    n = max(len(mesh.vertices), 1)
    key = np.minimum(ev[:, 0], ev[:, 1]) * n + np.maximum(ev[:, 0], ev[:, 1])
    E = np.asarray(E, dtype=np.int64).reshape(-1, 2)
    want = np.minimum(E[:, 0], E[:, 1]) * n + np.maximum(E[:, 0], E[:, 1])
    flags = np.isin(key, want)
    attr = mesh.attributes.get(name)
    if attr is None or attr.domain != 'EDGE' or attr.data_type != 'BOOLEAN':
        if attr is not None:
            mesh.attributes.remove(attr)
        attr = mesh.attributes.new(name, 'BOOLEAN', 'EDGE')
    attr.data.foreach_set("value", flags)
    return int(flags.sum())


def get_edge_flags(mesh, name):
    """(k,2) int64 vertex pairs of the edges whose boolean EDGE attribute
    ``name`` is True (empty when the attribute is absent)."""
    attr = mesh.attributes.get(name)
    if attr is None or attr.domain != 'EDGE':
        return np.zeros((0, 2), dtype=np.int64)
    n_e = len(mesh.edges)
    flags = np.zeros(n_e, dtype=bool)
    attr.data.foreach_get("value", flags)
    ev = np.empty(2 * n_e, dtype=np.int32)
    mesh.edges.foreach_get("vertices", ev)
    return ev.reshape(-1, 2)[flags].astype(np.int64)


def vertex_group_weights(obj, group_name):
    """(n,) float64 weights of a vertex group on ``obj``'s mesh (0 where a
    vertex is not in the group), or None when ``group_name`` is empty.

    The Python API has no bulk getter for vertex-group weights, so they are
    read through geometry nodes: a temporary object sharing the mesh gets a
    node modifier that stores the group as a float point attribute, and the
    evaluated mesh is read with ``foreach_get``. Nothing of it is left behind.

    Raises
    ------
    core.InvalidArgumentError
        Unknown group name.
    """
    if not group_name:
        return None
    if obj.vertex_groups.get(group_name) is None:
        raise core.InvalidArgumentError(f"vertex group '{group_name}' not found on "
                                        f"'{obj.name}'")
    tmp_name = "meshadjust_tmp_weights"
    ng = bpy.data.node_groups.new(tmp_name, 'GeometryNodeTree')
    tmp_obj = bpy.data.objects.new(tmp_name, obj.data)
    try:
        ng.interface.new_socket("Geometry", in_out='INPUT', socket_type='NodeSocketGeometry')
        ng.interface.new_socket("Geometry", in_out='OUTPUT', socket_type='NodeSocketGeometry')
        node_in = ng.nodes.new('NodeGroupInput')
        node_out = ng.nodes.new('NodeGroupOutput')
        named = ng.nodes.new('GeometryNodeInputNamedAttribute')
        named.data_type = 'FLOAT'
        named.inputs["Name"].default_value = group_name
        store = ng.nodes.new('GeometryNodeStoreNamedAttribute')
        store.data_type = 'FLOAT'
        store.domain = 'POINT'
        store.inputs["Name"].default_value = tmp_name
        ng.links.new(node_in.outputs[0], store.inputs["Geometry"])
        ng.links.new(named.outputs["Attribute"], store.inputs["Value"])
        ng.links.new(store.outputs["Geometry"], node_out.inputs[0])
        mod = tmp_obj.modifiers.new(tmp_name, 'NODES')
        mod.node_group = ng
        bpy.context.scene.collection.objects.link(tmp_obj)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        depsgraph.update()
        ob_eval = tmp_obj.evaluated_get(depsgraph)
        mesh = ob_eval.to_mesh()
        try:
            attr = mesh.attributes[tmp_name]
            buf = np.empty(len(mesh.vertices), dtype=np.float32)
            attr.data.foreach_get("value", buf)
        finally:
            ob_eval.to_mesh_clear()
    finally:
        bpy.data.objects.remove(tmp_obj)
        bpy.data.node_groups.remove(ng)
    return buf.astype(np.float64)


#: attribute data type -> (foreach field, values per element, dtype, continuous: may be
#: interpolated); the types a MeshAdjust step reads and writes in bulk (not STRING)
ATTRIBUTE_FIELDS = {
    'FLOAT': ("value", 1, np.float32, True), 'FLOAT2': ("vector", 2, np.float32, True),
    'FLOAT_VECTOR': ("vector", 3, np.float32, True),
    'FLOAT_COLOR': ("color", 4, np.float32, True), 'BYTE_COLOR': ("color", 4, np.float32, True),
    'INT': ("value", 1, np.int32, False), 'INT8': ("value", 1, np.int32, False),
    'BOOLEAN': ("value", 1, bool, False), 'INT32_2D': ("value", 2, np.int32, False),
    'QUATERNION': ("value", 4, np.float32, False), 'INT16_2D': ("value", 2, np.int32, False),
    'FLOAT4X4': ("value", 16, np.float32, False),
}


def read_attribute(attr):
    """(len, width) values of a mesh attribute of a type in :data:`ATTRIBUTE_FIELDS`."""
    field, width, dtype, _ = ATTRIBUTE_FIELDS[attr.data_type]
    buf = np.empty(len(attr.data) * width, dtype=dtype)
    attr.data.foreach_get(field, buf)
    return buf.reshape(-1, width)


def write_attribute(attr, values):
    """Write ``values`` (len, width) into a mesh attribute (:func:`read_attribute`)."""
    field, _, dtype, _ = ATTRIBUTE_FIELDS[attr.data_type]
    attr.data.foreach_set(field, np.ascontiguousarray(values, dtype=dtype).ravel())


#: Blender's attributes that are a view's state, not the artist's data
_VIEW_STATE = (".select_", ".uv_select")


def artist_data_key(mesh):
    """A checksum of what ``mesh`` holds besides its positions and
    MeshAdjust's own attributes: its other attributes (UV maps, colours,
    material indices, custom normals, sharp edges, seams, hidden parts, its
    faces) and its materials; selections and string attributes left out."""
    c = zlib.crc32(";".join(m.name if m is not None else "" for m in mesh.materials).encode())
    for attr in sorted(mesh.attributes, key=lambda a: a.name):
        name = attr.name
        if name == "position" or name.startswith(("meshadjust_",) + _VIEW_STATE) \
                or attr.data_type not in ATTRIBUTE_FIELDS:
            continue
        c = zlib.crc32(f"{name}|{attr.domain}|{attr.data_type}".encode(), c)
        c = zlib.crc32(memoryview(np.ascontiguousarray(read_attribute(attr))).cast("B"), c)
    return f"{len(mesh.vertices)}:{c:08x}"
